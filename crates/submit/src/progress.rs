//! Progress of a command on stderr, shared by `vtfarm render`, `study` and
//! `submit`: a bar with the count, the elapsed time and an ETA on a
//! terminal; a plain line every [`PLAIN_INTERVAL`] when stderr is not one
//! (a log file, CI), so that redirected output still shows the work moving.

use std::borrow::Cow;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// How often the plain progress line is written when stderr is not a
/// terminal.
pub const PLAIN_INTERVAL: Duration = Duration::from_secs(5);

/// A count of `total` `unit`s (frames, reflector triangles, methods) done.
pub struct Progress {
    bar: ProgressBar,
    unit: String,
    /// When stderr is not a terminal: the start and the last plain line.
    plain: Option<Mutex<PlainState>>,
}

struct PlainState {
    started: Instant,
    last_line: Instant,
}

impl Progress {
    /// A bar on a terminal, plain lines otherwise.
    pub fn new(total: u64, unit: &str, message: impl Into<Cow<'static, str>>) -> Progress {
        let terminal = std::io::stderr().is_terminal();
        let bar = if terminal {
            ProgressBar::new(total)
        } else {
            ProgressBar::hidden()
        };
        bar.set_length(total);
        let template = format!(
            "{{spinner}} {{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit} ({{elapsed}}, ETA {{eta}})"
        );
        bar.set_style(
            ProgressStyle::with_template(&template)
                .expect("template is valid")
                .progress_chars("=> "),
        );
        bar.set_message(message);
        let now = Instant::now();
        Progress {
            bar,
            unit: unit.to_owned(),
            plain: (!terminal).then(|| {
                Mutex::new(PlainState {
                    started: now,
                    last_line: now,
                })
            }),
        }
    }

    pub fn set_message(&self, message: impl Into<Cow<'static, str>>) {
        self.bar.set_message(message);
        self.plain_tick();
    }

    pub fn set_position(&self, done: u64) {
        self.bar.set_position(done);
        self.plain_tick();
    }

    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
        self.plain_tick();
    }

    pub fn position(&self) -> u64 {
        self.bar.position()
    }

    /// A line for the user on stderr: above the bar on a terminal, plainly
    /// otherwise.
    pub fn println(&self, line: impl AsRef<str>) {
        if self.bar.is_hidden() {
            eprintln!("{}", line.as_ref());
        } else {
            self.bar.println(line.as_ref());
        }
    }

    /// Removes the bar (a terminal's); plain output ends with nothing more.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }

    /// Writes the plain line when [`PLAIN_INTERVAL`] has passed since the last.
    fn plain_tick(&self) {
        let Some(state) = &self.plain else { return };
        let now = Instant::now();
        let mut state = state.lock().unwrap_or_else(|e| e.into_inner());
        if now.duration_since(state.last_line) < PLAIN_INTERVAL {
            return;
        }
        state.last_line = now;
        let line = plain_line(
            &self.bar.message(),
            self.bar.position(),
            self.bar.length().unwrap_or(0),
            &self.unit,
            now.duration_since(state.started),
        );
        eprintln!("{line}");
    }
}

/// The remaining time at the mean rate so far; `None` before the first unit.
pub fn eta(done: u64, total: u64, elapsed: Duration) -> Option<Duration> {
    (done > 0).then(|| elapsed.mul_f64(total.saturating_sub(done) as f64 / done as f64))
}

/// `study: 12/60 frames (20%), 1m02s elapsed, ETA 4m08s`.
pub fn plain_line(message: &str, done: u64, total: u64, unit: &str, elapsed: Duration) -> String {
    let percent = if total == 0 {
        100.0
    } else {
        done as f64 * 100.0 / total as f64
    };
    let eta = eta(done, total, elapsed).map_or("unknown".to_owned(), duration_text);
    let message = if message.is_empty() {
        String::new()
    } else {
        format!("{message}: ")
    };
    format!(
        "{message}{done}/{total} {unit} ({percent:.0}%), {} elapsed, ETA {eta}",
        duration_text(elapsed)
    )
}

/// `1h02m`, `4m08s` or `12s`.
pub fn duration_text(d: Duration) -> String {
    let s = d.as_secs();
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m{s:02}s"),
        (h, m, _) => format!("{h}h{m:02}m"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_eta_is_the_remaining_units_at_the_mean_rate_so_far() {
        let s = Duration::from_secs;
        assert_eq!(eta(0, 60, s(10)), None);
        assert_eq!(eta(12, 60, s(60)), Some(s(240)));
        assert_eq!(eta(60, 60, s(300)), Some(s(0)));
    }

    #[test]
    fn a_plain_line_gives_the_count_share_elapsed_time_and_eta() {
        let line = plain_line("study", 12, 60, "frames", Duration::from_secs(62));
        assert_eq!(line, "study: 12/60 frames (20%), 1m02s elapsed, ETA 4m08s");
        let line = plain_line("", 0, 3, "frames", Duration::from_secs(3700));
        assert_eq!(line, "0/3 frames (0%), 1h01m elapsed, ETA unknown");
    }
}
