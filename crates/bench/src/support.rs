//! What `vtfarm`'s subcommands and its benchmarks share: the `--quality`
//! parser, the process's thread pool and async runtime, JSON output, and
//! the one way to read CPU time.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result};
use vtfarm_vertex::Quality;

/// A `--quality` value that names no quality.
#[derive(Debug, thiserror::Error)]
#[error("unknown quality '{0}' (preview, refine, full, reference)")]
pub struct UnknownQuality(String);

/// Parses a `--quality` value.
pub fn parse_quality(s: &str) -> Result<Quality, UnknownQuality> {
    Quality::from_name(s).ok_or_else(|| UnknownQuality(s.to_owned()))
}

/// Sets the size of rayon's global pool (once, before any parallel work).
pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("setting the thread count")?;
    }
    Ok(())
}

/// The async runtime of the farm subcommands (two threads: the tracing
/// runs on rayon's pool).
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// Writes `value` as pretty JSON.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(value)?)
        .with_context(|| format!("writing {}", path.display()))
}

/// The system's load averages over 1, 5 and 15 minutes, as `uptime` prints
/// them ("?" where /proc/loadavg cannot be read): every speed figure on a
/// shared machine goes with it.
pub fn load_average() -> String {
    match std::fs::read_to_string("/proc/loadavg") {
        Ok(text) => text
            .split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" "),
        Err(_) => "?".to_owned(),
    }
}

/// Whose CPU time [`cpu_time`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CpuClock {
    /// The calling thread's.
    Thread,
    /// The whole process's (every thread, user and system).
    Process,
}

/// CPU time used so far by the thread or the process
/// (`clock_gettime`, nanoseconds); `None` where the system has no such clock.
pub fn cpu_time(clock: CpuClock) -> Option<Duration> {
    cpu_clock(clock)
}

#[cfg(unix)]
fn cpu_clock(clock: CpuClock) -> Option<Duration> {
    let id = match clock {
        CpuClock::Thread => libc::CLOCK_THREAD_CPUTIME_ID,
        CpuClock::Process => libc::CLOCK_PROCESS_CPUTIME_ID,
    };
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `clock_gettime` writes one `timespec` through the pointer,
    // which points at a live, writable local.
    let status = unsafe { libc::clock_gettime(id, &mut t) };
    (status == 0).then(|| Duration::new(t.tv_sec as u64, t.tv_nsec as u32))
}

#[cfg(not(unix))]
fn cpu_clock(_: CpuClock) -> Option<Duration> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Work on this thread shows on its clock, and the process has used at
    /// least what this thread has. Bounded: gives up spinning after 10 s.
    #[test]
    fn work_shows_on_the_thread_and_process_clocks() {
        let process0 = cpu_time(CpuClock::Process).expect("a process clock");
        let thread0 = cpu_time(CpuClock::Thread).expect("a thread clock");
        let (start, mut x) = (std::time::Instant::now(), 0u64);
        let mut thread = Duration::ZERO;
        while thread < Duration::from_millis(2) && start.elapsed() < Duration::from_secs(10) {
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(7));
            }
            thread = cpu_time(CpuClock::Thread).unwrap() - thread0;
        }
        let process = cpu_time(CpuClock::Process).unwrap() - process0;
        assert!(thread >= Duration::from_millis(2), "{thread:?}");
        assert!(process >= thread, "{process:?} < {thread:?}");
    }

    #[test]
    fn unknown_qualities_are_named_with_the_choices() {
        assert_eq!(parse_quality("full").unwrap(), Quality::Full);
        let error = parse_quality("best").unwrap_err().to_string();
        assert_eq!(
            error,
            "unknown quality 'best' (preview, refine, full, reference)"
        );
    }
}
