//! Messages over a byte stream (a QUIC stream, tokio's I/O traits): the
//! wire's framing (`vtfarm_proto::framing`) read and written
//! asynchronously. The reader checks the length prefix before it allocates
//! anything and then lets the body buffer grow only as bytes actually
//! arrive, so a peer that announces 256 MiB and sends nothing costs nothing;
//! and once a message has begun, each read must bring bytes within the
//! stall bound ([`ReadBounds::stall`]), so such a peer is not waited on
//! for ever either.

use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use vtfarm_proto::{
    FrameError, HANDSHAKE_TIMEOUT, MAX_HANDSHAKE_BYTES, MESSAGE_STALL, Message, RefuseCode,
    SESSION_LIMIT, body_len, decode_message, encode_message,
};

/// What a reader allows its peer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReadBounds {
    /// The largest message body (clamped to [`vtfarm_proto::MAX_MESSAGE_BYTES`]).
    pub limit: u32,
    /// Once a message's first byte is in, the longest wait for the next.
    pub stall: Duration,
}

impl ReadBounds {
    /// A session's messages, after the handshake.
    pub const SESSION: ReadBounds = ReadBounds {
        limit: SESSION_LIMIT,
        stall: MESSAGE_STALL,
    };

    /// A connection's first message and its answer (under the handshake's
    /// own timeout as a whole).
    pub const HANDSHAKE: ReadBounds = ReadBounds {
        limit: MAX_HANDSHAKE_BYTES,
        stall: HANDSHAKE_TIMEOUT,
    };
}

/// The body buffer starts at most this big and grows with the data received.
const INITIAL_BODY_CAPACITY: usize = 64 * 1024;

/// Why a message could not be read or written (and why a handshake failed).
#[derive(Debug, thiserror::Error)]
pub enum ProtoError {
    /// The stream failed.
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
    /// The frame does not hold a message (too large, cut short, garbage).
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The stream ended cleanly at a message boundary.
    #[error("stream closed")]
    Closed,
    /// The master refused the handshake.
    #[error("refused by the master ({code:?}): {message}")]
    Refused { code: RefuseCode, message: String },
    /// The QUIC connection failed.
    #[error("connection failed: {0}")]
    Connection(#[from] quinn::ConnectionError),
    /// A well-formed message that does not belong here.
    #[error("expected {expected}, got {got}")]
    Unexpected {
        expected: &'static str,
        got: &'static str,
    },
    /// The peer took too long.
    #[error("timed out")]
    Timeout,
    /// A message began and then stopped coming.
    #[error(
        "message stalled: {received} of {expected} bytes in, nothing more for {:.1} s",
        stall.as_secs_f64()
    )]
    Stalled {
        received: u64,
        expected: u64,
        stall: Duration,
    },
}

/// Reads one message within `bounds`. Clean end of stream before the first
/// byte gives [`ProtoError::Closed`]; a message that stops coming for
/// [`ReadBounds::stall`] gives [`ProtoError::Stalled`].
pub async fn read_message<R: AsyncRead + Unpin>(
    r: &mut R,
    bounds: ReadBounds,
) -> Result<Message, ProtoError> {
    let body = read_frame(r, bounds).await?;
    Ok(decode_message(&body)?)
}

/// Reads one frame's body, checking its length against the limit first.
pub(crate) async fn read_frame<R: AsyncRead + Unpin>(
    r: &mut R,
    bounds: ReadBounds,
) -> Result<Vec<u8>, ProtoError> {
    let mut prefix = [0u8; 4];
    let mut filled = 0;
    while filled < prefix.len() {
        let read = r.read(&mut prefix[filled..]);
        // Between messages the peer may idle; inside one it may not stall.
        let n = match filled {
            0 => read.await?,
            _ => within(bounds.stall, filled as u64, 4, read).await?,
        };
        if n == 0 {
            return Err(if filled == 0 {
                ProtoError::Closed
            } else {
                ProtoError::Frame(FrameError::Truncated {
                    expected: 4,
                    received: filled as u64,
                })
            });
        }
        filled += n;
    }
    let len = body_len(prefix, bounds.limit)?;
    let expected = 4 + u64::from(len);
    let mut body = Vec::with_capacity((len as usize).min(INITIAL_BODY_CAPACITY));
    let mut rest = (&mut *r).take(len.into());
    while body.len() < len as usize {
        let received = 4 + body.len() as u64;
        let n = within(bounds.stall, received, expected, rest.read_buf(&mut body)).await?;
        if n == 0 {
            return Err(ProtoError::Frame(FrameError::Truncated {
                expected,
                received,
            }));
        }
    }
    Ok(body)
}

/// `read` if it completes within `stall`; else the message stalled at
/// `received` of `expected` bytes.
async fn within(
    stall: Duration,
    received: u64,
    expected: u64,
    read: impl Future<Output = std::io::Result<usize>>,
) -> Result<usize, ProtoError> {
    match tokio::time::timeout(stall, read).await {
        Ok(read) => Ok(read?),
        Err(_) => Err(ProtoError::Stalled {
            received,
            expected,
            stall,
        }),
    }
}

/// Writes one message (prefix and body) and flushes.
pub async fn write_message<W: AsyncWrite + Unpin>(
    w: &mut W,
    message: &Message,
) -> Result<(), ProtoError> {
    let frame = encode_message(message)?;
    w.write_all(&frame).await?;
    w.flush().await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::pin::Pin;
    use std::task::{Context, Poll};

    use vtfarm_proto::{MAX_HANDSHAKE_BYTES, MAX_MESSAGE_BYTES};

    use super::*;

    fn block_on<F: std::future::Future>(f: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .expect("a current-thread runtime builds")
            .block_on(f)
    }

    fn bounds(limit: u32) -> ReadBounds {
        ReadBounds {
            limit,
            ..ReadBounds::SESSION
        }
    }

    fn read_all(bytes: &[u8], limit: u32) -> Result<Message, ProtoError> {
        let mut reader = bytes;
        block_on(read_message(&mut reader, bounds(limit)))
    }

    #[tokio::test]
    async fn messages_round_trip_through_a_stream() {
        let messages = [
            Message::Heartbeat,
            Message::JobAccepted {
                job: vtfarm_proto::JobId(1),
                frames: 2,
            },
            Message::StatusRequest,
        ];
        let (mut a, mut b) = tokio::io::duplex(16);
        let sent = messages.clone();
        let writer = tokio::spawn(async move {
            for m in &sent {
                write_message(&mut a, m).await.expect("duplex accepts");
            }
        });
        for expected in &messages {
            let got = read_message(&mut b, ReadBounds::SESSION)
                .await
                .expect("a whole message");
            assert_eq!(&got, expected);
        }
        writer.await.expect("writer finished");
        // The writer dropped its end at a message boundary.
        assert!(matches!(
            read_message(&mut b, ReadBounds::SESSION).await,
            Err(ProtoError::Closed)
        ));
    }

    /// A reader that yields `prefix` and then fails the test if read again.
    struct PrefixOnly {
        prefix: Vec<u8>,
    }

    impl AsyncRead for PrefixOnly {
        fn poll_read(
            mut self: Pin<&mut Self>,
            _: &mut Context<'_>,
            buf: &mut tokio::io::ReadBuf<'_>,
        ) -> Poll<std::io::Result<()>> {
            assert!(!self.prefix.is_empty(), "read past the length prefix");
            let n = self.prefix.len().min(buf.remaining());
            buf.put_slice(&self.prefix[..n]);
            self.prefix.drain(..n);
            Poll::Ready(Ok(()))
        }
    }

    #[tokio::test]
    async fn oversized_prefixes_are_rejected_before_reading_the_body() {
        for (len, limit) in [
            (MAX_HANDSHAKE_BYTES + 1, MAX_HANDSHAKE_BYTES),
            (u32::MAX, MAX_MESSAGE_BYTES),
            // A caller's limit above the maximum is clamped.
            (MAX_MESSAGE_BYTES + 1, u32::MAX),
        ] {
            let mut r = PrefixOnly {
                prefix: len.to_le_bytes().to_vec(),
            };
            match read_message(&mut r, bounds(limit)).await {
                Err(ProtoError::Frame(FrameError::TooLarge { len: l, limit: m })) => {
                    assert_eq!((l, m), (len.into(), limit.min(MAX_MESSAGE_BYTES)));
                }
                other => panic!("expected TooLarge, got {other:?}"),
            }
        }
    }

    /// A peer that announces a message, sends part of it and goes silent
    /// (its end still open) is given up on after the stall bound; one that
    /// is silent between messages is waited for.
    #[tokio::test]
    async fn a_message_that_stops_coming_stalls_and_an_idle_stream_does_not() {
        let stall = Duration::from_millis(50);
        let bounds = ReadBounds {
            stall,
            ..ReadBounds::SESSION
        };
        let (mut peer, mut reader) = tokio::io::duplex(1 << 16);
        let mut begun = 1000u32.to_le_bytes().to_vec();
        begun.extend_from_slice(&[7; 10]);
        peer.write_all(&begun).await.expect("duplex accepts");
        match read_message(&mut reader, bounds).await {
            Err(ProtoError::Stalled {
                received,
                expected,
                stall: s,
            }) => {
                assert_eq!((received, expected, s), (14, 1004, stall));
            }
            other => panic!("expected a stall, got {other:?}"),
        }
        // Half a prefix stalls too.
        let (mut peer, mut reader) = tokio::io::duplex(1 << 16);
        peer.write_all(&[1, 0]).await.expect("duplex accepts");
        assert!(matches!(
            read_message(&mut reader, bounds).await,
            Err(ProtoError::Stalled {
                received: 2,
                expected: 4,
                ..
            })
        ));
        // Nothing at all: still waiting after many stall bounds.
        let (_peer, mut reader) = tokio::io::duplex(1 << 16);
        let idle = tokio::time::timeout(20 * stall, read_message(&mut reader, bounds)).await;
        assert!(
            idle.is_err(),
            "an idle stream is not a stalled message: {idle:?}"
        );
    }

    #[test]
    fn truncated_streams_are_told_from_clean_closes() {
        assert!(matches!(read_all(&[], 100), Err(ProtoError::Closed)));
        assert!(matches!(
            read_all(&[3, 0], 100),
            Err(ProtoError::Frame(FrameError::Truncated {
                expected: 4,
                received: 2
            }))
        ));
        let whole = encode_message(&Message::JobAccepted {
            job: vtfarm_proto::JobId(1),
            frames: 2,
        })
        .expect("encodes");
        let cut = &whole[..whole.len() - 1];
        assert!(matches!(
            read_all(cut, 100),
            Err(ProtoError::Frame(FrameError::Truncated { expected, received }))
                if expected == whole.len() as u64 && received == cut.len() as u64
        ));
    }
}
