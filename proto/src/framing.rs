//! Framing: each message is a 4-byte little-endian body length followed by
//! the bincode body (`bincode::config::standard()`, serde).
//!
//! A length prefix is checked against the reader's limit ([`body_len`])
//! before anything is allocated; the stream reader (`vtfarm-transport`) then
//! lets the body buffer grow only as bytes actually arrive, so a peer that
//! announces 256 MiB and sends nothing costs nothing. Decoding runs under a
//! bincode limit scaled to the body's size, so a small body cannot claim a
//! huge vector either. No I/O here: frames in memory only.

use std::time::Duration;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::message::Message;

/// The largest message body: scene data and finished frames are the big ones.
pub const MAX_MESSAGE_BYTES: u32 = 256 * 1024 * 1024;
/// The largest first message of a connection (the `Hello` and its answer),
/// read before the peer has shown a token.
pub const MAX_HANDSHAKE_BYTES: u32 = 64 * 1024;

/// The limit of a session's messages (after the handshake): the protocol's
/// maximum, since scene data and finished frames travel on the session.
pub const SESSION_LIMIT: u32 = MAX_MESSAGE_BYTES;

/// Once a message's first byte is in, the longest a reader waits for the
/// next one. A session may idle between messages (QUIC keeps the
/// connection alive), but a peer that announces a message and goes silent
/// inside it is closed.
pub const MESSAGE_STALL: Duration = Duration::from_secs(10);

/// Why a frame does not hold a message (or a message makes no frame).
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The length prefix (or an outgoing message) exceeds the limit.
    #[error("message of {len} bytes exceeds the limit of {limit} bytes")]
    TooLarge { len: u64, limit: u32 },
    /// The bytes end inside a message: `received` of `expected` bytes
    /// (counting the 4-byte prefix).
    #[error("stream ended inside a message: {received} of {expected} bytes")]
    Truncated { expected: u64, received: u64 },
    /// The body is not a valid message (garbage, an unknown variant, bytes
    /// left over after the message).
    #[error("cannot decode message: {0}")]
    Decode(#[from] DecodeError),
    /// The message could not be encoded (does not happen for vtfarm's types).
    #[error("cannot encode message: {0}")]
    Encode(String),
}

/// Why bytes do not decode as exactly one value.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// Garbage, an unknown variant, a value cut short or over the limit.
    #[error(transparent)]
    Bincode(#[from] bincode::error::DecodeError),
    /// A whole value, then this many more bytes.
    #[error("{0} bytes left over after the message")]
    LeftOver(usize),
}

/// The body length a frame's prefix announces, checked against `limit`
/// (clamped to [`MAX_MESSAGE_BYTES`]) before anything is allocated for it.
pub fn body_len(prefix: [u8; 4], limit: u32) -> Result<u32, FrameError> {
    let limit = limit.min(MAX_MESSAGE_BYTES);
    let len = u32::from_le_bytes(prefix);
    if len > limit {
        return Err(FrameError::TooLarge {
            len: len.into(),
            limit,
        });
    }
    Ok(len)
}

/// The first frame of `bytes`: its body (at most `limit` bytes, see
/// [`body_len`]) and the bytes after it.
pub fn split_frame(bytes: &[u8], limit: u32) -> Result<(&[u8], &[u8]), FrameError> {
    let Some((prefix, rest)) = bytes.split_first_chunk::<4>() else {
        return Err(FrameError::Truncated {
            expected: 4,
            received: bytes.len() as u64,
        });
    };
    let len = body_len(*prefix, limit)? as usize;
    if rest.len() < len {
        return Err(FrameError::Truncated {
            expected: 4 + len as u64,
            received: bytes.len() as u64,
        });
    }
    Ok(rest.split_at(len))
}

/// One message as a whole frame: the length prefix and the body.
pub fn encode_message(message: &Message) -> Result<Vec<u8>, FrameError> {
    let mut frame = vec![0u8; 4];
    bincode::serde::encode_into_std_write(message, &mut frame, bincode::config::standard())
        .map_err(|e| FrameError::Encode(e.to_string()))?;
    let len = frame.len() - 4;
    match u32::try_from(len) {
        Ok(len) if len <= MAX_MESSAGE_BYTES => {
            frame[..4].copy_from_slice(&len.to_le_bytes());
            Ok(frame)
        }
        _ => Err(FrameError::TooLarge {
            len: len as u64,
            limit: MAX_MESSAGE_BYTES,
        }),
    }
}

/// Decodes a message body (without the prefix); the body must hold exactly
/// one message.
pub fn decode_message(body: &[u8]) -> Result<Message, FrameError> {
    Ok(decode_value(body)?)
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
pub(crate) fn decode_value<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, DecodeError> {
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
    let (value, used) = decoded?;
    if used != bytes.len() {
        return Err(DecodeError::LeftOver(bytes.len() - used));
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
            Message::SceneOffer {
                hash,
                job: JobId(3),
            },
            Message::SceneRequest { hash },
            Message::SceneData(SceneData::from_scene(&scene())),
            Message::FrameStart(FrameStart {
                job: JobId(3),
                frame: 1,
                scene: hash,
                setup: setup(),
                reflectors: vec![0, 1],
                method: crate::WireMethod::Pvrr,
                aux: true,
                image: crate::WireImageFormat::Srgb8,
                stages: vec![crate::WireQuality::Preview, crate::WireQuality::Full],
            }),
            Message::RequestWork {
                job: JobId(3),
                frame: 1,
            },
            Message::Package(Package {
                id: 99,
                job: JobId(3),
                frame: 1,
                triangles: vec![1, 0],
                whole: None,
            }),
            Message::PackageResult(PackageResult {
                id: 99,
                pixels: crate::ResultPixels::Bitmap(WireBitmap::from(&bitmap())),
                stats,
                busy_micros: 1234,
                setup_micros: 56,
                triangle_samples: vec![3, 0, 17],
                stage: Some(crate::WireQuality::Refine),
                mesh: Some(crate::WireMesh {
                    parts: vec![crate::WireMeshPart {
                        triangle: 1,
                        positions: vec![[0.5, -1.0, 2.0]],
                        colors: vec![[0.1, 0.2, 0.3]],
                        reflected: vec![[0.0; 3]],
                        transmitted: vec![[0.25; 3]],
                        objects: vec![4],
                        behind: vec![[0.72; 3]],
                        reflection_scale: vec![1.7],
                        faces: vec![[0, 0, 0]],
                    }],
                }),
            }),
            Message::PackageResult(PackageResult {
                id: 100,
                pixels: crate::ResultPixels::Frame {
                    image: WireImage::from_pixels(2, 1, &[Vec3::X, Vec3::ONE]),
                    aux: None,
                },
                stats: Default::default(),
                busy_micros: 4321,
                setup_micros: 0,
                triangle_samples: vec![1, 2],
                stage: None,
                mesh: None,
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
                    priority: -2,
                    kind: crate::WireJobKind::Study,
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
                    priority: 5,
                    kind: crate::WireJobKind::Render,
                },
            },
            Message::JobAccepted {
                job: JobId(3),
                frames: 2,
            },
            Message::Progress {
                job: JobId(3),
                frame: 1,
                done: 5,
                total: 8,
            },
            Message::FrameDone(FrameDone {
                job: JobId(3),
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
                job: JobId(4),
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
                    waiting: vec![JobId(9)],
                    running: vec![
                        RunningJob {
                            job: JobId(8),
                            name: "cockpit".to_owned(),
                            frame: 1,
                            frames: 3,
                            triangles_done: 100,
                            triangles_total: 576,
                            paused: false,
                        },
                        RunningJob {
                            job: JobId(10),
                            name: "single".to_owned(),
                            frame: 0,
                            frames: 1,
                            triangles_done: 0,
                            triangles_total: 576,
                            paused: true,
                        },
                    ],
                },
                scene_bytes_sent: 12_345,
            }),
            Message::ListJobs { all: true },
            Message::JobList {
                jobs: vec![crate::JobSummary {
                    id: JobId(8),
                    name: "cockpit".to_owned(),
                    kind: crate::WireJobKind::View,
                    state: crate::WireJobState::Paused,
                    priority: 3,
                    frames_done: 1,
                    frames_failed: 0,
                    frames_cancelled: 0,
                    frames_total: 3,
                    submitted_ms: 1_700_000_000_000,
                    started_ms: Some(1_700_000_001_000),
                    finished_ms: None,
                    host: "10.0.0.2:40000".to_owned(),
                    reason: String::new(),
                }],
            },
            Message::SubmitStudy {
                study: crate::WireStudy {
                    name: "sun study".to_owned(),
                    priority: 2,
                    variants: Vec::new(),
                },
            },
            Message::StudyAccepted {
                study: JobId(9),
                variants: vec![(JobId(10), 4), (JobId(11), 4)],
            },
            Message::JobRows {
                rows: vec![crate::JobRow {
                    job: crate::JobSummary {
                        id: JobId(9),
                        name: "sun study".to_owned(),
                        kind: crate::WireJobKind::Study,
                        state: crate::WireJobState::Running,
                        priority: 0,
                        frames_done: 1,
                        frames_failed: 0,
                        frames_cancelled: 0,
                        frames_total: 8,
                        submitted_ms: 1_700_000_000_000,
                        started_ms: None,
                        finished_ms: None,
                        host: "10.0.0.2:40000".to_owned(),
                        reason: String::new(),
                    },
                    variants: Vec::new(),
                }],
            },
            Message::ControlJob {
                job: JobId(8),
                action: crate::JobAction::Requeue { failed_only: true },
            },
            Message::ControlJob {
                job: JobId(8),
                action: crate::JobAction::SetPriority(-7),
            },
            Message::JobControlled {
                job: JobId(8),
                outcome: Err("no job 8".to_owned()),
            },
            Message::JobStateChanged {
                job: JobId(8),
                state: crate::WireJobState::Cancelled,
                reason: "cancelled from 127.0.0.1".to_owned(),
            },
            Message::FrameMesh {
                job: JobId(12),
                frame: 0,
                mesh: crate::WireMesh {
                    parts: vec![crate::WireMeshPart {
                        triangle: 4,
                        positions: vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
                        colors: vec![[0.5; 3]; 3],
                        reflected: vec![[0.25; 3]; 3],
                        transmitted: vec![[0.0; 3]; 3],
                        objects: vec![2, 2, 7],
                        behind: vec![[0.0; 3]; 3],
                        reflection_scale: vec![1.0; 3],
                        faces: vec![[0, 1, 2]],
                    }],
                },
            },
        ]
    }

    /// The first message of `bytes`, as a session reads it.
    fn read_all(bytes: &[u8], limit: u32) -> Result<Message, FrameError> {
        decode_message(split_frame(bytes, limit)?.0)
    }

    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = (body.len() as u32).to_le_bytes().to_vec();
        f.extend_from_slice(body);
        f
    }

    #[test]
    fn every_message_round_trips_through_frames() {
        let messages = every_message();
        // Every variant is covered (the list has two extra alternatives).
        let names: std::collections::BTreeSet<_> = messages.iter().map(Message::name).collect();
        assert_eq!(names.len(), 30);
        let stream: Vec<u8> = (messages.iter())
            .flat_map(|m| encode_message(m).expect("encodes"))
            .collect();
        let mut rest = &stream[..];
        for expected in &messages {
            let (body, after) = split_frame(rest, MAX_MESSAGE_BYTES).expect("a whole frame");
            assert_eq!(&decode_message(body).expect("decodes"), expected);
            rest = after;
        }
        assert!(rest.is_empty());
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

    #[test]
    fn oversized_prefixes_are_rejected_before_the_body() {
        for (len, limit) in [
            (MAX_HANDSHAKE_BYTES + 1, MAX_HANDSHAKE_BYTES),
            (u32::MAX, MAX_MESSAGE_BYTES),
            // A caller's limit above the maximum is clamped.
            (MAX_MESSAGE_BYTES + 1, u32::MAX),
        ] {
            // The prefix alone: no body follows, and none is looked for.
            match split_frame(&len.to_le_bytes(), limit) {
                Err(FrameError::TooLarge { len: l, limit: m }) => {
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
                matches!(result, Err(FrameError::Decode(_))),
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
        assert!(matches!(result, Err(FrameError::Decode(_))), "{result:?}");
    }

    #[test]
    fn truncated_frames_say_how_much_came() {
        assert!(matches!(
            read_all(&[3, 0], 100),
            Err(FrameError::Truncated {
                expected: 4,
                received: 2
            })
        ));
        let whole = encode_message(&Message::JobAccepted {
            job: JobId(1),
            frames: 2,
        })
        .expect("encodes");
        let cut = &whole[..whole.len() - 1];
        assert!(matches!(
            read_all(cut, 100),
            Err(FrameError::Truncated { expected, received })
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
