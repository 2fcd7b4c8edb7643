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
//! [`error_report`] is every command's one way to print a failure, and
//! [`init_logging`] the farm daemons' (`vtfarm master`, `vtfarm worker`)
//! log set-up, and [`lower_this_thread`] the priority of their background
//! threads, here because both sit on this crate.

pub mod client;
pub mod cluster;
pub mod handshake;
pub mod link;
pub mod stream;
pub mod tls;

pub use cluster::{CLUSTER_FILE, ClusterConfig, ConfigError};
pub use handshake::{CLOSE_NORMAL, REFUSAL_LINGER, client_handshake, server_handshake};
pub use link::Link;
pub use stream::{ProtoError, ReadBounds, read_message, write_message};
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

/// The line a command prints for `error`: its message, then each cause the
/// text so far does not already quote, so every cause is printed once (a
/// library error's message often names its cause and also chains it).
pub fn error_report(error: &(dyn std::error::Error + 'static)) -> String {
    let mut report = error.to_string();
    let mut cause = error.source();
    while let Some(e) = cause {
        let text = e.to_string();
        if !text.is_empty() && !report.contains(&text) {
            report.push_str(": ");
            report.push_str(&text);
        }
        cause = e.source();
    }
    report
}

/// Lowers the calling thread's scheduling priority by `niceness` (a
/// `nice` increment, up to the lowest, 19): work that nobody waits for
/// yet takes the cores the rest leaves. Linux keeps a nice value per
/// thread; elsewhere the thread keeps the process's priority. Lowering
/// needs no privilege, raising it again would: a thread lowered so stays
/// so, so callers lower threads of their own.
pub fn lower_this_thread(niceness: i32) {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: `getpriority`/`setpriority` with who = 0 read and change
        // only the calling thread's scheduling weight (Linux).
        let done = unsafe {
            let now = libc::getpriority(libc::PRIO_PROCESS, 0);
            libc::setpriority(libc::PRIO_PROCESS, 0, (now + niceness).min(19))
        };
        if done != 0 {
            let error = std::io::Error::last_os_error();
            tracing::debug!("a background thread keeps its priority: {error}");
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = niceness;
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

#[cfg(test)]
mod tests {
    use super::error_report;

    /// The calling thread's nice value.
    #[cfg(target_os = "linux")]
    fn niceness() -> i32 {
        // SAFETY: reads the calling thread's nice value.
        unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }
    }

    /// A thread lowers only itself, by the increment, down to the lowest
    /// priority (19) and no further.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_thread_lowers_only_its_own_priority() {
        let caller = niceness();
        let lowered = std::thread::spawn(|| {
            let before = niceness();
            super::lower_this_thread(3);
            let once = niceness();
            super::lower_this_thread(40);
            (before, once, niceness())
        });
        let (before, once, floor) = lowered.join().unwrap();
        assert_eq!(before, caller);
        assert_eq!(once, (caller + 3).min(19));
        assert_eq!(floor, 19);
        assert_eq!(niceness(), caller, "the caller keeps its priority");
    }

    #[derive(Debug, thiserror::Error)]
    #[error("{file}: cannot read: {source}")]
    struct Quoting {
        file: &'static str,
        source: std::io::Error,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("loading the job")]
    struct Outer(#[source] Quoting);

    #[test]
    fn a_cause_the_message_already_quotes_is_printed_once() {
        let quoting = Quoting {
            file: "job.toml",
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        };
        assert_eq!(
            error_report(&quoting),
            "job.toml: cannot read: no such file"
        );
        let outer = Outer(Quoting {
            file: "job.toml",
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        });
        assert_eq!(
            error_report(&outer),
            "loading the job: job.toml: cannot read: no such file"
        );
    }
}
