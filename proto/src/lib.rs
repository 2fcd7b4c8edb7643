//! Everything vtfarm puts on the wire, and nothing else: the typed, versioned
//! messages between master, workers and submitters; their framing over any
//! byte stream; the TLS set-up with a pinned master certificate; the
//! `cluster.toml` that tells workers and submitters where the master is; and
//! the handshake every connection starts with.
//!
//! Architecture invariant: this is the only crate that derives `Serialize`.
//! Domain types (`Scene`, `Camera`, `SparseBitmap`, ...) have `Wire*` mirrors
//! here with hand-written conversions; the `TryFrom` direction validates
//! everything a peer could get wrong (non-finite floats, indices out of range,
//! inconsistent sizes) and never panics. No scheduling or rendering logic.
//!
//! - [`message`]: the [`Message`] enum and its payload structs.
//! - [`wire`]: wire mirrors of the domain types and their conversions.
//! - [`framing`]: `u32` little-endian length prefix plus a bincode body,
//!   [`read_message`] / [`write_message`] over tokio's I/O traits.
//! - [`tls`]: the master's self-signed identity and the quinn configurations
//!   whose client verifier accepts exactly one certificate fingerprint.
//! - [`cluster`]: `cluster.toml` and the shared token.
//! - [`handshake`]: `Hello` / `Welcome` / `Refused` on a connection's first stream.

pub mod client;
pub mod cluster;
pub mod framing;
pub mod handshake;
pub mod link;
pub mod message;
pub mod tls;
pub mod wire;

pub use cluster::{CLUSTER_FILE, ClusterConfig, ConfigError, token_matches};
pub use framing::{
    MAX_HANDSHAKE_BYTES, MAX_MESSAGE_BYTES, ProtoError, decode_message, encode_message,
    encoded_len, read_message, write_message,
};
pub use handshake::{
    CLOSE_NORMAL, HANDSHAKE_TIMEOUT, HandshakePolicy, REFUSAL_LINGER, check_hello,
    client_handshake, server_handshake,
};
pub use link::{Link, SESSION_LIMIT};
pub use message::{
    FrameDone, FramePhase, FrameStart, FrameStats, Hello, JobId, JobScene, Message, Package,
    PackageFailed, PackageId, PackageResult, PhaseKind, QueueStatus, Refusal, RefuseCode, Role,
    RunningJob, SceneData, SceneHash, StatusReply, Welcome, WireFrameAux, WireJob,
    WorkerFrameStats, WorkerStatus, scene_hash,
};
pub use tls::{
    ALPN, IDLE_TIMEOUT, IdentityError, KEEP_ALIVE_INTERVAL, MasterIdentity, SERVER_NAME, TlsError,
    client_config, fingerprint_of, parse_fingerprint, server_config,
};
pub use wire::{
    WireBitmap, WireBitmapParts, WireCamera, WireError, WireFrameSetup, WireImage, WireImageFormat,
    WireLight, WireLightKind, WireLighting, WireMaterial, WireMethod, WirePackageStats,
    WireQuality, WireScene, WireTraceSettings, WireTransmission, WireTriangle, WireVertexSettings,
    check_triangle_ids,
};

/// The protocol version in every `Hello` and `Welcome`. Bump it on any change
/// to a message's encoding; the master refuses other versions with
/// [`RefuseCode::BadVersion`].
pub const PROTOCOL_VERSION: u32 = 6;

/// How many frames of a job the master runs at once (pipelined frames) and
/// so how many prepared frames a worker keeps: a package of any of them may
/// come. The master's scheduler configuration must not exceed it.
pub const FRAMES_IN_FLIGHT: usize = 8;

/// The first bytes of every `Hello`, so a stray client is told apart from an
/// old vtfarm.
pub const MAGIC: [u8; 8] = *b"VTFARM\0\0";

/// The longest prefix of `text` of at most `max` bytes that ends on a
/// character boundary.
pub(crate) fn truncate_utf8(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}
