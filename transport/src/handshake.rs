//! The handshake every connection starts with, on its first bidirectional
//! stream: the client sends `Hello`, the master answers `Welcome` or
//! `Refused`; both messages are limited to
//! [`MAX_HANDSHAKE_BYTES`](vtfarm_proto::MAX_HANDSHAKE_BYTES). Both ends
//! then finish that stream; the session continues on new streams.
//!
//! On a refusal the master sends `Refused`, waits up to [`REFUSAL_LINGER`]
//! for it to be acknowledged, and closes the connection with the code's
//! `RefuseCode::close_code` and the reason. A client that lost the
//! message (QUIC may drop undelivered stream data on close) still gets the
//! refusal from the close code, so [`client_handshake`] reports
//! [`ProtoError::Refused`] either way. The client never closes the
//! connection itself on a refusal.
//!
//! What the master accepts is the wire's rule (`vtfarm_proto::check_hello`).

use std::time::Duration;

use vtfarm_proto::{
    FrameError, HANDSHAKE_TIMEOUT, HandshakePolicy, Hello, Message, Refusal, RefuseCode, Welcome,
    check_hello,
};

use crate::stream::{ProtoError, ReadBounds, read_frame, read_message, write_message};
use crate::truncate_utf8;

/// How long the master waits for a `Refused` to be acknowledged before closing.
pub const REFUSAL_LINGER: Duration = Duration::from_secs(1);
/// The application close code of an orderly close (`Shutdown`, job done).
pub const CLOSE_NORMAL: quinn::VarInt = quinn::VarInt::from_u32(0);
/// Close reasons are cut to this many bytes to fit one packet.
pub(crate) const MAX_REASON_BYTES: usize = 200;

/// The client side: opens the first stream, sends `hello` and returns the
/// master's `Welcome`, or [`ProtoError::Refused`] with the master's code.
/// Gives up after [`HANDSHAKE_TIMEOUT`] with [`ProtoError::Timeout`].
pub async fn client_handshake(
    conn: &quinn::Connection,
    hello: &Hello,
) -> Result<Welcome, ProtoError> {
    match tokio::time::timeout(HANDSHAKE_TIMEOUT, client_exchange(conn, hello)).await {
        Ok(Ok(welcome)) => Ok(welcome),
        // A failure caused by the master closing with a refusal code is that refusal.
        Ok(Err(error)) => Err(refusal_from_close(conn).unwrap_or(error)),
        Err(_) => Err(ProtoError::Timeout),
    }
}

async fn client_exchange(conn: &quinn::Connection, hello: &Hello) -> Result<Welcome, ProtoError> {
    let (mut send, mut recv) = conn.open_bi().await?;
    write_message(&mut send, &Message::Hello(hello.clone())).await?;
    // Already finished or reset only if the connection is gone; the read says so.
    let _ = send.finish();
    match read_message(&mut recv, ReadBounds::HANDSHAKE).await? {
        Message::Welcome(welcome) if welcome.version == hello.version => Ok(welcome),
        Message::Welcome(_) => Err(ProtoError::Unexpected {
            expected: "Welcome of our version",
            got: "Welcome of another version",
        }),
        Message::Refused(refusal) => Err(ProtoError::Refused {
            code: refusal.code,
            message: refusal.message,
        }),
        other => Err(ProtoError::Unexpected {
            expected: "Welcome or Refused",
            got: other.name(),
        }),
    }
}

fn refusal_from_close(conn: &quinn::Connection) -> Option<ProtoError> {
    match conn.close_reason()? {
        quinn::ConnectionError::ApplicationClosed(close) => {
            let code = RefuseCode::from_close_code(close.error_code.into_inner())?;
            Some(ProtoError::Refused {
                code,
                message: String::from_utf8_lossy(&close.reason).into_owned(),
            })
        }
        _ => None,
    }
}

/// The master side: accepts the first stream, reads the `Hello` and checks
/// magic, version and token against `policy`. Answers `Welcome` and returns
/// the `Hello`; or answers `Refused`, closes the connection with the
/// refusal's close code and returns the [`Refusal`] (for the log).
pub async fn server_handshake(
    conn: &quinn::Connection,
    policy: &HandshakePolicy,
) -> Result<Hello, Refusal> {
    let received = match tokio::time::timeout(policy.timeout, receive_hello(conn, policy)).await {
        Ok(received) => received,
        Err(_) => Err((
            None,
            Refusal::new(
                RefuseCode::Timeout,
                format!("no Hello within {} s", policy.timeout.as_secs_f32()),
            ),
        )),
    };
    let refusal = match received {
        Ok((hello, mut send)) => {
            let welcome = Message::Welcome(Welcome {
                version: policy.version,
                master_name: policy.master_name.clone(),
            });
            match write_message(&mut send, &welcome).await {
                Ok(()) => {
                    let _ = send.finish();
                    return Ok(hello);
                }
                Err(e) => Refusal::new(
                    RefuseCode::Disconnected,
                    format!("cannot send Welcome: {e}"),
                ),
            }
        }
        Err((send, refusal)) => {
            if let Some(send) = send {
                send_refusal(send, &refusal).await;
            }
            refusal
        }
    };
    conn.close(
        quinn::VarInt::from_u32(refusal.code.close_code()),
        truncate_utf8(&refusal.message, MAX_REASON_BYTES).as_bytes(),
    );
    Err(refusal)
}

/// Reads and checks the `Hello`. A refusal comes with the stream to send it
/// on, when there is one.
async fn receive_hello(
    conn: &quinn::Connection,
    policy: &HandshakePolicy,
) -> Result<(Hello, quinn::SendStream), (Option<quinn::SendStream>, Refusal)> {
    let (send, mut recv) = conn.accept_bi().await.map_err(|e| {
        let message = format!("connection lost before Hello: {e}");
        (None, Refusal::new(RefuseCode::Disconnected, message))
    })?;
    let refuse = |send, code, message: String| Err((Some(send), Refusal::new(code, message)));
    let body = match read_frame(&mut recv, ReadBounds::HANDSHAKE).await {
        Ok(body) => body,
        Err(ProtoError::Frame(FrameError::TooLarge { len, limit })) => {
            let message = format!("first message of {len} bytes exceeds {limit}");
            return refuse(send, RefuseCode::TooLarge, message);
        }
        Err(e @ (ProtoError::Closed | ProtoError::Frame(FrameError::Truncated { .. }))) => {
            return refuse(send, RefuseCode::BadMessage, format!("no whole Hello: {e}"));
        }
        Err(e) => {
            let message = format!("stream failed before Hello: {e}");
            return Err((None, Refusal::new(RefuseCode::Disconnected, message)));
        }
    };
    match check_hello(&body, policy) {
        Ok(hello) => Ok((hello, send)),
        Err(refusal) => Err((Some(send), refusal)),
    }
}

async fn send_refusal(mut send: quinn::SendStream, refusal: &Refusal) {
    let message = Message::Refused(refusal.clone());
    let delivered = async {
        write_message(&mut send, &message).await.ok()?;
        send.finish().ok()?;
        // Resolves once the client acknowledged everything (or stopped the stream).
        send.stopped().await.ok()
    };
    // Best effort: the close code carries the refusal anyway.
    let _ = tokio::time::timeout(REFUSAL_LINGER, delivered).await;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_reasons_are_cut_on_character_boundaries() {
        assert_eq!(truncate_utf8("abc", 2), "ab");
        assert_eq!(truncate_utf8("aé", 2), "a");
        assert_eq!(truncate_utf8("short", 200), "short");
    }
}
