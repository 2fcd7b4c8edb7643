//! How vtfarm's messages travel: QUIC with TLS pinned to the master's
//! self-signed certificate, the handshake exchange on a connection's first
//! stream, messages over a byte stream, the [`Link`] a session works with,
//! the `cluster.toml` that tells workers and submitters where the master is,
//! and the client's [`client::connect`]. What the bytes mean is
//! `vtfarm-proto`, which knows nothing of this crate.
//!
//! - [`stream`]: [`read_message`] / [`write_message`] over tokio's I/O traits.
//! - [`handshake`]: `Hello` / `Welcome` / `Refused` over QUIC, close codes.
//! - [`link`]: a session's two channel ends, over a QUIC stream or in-process.
//! - [`tls`]: the master's self-signed identity and the quinn configurations
//!   whose client verifier accepts exactly one certificate fingerprint.
//! - [`cluster`]: `cluster.toml` and the shared token.
//! - [`client`]: dialling the master.
//!
//! [`init_logging`] is the farm daemons' (`vtfarm master`, `vtfarm worker`)
//! log set-up, here because both sit on this crate.

pub mod client;
pub mod cluster;
pub mod handshake;
pub mod link;
pub mod stream;
pub mod tls;

pub use cluster::{CLUSTER_FILE, ClusterConfig, ConfigError};
pub use handshake::{CLOSE_NORMAL, REFUSAL_LINGER, client_handshake, server_handshake};
pub use link::Link;
pub use stream::{ProtoError, read_message, write_message};
pub use tls::{
    ALPN, IdentityError, KEEP_ALIVE_INTERVAL, MasterIdentity, SERVER_NAME, TlsError, client_config,
    fingerprint_of, parse_fingerprint, server_config,
};

/// Logs to stderr through `tracing`, filtered by `RUST_LOG` (default `info`):
/// the master's and the worker's command lines.
pub fn init_logging() {
    init_logging_at("info");
}

/// [`init_logging`] with `default` as the filter when `RUST_LOG` is unset
/// (the CLI's other commands log warnings only). Colours only when stderr
/// is a terminal: a redirected log holds no escape codes.
pub fn init_logging_at(default: &str) {
    use std::io::IsTerminal;
    let filter =
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| default.into());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
}

/// The longest prefix of `text` of at most `max` bytes that ends on a
/// character boundary.
pub(crate) fn truncate_utf8(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}
