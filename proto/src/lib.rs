//! Everything vtfarm puts on the wire, and nothing of how it travels: the
//! typed, versioned messages between master, workers and submitters; the
//! wire mirrors of the domain types with their codecs; the framing of a
//! message into bytes; and the handshake's rules. No I/O: the QUIC
//! transport, TLS, `cluster.toml` and the stream reader are
//! `vtfarm-transport`, so the decoder is fuzzed and tested without them.
//!
//! Architecture invariant: this is the only crate that derives `Serialize`
//! for what goes on the wire. Domain types (`Scene`, `Camera`,
//! `SparseBitmap`, ...) have `Wire*` mirrors here with hand-written
//! conversions; the `TryFrom` direction validates everything a peer could
//! get wrong (non-finite floats, indices out of range, inconsistent sizes)
//! and never panics. No scheduling or rendering logic.
//!
//! - [`message`]: the [`Message`] enum and its payload structs.
//! - [`wire`]: wire mirrors of the domain types and their conversions.
//! - [`framing`]: `u32` little-endian length prefix plus a bincode body,
//!   [`encode_message`] / [`decode_message`] and the limits.
//! - [`handshake`]: what a `Hello` must be ([`check_hello`]).
//! - [`kept`]: which frames a worker keeps ([`KeptFrames`]), as both ends
//!   of its session count them.

use std::time::Duration;

pub mod framing;
pub mod handshake;
pub mod kept;
pub mod message;
pub mod wire;

pub use framing::{
    DecodeError, FrameError, MAX_HANDSHAKE_BYTES, MAX_MESSAGE_BYTES, MESSAGE_STALL, SESSION_LIMIT,
    body_len, decode_message, encode_message, encoded_len, split_frame,
};
pub use handshake::{HANDSHAKE_TIMEOUT, HandshakePolicy, check_hello, token_matches};
pub use kept::{FrameKey, KeptFrames};
pub use message::{
    FrameDone, FramePhase, FrameStart, FrameStats, Hello, JobAction, JobId, JobOptions, JobRow,
    JobScene, JobSummary, MAX_CORNER_MESH_TRIANGLES, MAX_STAGES, Message, Package, PackageFailed,
    PackageId, PackageResult, PhaseKind, QueueStatus, Refusal, RefuseCode, ResultPixels, Role,
    RunningJob, SceneData, SceneHash, StatusReply, Welcome, WireFrameAux, WireJob, WireJobKind,
    WireJobState, WireStudy, WorkerFrameStats, WorkerStatus, check_stages, scene_hash, wire_job,
};
pub use wire::{
    WireBitmap, WireBitmapParts, WireCamera, WireError, WireFrameSetup, WireImage, WireImageFormat,
    WireLight, WireLightKind, WireLighting, WireMaterial, WireMesh, WireMeshPart, WireMethod,
    WirePackageStats, WireQuality, WireScene, WireTraceSettings, WireTransmission, WireTriangle,
    WireVertexSettings, check_triangle_ids, wire_triangles,
};

/// The protocol version in every `Hello` and `Welcome`. Bump it on any change
/// to a message's encoding or to a rule both ends follow (such as a
/// material's `thin` and `fresnel`, a directional light's disc, the vertex
/// tracer's `capture_cd_m2`, a progressive stage's reflector meshes in
/// its result or a view frame's corner mesh ahead of its set-up, with the glass's
/// weights per vertex); the master refuses other versions with
/// [`RefuseCode::BadVersion`].
pub const PROTOCOL_VERSION: u32 = 14;

/// How many split frames of a job the master runs at once (pipelined
/// frames) and so how many frames a worker keeps ([`KeptFrames`]): a
/// package of any of them may come. The master's scheduler configuration
/// must not exceed it for split frames; whole frames (more of them in
/// flight, two per worker) bring their `FrameStart` with their package, and
/// the master sends a split frame's `FrameStart` again to a worker that no
/// longer keeps it, so a worker never needs one it was not sent.
pub const FRAMES_IN_FLIGHT: usize = 8;

/// A peer silent this long is gone: the master drops a worker that sent
/// nothing (heartbeat, request or result) for this long and requeues its
/// packages (the default `heartbeat_timeout` of `vtfarm_master_core::FarmRules`),
/// and QUIC closes a connection idle this long on either end, so a worker or
/// submitter notices a dead master in the same time.
pub const PEER_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a persistent master keeps a job whose submitters are gone (and
/// a completed job's frames) for a submitter to re-attach, and so how long
/// a submitter that lost the master tries to reconnect.
pub const ATTACH_GRACE: Duration = Duration::from_secs(120);

/// The first bytes of every `Hello`, so a stray client is told apart from an
/// old vtfarm.
pub const MAGIC: [u8; 8] = *b"VTFARM\0\0";
