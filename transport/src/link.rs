//! A message link: the two channel ends a session works with, whether the
//! peer is across a QUIC stream ([`Link::over_stream`]) or in the same
//! process ([`Link::pair`], the embedded master's local workers). Sessions are
//! written once against `Link` and never see the transport.

use std::sync::Arc;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender, unbounded_channel};
use tracing::{debug, warn};

use vtfarm_proto::{FrameError, Message, RefuseCode, StatusReply, encode_message};

use crate::stream::{ProtoError, ReadBounds, read_message};

/// One end of a message link.
#[derive(Debug)]
pub struct Link {
    /// Messages to the peer. Sending fails once the link is down.
    pub tx: UnboundedSender<Message>,
    /// Messages from the peer; `None` once the link is down. A link that
    /// failed on bad input says why in [`Link::error`] after that.
    pub rx: UnboundedReceiver<Message>,
    error: Arc<std::sync::Mutex<Option<ProtoError>>>,
}

impl Link {
    /// Two connected in-process ends.
    pub fn pair() -> (Link, Link) {
        let (a_tx, b_rx) = unbounded_channel();
        let (b_tx, a_rx) = unbounded_channel();
        let end = |tx, rx| Link {
            tx,
            rx,
            error: Arc::default(),
        };
        (end(a_tx, a_rx), end(b_tx, b_rx))
    }

    /// Asks the master for its status (a submitter's link): sends
    /// `StatusRequest` and waits for the `StatusReply`, skipping other
    /// messages; `None` once the link is down.
    pub async fn status(&mut self) -> Option<StatusReply> {
        self.tx.send(Message::StatusRequest).ok()?;
        loop {
            if let Message::StatusReply(reply) = self.rx.recv().await? {
                return Some(reply);
            }
        }
    }

    /// A link over a byte stream pair (a QUIC bidirectional stream): a task
    /// reads framed messages within `bounds` into `rx`, another writes `tx`
    /// out. The link goes down on the first error either way.
    pub fn over_stream<R, W>(recv: R, send: W, bounds: ReadBounds) -> Link
    where
        R: AsyncRead + Unpin + Send + 'static,
        W: AsyncWrite + Unpin + Send + 'static,
    {
        Link::with_read_error(recv, send, bounds, |_| {})
    }

    /// A link over a QUIC connection's session stream (after the handshake).
    /// Bad input from the peer — a length prefix over the limit, a body that
    /// does not decode, a stream cut inside a message, a message that
    /// stalls — is logged naming `peer` and closes the connection with the
    /// handshake's close code for it (3 bad message, 4 too large, 5 timed
    /// out) and the error as the reason.
    pub fn over_connection(
        connection: quinn::Connection,
        recv: quinn::RecvStream,
        send: quinn::SendStream,
        bounds: ReadBounds,
        peer: String,
    ) -> Link {
        Link::with_read_error(recv, send, bounds, move |e| {
            let code = match e {
                ProtoError::Frame(FrameError::TooLarge { .. }) => RefuseCode::TooLarge,
                ProtoError::Frame(FrameError::Decode(_) | FrameError::Truncated { .. }) => {
                    RefuseCode::BadMessage
                }
                ProtoError::Stalled { .. } => RefuseCode::Timeout,
                _ => return,
            };
            warn!(%peer, ?code, "closing the connection: {e}");
            let reason = e.to_string();
            connection.close(
                quinn::VarInt::from_u32(code.close_code()),
                crate::truncate_utf8(&reason, crate::handshake::MAX_REASON_BYTES).as_bytes(),
            );
        })
    }

    /// [`Link::over_stream`], calling `on_read_error` when reading fails
    /// other than by a clean close.
    fn with_read_error<R, W>(
        mut recv: R,
        mut send: W,
        bounds: ReadBounds,
        on_read_error: impl FnOnce(&ProtoError) + Send + 'static,
    ) -> Link
    where
        R: AsyncRead + Unpin + Send + 'static,
        W: AsyncWrite + Unpin + Send + 'static,
    {
        let (in_tx, rx) = unbounded_channel();
        let (tx, mut out_rx) = unbounded_channel::<Message>();
        let error = Arc::new(std::sync::Mutex::new(None));
        let read_error = error.clone();
        tokio::spawn(async move {
            loop {
                match read_message(&mut recv, bounds).await {
                    Ok(message) => {
                        if in_tx.send(message).is_err() {
                            break;
                        }
                    }
                    Err(e) => {
                        debug!("link read ended: {e}");
                        if !matches!(e, ProtoError::Closed) {
                            on_read_error(&e);
                            *read_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                        }
                        break;
                    }
                }
            }
        });
        tokio::spawn(async move {
            use tokio::io::AsyncWriteExt;
            while let Some(message) = out_rx.recv().await {
                let Ok(frame) = encode_message(&message) else {
                    break;
                };
                if send.write_all(&frame).await.is_err() {
                    break;
                }
            }
            let _ = send.shutdown().await;
        });
        Link { tx, rx, error }
    }

    /// Why the link went down, when it was bad input rather than a close.
    pub fn error(&self) -> Option<String> {
        self.error
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .map(ToString::to_string)
    }
}
