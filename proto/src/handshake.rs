//! The handshake every connection starts with, on its first bidirectional
//! stream: the client sends `Hello`, the master answers `Welcome` or
//! `Refused`; both messages are limited to [`MAX_HANDSHAKE_BYTES`]. Both
//! ends then finish that stream; the session continues on new streams.
//!
//! On a refusal the master sends `Refused`, waits up to [`REFUSAL_LINGER`]
//! for it to be acknowledged, and closes the connection with the code's
//! [`RefuseCode::close_code`] and the reason. A client that lost the
//! message (QUIC may drop undelivered stream data on close) still gets the
//! refusal from the close code, so [`client_handshake`] reports
//! [`ProtoError::Refused`] either way. The client never closes the
//! connection itself on a refusal.
//!
//! The master checks, in order: magic, version, token. Versions are read
//! even from a `Hello` that does not decode as this version's, because its
//! leading fields are frozen (see [`crate::message`]).

use std::time::Duration;

use crate::cluster::token_matches;
use crate::framing::{
    MAX_HANDSHAKE_BYTES, ProtoError, decode_message, read_frame, read_message, write_message,
};
use crate::message::{Hello, Message, Refusal, RefuseCode, Welcome};
use crate::truncate_utf8;

/// How long the master waits for a complete `Hello` (and a client for the answer).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// How long the master waits for a `Refused` to be acknowledged before closing.
pub const REFUSAL_LINGER: Duration = Duration::from_secs(1);
/// The application close code of an orderly close (`Shutdown`, job done).
pub const CLOSE_NORMAL: quinn::VarInt = quinn::VarInt::from_u32(0);
/// Close reasons are cut to this many bytes to fit one packet.
pub(crate) const MAX_REASON_BYTES: usize = 200;

/// What the master accepts and how it introduces itself.
#[derive(Clone, PartialEq, Eq)]
pub struct HandshakePolicy {
    /// The cluster token every `Hello` must present.
    pub token: String,
    /// The protocol version to accept and to answer with.
    pub version: u32,
    /// The name in `Welcome`.
    pub master_name: String,
    /// How long a client may take to send its `Hello`.
    pub timeout: Duration,
}

impl HandshakePolicy {
    /// This build's version and the default timeout.
    pub fn new(token: impl Into<String>, master_name: impl Into<String>) -> Self {
        HandshakePolicy {
            token: token.into(),
            version: crate::PROTOCOL_VERSION,
            master_name: master_name.into(),
            timeout: HANDSHAKE_TIMEOUT,
        }
    }
}

impl std::fmt::Debug for HandshakePolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Logs must not leak the token.
        f.debug_struct("HandshakePolicy")
            .field("version", &self.version)
            .field("master_name", &self.master_name)
            .field("timeout", &self.timeout)
            .finish_non_exhaustive()
    }
}

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
    match read_message(&mut recv, MAX_HANDSHAKE_BYTES).await? {
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
            let code = RefuseCode::from_close_code(close.error_code)?;
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
        refusal.code.close_code(),
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
    let body = match read_frame(&mut recv, MAX_HANDSHAKE_BYTES).await {
        Ok(body) => body,
        Err(ProtoError::TooLarge { len, limit }) => {
            let message = format!("first message of {len} bytes exceeds {limit}");
            return refuse(send, RefuseCode::TooLarge, message);
        }
        Err(e @ (ProtoError::Closed | ProtoError::Truncated { .. })) => {
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

/// Checks the body of a connection's first message (without its length
/// prefix): a `Hello` with the magic, the policy's version and token. No I/O,
/// so it can be fuzzed and tested alone.
pub fn check_hello(body: &[u8], policy: &HandshakePolicy) -> Result<Hello, Refusal> {
    let refuse = |code, message: String| Err(Refusal::new(code, message));
    let hello = match decode_message(body) {
        Ok(Message::Hello(hello)) => hello,
        Ok(other) => {
            let message = format!("expected Hello, got {}", other.name());
            return refuse(RefuseCode::BadMessage, message);
        }
        Err(e) => {
            // A Hello of another version need not decode as ours.
            return match frozen_hello_version(body) {
                Some(v) if v != policy.version => {
                    refuse(RefuseCode::BadVersion, unsupported(v, policy.version))
                }
                _ => refuse(RefuseCode::BadMessage, format!("not a vtfarm Hello: {e}")),
            };
        }
    };
    if hello.magic != crate::MAGIC {
        return refuse(
            RefuseCode::BadMessage,
            "not a vtfarm Hello: bad magic".to_owned(),
        );
    }
    if hello.version != policy.version {
        let message = unsupported(hello.version, policy.version);
        return refuse(RefuseCode::BadVersion, message);
    }
    if !token_matches(&policy.token, &hello.token) {
        return refuse(RefuseCode::BadToken, "wrong cluster token".to_owned());
    }
    Ok(hello)
}

fn unsupported(version: u32, ours: u32) -> String {
    format!("protocol version {version} is not supported (master speaks {ours})")
}

/// The version of a `Hello` body of any protocol version: variant 0, the
/// magic, then the version as a bincode varint. `None` if the body does not
/// start that way.
fn frozen_hello_version(body: &[u8]) -> Option<u32> {
    let rest = body.strip_prefix(&[0])?.strip_prefix(&crate::MAGIC[..])?;
    // bincode's varint: one byte below 251, else a marker and a little-endian integer.
    let v = match *rest.first()? {
        b @ 0..=250 => u64::from(b),
        251 => u16::from_le_bytes(rest.get(1..3)?.try_into().ok()?).into(),
        252 => u32::from_le_bytes(rest.get(1..5)?.try_into().ok()?).into(),
        _ => return None,
    };
    u32::try_from(v).ok()
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
    use crate::framing::encode_message;
    use crate::message::Role;

    #[test]
    fn the_version_of_any_hello_can_be_read() {
        for version in [0, 1, 250, 251, 65535, 65536, u32::MAX] {
            let hello = Hello {
                version,
                ..Hello::new("t", Role::Submitter)
            };
            let frame = encode_message(&Message::Hello(hello)).expect("encodes");
            let mut body = frame[4..].to_vec();
            assert_eq!(frozen_hello_version(&body), Some(version));
            // A future Hello with more fields still shows its version.
            body.extend_from_slice(b"future fields");
            assert_eq!(frozen_hello_version(&body), Some(version));
        }
        assert_eq!(frozen_hello_version(&[1]), None);
        assert_eq!(frozen_hello_version(b"\0VTFARM\0\0"), None);
        assert_eq!(frozen_hello_version(b"\0VTFARX\0\0\x01"), None);
    }

    #[test]
    fn close_reasons_are_cut_on_character_boundaries() {
        assert_eq!(truncate_utf8("abc", 2), "ab");
        assert_eq!(truncate_utf8("aé", 2), "a");
        assert_eq!(truncate_utf8("short", 200), "short");
    }
}
