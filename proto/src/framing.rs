//! Framing: each message is a 4-byte little-endian body length followed by
//! the bincode body (`bincode::config::standard()`, serde).
//!
//! The reader checks the length against the caller's limit before it
//! allocates anything, and then lets the body buffer grow only as bytes
//! actually arrive, so a peer that announces 256 MiB and sends nothing costs
//! nothing. Decoding runs under a bincode limit scaled to the body's size,
//! so a small body cannot claim a huge vector either.

use serde::Serialize;
use serde::de::DeserializeOwned;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use crate::message::{Message, RefuseCode};

/// The largest message body: scene data and finished frames are the big ones.
pub const MAX_MESSAGE_BYTES: u32 = 256 * 1024 * 1024;
/// The largest first message of a connection (the `Hello` and its answer),
/// read before the peer has shown a token.
pub const MAX_HANDSHAKE_BYTES: u32 = 64 * 1024;

/// The body buffer starts at most this big and grows with the data received.
const INITIAL_BODY_CAPACITY: usize = 64 * 1024;

/// Why a message could not be read or written (and why a handshake failed).
#[derive(Debug, thiserror::Error)]
pub enum ProtoError {
    /// The stream failed.
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
    /// The length prefix (or an outgoing message) exceeds the limit.
    #[error("message of {len} bytes exceeds the limit of {limit} bytes")]
    TooLarge { len: u64, limit: u32 },
    /// The body is not a valid message (garbage, an unknown variant, bytes
    /// left over after the message).
    #[error("cannot decode message: {0}")]
    Decode(String),
    /// The message could not be encoded (does not happen for vtfarm's types).
    #[error("cannot encode message: {0}")]
    Encode(String),
    /// The stream ended cleanly at a message boundary.
    #[error("stream closed")]
    Closed,
    /// The stream ended inside a message: `received` of `expected` bytes
    /// (counting the 4-byte prefix).
    #[error("stream ended inside a message: {received} of {expected} bytes")]
    Truncated { expected: u64, received: u64 },
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
}

/// Reads one message whose body may be at most `limit` bytes (clamped to
/// [`MAX_MESSAGE_BYTES`]). Clean end of stream before the first byte gives
/// [`ProtoError::Closed`].
pub async fn read_message<R: AsyncRead + Unpin>(
    r: &mut R,
    limit: u32,
) -> Result<Message, ProtoError> {
    let body = read_frame(r, limit).await?;
    decode_message(&body)
}

/// Reads one frame's body, checking its length against `limit` first.
pub(crate) async fn read_frame<R: AsyncRead + Unpin>(
    r: &mut R,
    limit: u32,
) -> Result<Vec<u8>, ProtoError> {
    let limit = limit.min(MAX_MESSAGE_BYTES);
    let mut prefix = [0u8; 4];
    let mut filled = 0;
    while filled < prefix.len() {
        let n = r.read(&mut prefix[filled..]).await?;
        if n == 0 {
            return Err(if filled == 0 {
                ProtoError::Closed
            } else {
                ProtoError::Truncated {
                    expected: 4,
                    received: filled as u64,
                }
            });
        }
        filled += n;
    }
    let len = u32::from_le_bytes(prefix);
    if len > limit {
        return Err(ProtoError::TooLarge {
            len: len.into(),
            limit,
        });
    }
    let mut body = Vec::with_capacity((len as usize).min(INITIAL_BODY_CAPACITY));
    let received = (&mut *r).take(len.into()).read_to_end(&mut body).await?;
    if received < len as usize {
        return Err(ProtoError::Truncated {
            expected: 4 + u64::from(len),
            received: 4 + received as u64,
        });
    }
    Ok(body)
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

/// One message as a whole frame: the length prefix and the body.
pub fn encode_message(message: &Message) -> Result<Vec<u8>, ProtoError> {
    let mut frame = vec![0u8; 4];
    bincode::serde::encode_into_std_write(message, &mut frame, bincode::config::standard())
        .map_err(|e| ProtoError::Encode(e.to_string()))?;
    let len = frame.len() - 4;
    match u32::try_from(len) {
        Ok(len) if len <= MAX_MESSAGE_BYTES => {
            frame[..4].copy_from_slice(&len.to_le_bytes());
            Ok(frame)
        }
        _ => Err(ProtoError::TooLarge {
            len: len as u64,
            limit: MAX_MESSAGE_BYTES,
        }),
    }
}

/// Decodes a message body (without the prefix); the body must hold exactly
/// one message.
pub fn decode_message(body: &[u8]) -> Result<Message, ProtoError> {
    decode_value(body).map_err(ProtoError::Decode)
}

/// The size on the wire of `message` (length prefix included), counted
/// without encoding it into a buffer: for transfer statistics.
pub fn encoded_len(message: &Message) -> u64 {
    let mut size = bincode::enc::write::SizeWriter::default();
    // Same encoding as `encode_message`, which cannot fail for vtfarm's types.
    let _ = bincode::serde::encode_into_writer(message, &mut size, bincode::config::standard());
    4 + size.bytes_written as u64
}

/// bincode of a local value (standard configuration).
pub(crate) fn encode_value<T: Serialize>(value: &T) -> Vec<u8> {
    // Derived serde impls of owned data with known lengths cannot fail to encode.
    bincode::serde::encode_to_vec(value, bincode::config::standard())
        .expect("vtfarm's wire types always encode")
}

/// Decodes exactly one `T` from `bytes` under a bincode limit scaled to the
/// input: bincode allocates a claimed `Vec<u8>` before reading it, so the
/// limit bounds what a short body can make us allocate. The limit counts
/// decoded (in-memory) bytes, up to 8 per wire byte for small varints, hence
/// the 16× headroom.
pub(crate) fn decode_value<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    use bincode::config::standard;
    const KIB: usize = 1024;
    const MIB: usize = 1024 * KIB;
    const TOP: usize = (MAX_MESSAGE_BYTES as usize).saturating_mul(16);
    let decoded = match bytes.len() {
        n if n <= 64 * KIB => decode_with(bytes, standard().with_limit::<{ MIB }>()),
        n if n <= MIB => decode_with(bytes, standard().with_limit::<{ 16 * MIB }>()),
        n if n <= 16 * MIB => decode_with(bytes, standard().with_limit::<{ 256 * MIB }>()),
        _ => decode_with(bytes, standard().with_limit::<TOP>()),
    };
    let (value, used) = decoded.map_err(|e| e.to_string())?;
    if used != bytes.len() {
        return Err(format!(
            "{} bytes left over after the message",
            bytes.len() - used
        ));
    }
    Ok(value)
}

fn decode_with<T: DeserializeOwned, C: bincode::config::Config>(
    bytes: &[u8],
    config: C,
) -> Result<(T, usize), bincode::error::DecodeError> {
    bincode::serde::decode_from_slice(bytes, config)
}

#[cfg(test)]
mod tests {
    use std::pin::Pin;
    use std::task::{Context, Poll};
    use std::time::Duration;

    use crate::WorkerFrameStats;
    use glam::Vec3;
    use proptest::prelude::*;
    use vtfarm_method::FrameSetup;
    use vtfarm_trace::TraceSettings;
    use vtfarm_vertex::{PackageStats, VertexSettings};

    use super::*;
    use crate::message::*;
    use crate::wire::tests::{bitmap, camera, lighting, scene};
    use crate::wire::{WireBitmap, WireFrameSetup, WireImage, WirePackageStats};

    fn setup() -> WireFrameSetup {
        WireFrameSetup::from(&FrameSetup {
            camera: camera(),
            lighting: lighting(),
            trace: TraceSettings::default(),
            vertex: VertexSettings::default(),
        })
    }

    /// One of every message.
    #[test]
    fn encoded_len_is_the_framed_size() {
        for message in every_message() {
            let framed = encode_message(&message).expect("encodes");
            assert_eq!(
                encoded_len(&message),
                framed.len() as u64,
                "{}",
                message.name()
            );
        }
    }

    fn every_message() -> Vec<Message> {
        let hash = scene_hash(&scene());
        let stats = WirePackageStats::from(&PackageStats {
            pixels: 4,
            vertex_time: Duration::from_micros(1500),
            ..PackageStats::default()
        });
        vec![
            Message::Hello(Hello::new(
                "secret",
                Role::Worker {
                    threads: 16,
                    name: "node-7".to_owned(),
                },
            )),
            Message::Hello(Hello::new("secret", Role::Submitter)),
            Message::Welcome(Welcome {
                version: crate::PROTOCOL_VERSION,
                master_name: "master".to_owned(),
            }),
            Message::Refused(Refusal::new(RefuseCode::BadToken, "wrong token")),
            Message::SceneOffer { hash },
            Message::SceneRequest { hash },
            Message::SceneData(SceneData::from_scene(&scene())),
            Message::FrameStart(FrameStart {
                job: 3,
                frame: 1,
                scene: hash,
                setup: setup(),
                reflectors: vec![0, 1],
                method: crate::WireMethod::Pvrr,
                aux: true,
            }),
            Message::RequestWork { job: 3, frame: 1 },
            Message::Package(Package {
                id: 99,
                job: 3,
                frame: 1,
                triangles: vec![1, 0],
            }),
            Message::PackageResult(PackageResult {
                id: 99,
                bitmap: WireBitmap::from(&bitmap()),
                stats,
                busy_micros: 1234,
                setup_micros: 56,
                triangle_samples: vec![3, 0, 17],
            }),
            Message::PackageFailed(PackageFailed {
                id: 98,
                error: "no scene".to_owned(),
            }),
            Message::CancelPackage { id: 97 },
            Message::Heartbeat,
            Message::Shutdown,
            Message::SubmitJob {
                job: WireJob {
                    name: "cab".to_owned(),
                    scene: JobScene::Data(SceneData::from_scene(&scene())),
                    frames: vec![setup(), setup()],
                    reflectors: vec![0],
                    aux: true,
                    method: crate::WireMethod::CubeMapGrid,
                    image: crate::WireImageFormat::LinearF32,
                },
            },
            Message::SubmitJob {
                job: WireJob {
                    name: "again".to_owned(),
                    scene: JobScene::Hash(hash),
                    frames: vec![setup()],
                    reflectors: vec![1],
                    aux: false,
                    method: crate::WireMethod::VertexTracing,
                    image: crate::WireImageFormat::Srgb8,
                },
            },
            Message::JobAccepted { job: 3, frames: 2 },
            Message::Progress {
                job: 3,
                frame: 1,
                done: 5,
                total: 8,
            },
            Message::FrameDone(FrameDone {
                job: 3,
                frame: 1,
                image: WireImage::from_pixels(2, 1, &[Vec3::X, Vec3::ONE]),
                aux: Some(WireFrameAux::encode(
                    &vtfarm_vertex::FrameImage::from_components(
                        vtfarm_imaging::Image::black(2, 1),
                        vtfarm_vertex::Components {
                            reflected: vtfarm_imaging::Image {
                                width: 2,
                                height: 1,
                                pixels: vec![Vec3::ZERO, Vec3::Y],
                            },
                            transmitted: vtfarm_imaging::Image {
                                width: 2,
                                height: 1,
                                pixels: vec![Vec3::ZERO, Vec3::Z],
                            },
                            reflected_object: vec![vtfarm_scene::NONE, 4],
                            mask: vec![false, true],
                        },
                    ),
                )),
                stats: FrameStats {
                    packages: 8,
                    failures: 1,
                    wall_micros: 5_000,
                    imbalance: 0.04,
                    speedup: 1.9,
                    totals: stats,
                    workers: vec![WorkerFrameStats {
                        name: "w1".into(),
                        busy_micros: 4_000,
                        packages: 3,
                        triangles: 70,
                        rays: 900,
                        bytes_in: 100,
                        bytes_out: 2_000,
                    }],
                    ..FrameStats::default()
                },
            }),
            Message::JobFailed {
                job: 4,
                errors: vec!["scene missing".to_owned()],
            },
            Message::StatusRequest,
            Message::StatusReply(StatusReply {
                workers: vec![WorkerStatus {
                    name: "node-7".to_owned(),
                    address: "10.0.0.7:50123".to_owned(),
                    threads: 16,
                    state: "busy".to_owned(),
                    throughput: 1.5e6,
                    packages_running: 1,
                    packages_done: 40,
                    triangles_done: 4_000,
                    failures: 1,
                    busy_micros: 3_600_000,
                }],
                queue: QueueStatus {
                    waiting: vec![9],
                    running: Some(RunningJob {
                        job: 8,
                        name: "cockpit".to_owned(),
                        frame: 1,
                        frames: 3,
                        triangles_done: 100,
                        triangles_total: 576,
                    }),
                },
                scene_bytes_sent: 12_345,
            }),
        ]
    }

    fn block_on<F: std::future::Future>(f: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread()
            .build()
            .expect("a current-thread runtime builds")
            .block_on(f)
    }

    fn read_all(bytes: &[u8], limit: u32) -> Result<Message, ProtoError> {
        let mut reader = bytes;
        block_on(read_message(&mut reader, limit))
    }

    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = (body.len() as u32).to_le_bytes().to_vec();
        f.extend_from_slice(body);
        f
    }

    #[tokio::test]
    async fn every_message_round_trips_through_a_stream() {
        let messages = every_message();
        // Every variant is covered (the list has two extra alternatives).
        let names: std::collections::BTreeSet<_> = messages.iter().map(Message::name).collect();
        assert_eq!(names.len(), 21);
        let (mut a, mut b) = tokio::io::duplex(1024);
        let sent = messages.clone();
        let writer = tokio::spawn(async move {
            for m in &sent {
                write_message(&mut a, m).await.expect("duplex accepts");
            }
        });
        for expected in &messages {
            let got = read_message(&mut b, MAX_MESSAGE_BYTES)
                .await
                .expect("a whole message");
            assert_eq!(&got, expected);
        }
        writer.await.expect("writer finished");
        // The writer dropped its end at a message boundary.
        assert!(matches!(
            read_message(&mut b, MAX_MESSAGE_BYTES).await,
            Err(ProtoError::Closed)
        ));
    }

    #[test]
    fn frames_are_length_prefixed_little_endian() {
        let f = encode_message(&Message::Heartbeat).expect("encodes");
        assert_eq!(f.len(), 5);
        assert_eq!(f[..4], 1u32.to_le_bytes());
        assert_eq!(
            decode_message(&f[4..]).expect("decodes"),
            Message::Heartbeat
        );
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
            match read_message(&mut r, limit).await {
                Err(ProtoError::TooLarge { len: l, limit: m }) => {
                    assert_eq!((l, m), (len.into(), limit.min(MAX_MESSAGE_BYTES)));
                }
                other => panic!("expected TooLarge, got {other:?}"),
            }
        }
    }

    #[test]
    fn garbage_bodies_are_decode_errors() {
        for body in [
            &[0xff, 0xff, 0xff, 0xff, 0xff][..],
            // Variant 0 (Hello) cut short.
            &[0, b'V', b'T'][..],
            b"GET / HTTP/1.1",
        ] {
            let result = read_all(&frame(body), MAX_MESSAGE_BYTES);
            assert!(
                matches!(result, Err(ProtoError::Decode(_))),
                "{body:?}: {result:?}"
            );
        }
        // A valid message followed by junk inside the same frame.
        let mut body = encode_message(&Message::Heartbeat).expect("encodes")[4..].to_vec();
        body.push(0);
        let error = read_all(&frame(&body), MAX_MESSAGE_BYTES).expect_err("left over");
        assert!(error.to_string().contains("1 bytes left over"), "{error}");
    }

    #[test]
    fn a_small_body_cannot_claim_a_huge_allocation() {
        // SceneData { hash, bytes } whose byte vector claims 200 MB (varint
        // 0xfc + u32) in a body of 40 bytes.
        let mut body = vec![5u8]; // variant SceneData
        body.extend_from_slice(&[7; 32]);
        body.push(0xfc);
        body.extend_from_slice(&200_000_000u32.to_le_bytes());
        body.extend_from_slice(&[1, 2, 3]);
        let result = read_all(&frame(&body), MAX_MESSAGE_BYTES);
        assert!(matches!(result, Err(ProtoError::Decode(_))), "{result:?}");
    }

    #[test]
    fn truncated_streams_are_told_from_clean_closes() {
        assert!(matches!(read_all(&[], 100), Err(ProtoError::Closed)));
        assert!(matches!(
            read_all(&[3, 0], 100),
            Err(ProtoError::Truncated {
                expected: 4,
                received: 2
            })
        ));
        let whole = encode_message(&Message::JobAccepted { job: 1, frames: 2 }).expect("encodes");
        let cut = &whole[..whole.len() - 1];
        assert!(matches!(
            read_all(cut, 100),
            Err(ProtoError::Truncated { expected, received })
                if expected == whole.len() as u64 && received == cut.len() as u64
        ));
    }

    proptest! {
        #[test]
        fn random_streams_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = read_all(&bytes, MAX_HANDSHAKE_BYTES);
        }

        #[test]
        fn random_bodies_never_panic(
            variant in 0u8..24,
            body in proptest::collection::vec(any::<u8>(), 0..512),
        ) {
            // A plausible variant tag gets the decoder past the first byte.
            let mut b = vec![variant];
            b.extend_from_slice(&body);
            if let Ok(m) = decode_message(&b) {
                // Whatever decodes can be sent on.
                prop_assert!(encode_message(&m).is_ok());
            }
        }

        #[test]
        fn mutated_messages_never_panic(
            which in 0usize..23,
            flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
        ) {
            let mut body = encode_message(&every_message()[which]).expect("encodes")[4..].to_vec();
            for (at, value) in flips {
                let i = at.index(body.len());
                body[i] = value;
            }
            let _ = decode_message(&body);
        }
    }
}
