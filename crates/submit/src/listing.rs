//! What a submitter prints of the farm: the jobs table of `vtfarm jobs`,
//! the workers and queue of `vtfarm status`, a frame's statistics, the
//! records of `stats.json` and the JSON lines of `vtfarm submit --json`.
//! Each returns text; the caller decides where it goes.

use std::collections::BTreeMap;
use std::fmt::Write;

use vtfarm_proto::{FrameStats, JobRow, StatusReply};

use crate::{FinishedFrame, JobEvent, StudyEvent};

/// The name column's width: a longer name is cut, so the columns stay aligned.
const NAME_WIDTH: usize = 24;

/// The table `vtfarm jobs` prints: one line per job under a header; a
/// study's variants each a line under it (`done/total` and state).
pub fn jobs_table(rows: &[JobRow]) -> String {
    let mut out = format!(
        "{:>5} {:<NAME_WIDTH$} {:<6} {:<9} {:>8} {:>6} {:>6} {:>9} {:>6}  {:<19}  {:<19}  {:<19}  {}\n",
        "id",
        "name",
        "kind",
        "state",
        "priority",
        "done",
        "failed",
        "cancelled",
        "total",
        "submitted (UTC)",
        "started",
        "finished",
        "host"
    );
    let time = |ms: Option<u64>| ms.map_or("-".to_owned(), utc_time);
    for JobRow { job, variants } in rows {
        out += &format!(
            "{:>5} {:<NAME_WIDTH$} {:<6} {:<9} {:>8} {:>6} {:>6} {:>9} {:>6}  {:<19}  {:<19}  {:<19}  {}\n",
            job.id,
            fitted(&job.name, NAME_WIDTH),
            job.kind.name(),
            job.state.name(),
            job.priority,
            job.frames_done,
            job.frames_failed,
            job.frames_cancelled,
            job.frames_total,
            utc_time(job.submitted_ms),
            time(job.started_ms),
            time(job.finished_ms),
            job.host
        );
        if !job.reason.is_empty() {
            out += &format!("      {}\n", job.reason);
        }
        for v in variants {
            out += &format!(
                "      variant {:<NAME_WIDTH$} job {:>5} {:<9} {:>6}/{} frames\n",
                fitted(&v.name, NAME_WIDTH),
                v.id,
                v.state.name(),
                v.frames_done,
                v.frames_total
            );
        }
    }
    out
}

/// `text` in at most `width` characters: cut with an ellipsis when longer.
fn fitted(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        return text.to_owned();
    }
    let kept: String = text.chars().take(width.saturating_sub(1)).collect();
    format!("{kept}…")
}

/// Milliseconds since the Unix epoch as `YYYY-MM-DD HH:MM:SS` (UTC), for
/// listings.
fn utc_time(ms: u64) -> String {
    let time = vtfarm_job::study::UtcTime {
        unix_seconds: (ms / 1000) as i64,
    };
    let (year, month, day, h, m, s) = time.civil();
    format!("{year:04}-{month:02}-{day:02} {h:02}:{m:02}:{s:02}")
}

/// What `vtfarm status` prints: the workers with their measured
/// throughput, the running jobs and the queue.
pub fn status_table(reply: &StatusReply) -> String {
    // Throughput is the load balancer's: estimated cost (traced samples,
    // once a frame has been measured) per second, transfers included.
    let mut out = format!(
        "{:<24} {:<22} {:>7} {:>8} {:>18} {:>9} {:>10} {:>8}\n",
        "worker",
        "address",
        "threads",
        "state",
        "throughput (samples/s)",
        "packages",
        "triangles",
        "failures"
    );
    for w in &reply.workers {
        out += &format!(
            "{:<24} {:<22} {:>7} {:>8} {:>22.0} {:>9} {:>10} {:>8}\n",
            w.name,
            w.address,
            w.threads,
            w.state,
            w.throughput,
            w.packages_done,
            w.triangles_done,
            w.failures
        );
    }
    if reply.queue.running.is_empty() {
        out += "running: nothing\n";
    }
    // In the order the jobs get workers; frames are numbered from 0, as
    // the files are (frame_0000).
    for r in &reply.queue.running {
        // A paused job keeps its place in the queue but gets no work.
        let state = if r.paused { "paused" } else { "running" };
        out += &format!(
            "{state}: job {} ({}) frame {} of {} (frame_{:04}): {}/{} triangles\n",
            r.job, r.name, r.frame, r.frames, r.frame, r.triangles_done, r.triangles_total
        );
    }
    out += &format!(
        "waiting: {} job(s) {:?}\n",
        reply.queue.waiting.len(),
        reply.queue.waiting
    );
    out += &format!("scene bytes sent to workers: {}\n", reply.scene_bytes_sent);
    out
}

/// A frame's summary line. The last figure is `FrameStats::speedup`, the
/// workers' summed busy time over the frame's wall time: how many workers
/// were busy on average (it says nothing of a speed-up over anything).
pub fn frame_line(s: &FrameStats) -> String {
    format!(
        "{:.3} s, {} packages, imbalance {:.1}%, {:.2} workers busy on average",
        s.wall_micros as f64 / 1e6,
        s.packages,
        s.imbalance * 100.0,
        s.speedup
    )
}

/// A frame's summary line and per-worker table, each line indented.
pub fn frame_table(s: &FrameStats) -> String {
    let mut out = format!("  {}\n", frame_line(s));
    let _ = writeln!(
        out,
        "  {:<24} {:>9} {:>8} {:>9} {:>10} {:>10} {:>10}",
        "worker", "busy s", "packages", "triangles", "samples", "bytes in", "bytes out"
    );
    for w in &s.workers {
        let _ = writeln!(
            out,
            "  {:<24} {:>9.3} {:>8} {:>9} {:>10} {:>10} {:>10}",
            w.name,
            w.busy_micros as f64 / 1e6,
            w.packages,
            w.triangles,
            w.rays,
            w.bytes_in,
            w.bytes_out
        );
    }
    out
}

/// One frame in `stats.json`: the master's statistics, and when the frame
/// reached the submitter (from the submission; the intervals between
/// arrivals are the farm's frame rate, pipelined or not).
#[derive(serde::Serialize)]
pub struct FrameRecord<'a> {
    frame: u32,
    arrival_micros: u64,
    #[serde(flatten)]
    stats: &'a FrameStats,
}

impl FrameRecord<'_> {
    /// The records of `frames`, with their arrival times (microseconds
    /// after the submission) from `arrivals`.
    pub fn of<'a>(
        frames: &'a [FinishedFrame],
        arrivals: &BTreeMap<u32, u64>,
    ) -> Vec<FrameRecord<'a>> {
        (frames.iter())
            .map(|f| FrameRecord {
                frame: f.frame,
                arrival_micros: arrivals.get(&f.frame).copied().unwrap_or_default(),
                stats: &f.stats,
            })
            .collect()
    }
}

impl JobEvent<'_> {
    /// The event as a line of `vtfarm submit --json`, for the events
    /// scripts follow (acceptance and state changes).
    pub fn json_line(&self) -> Option<String> {
        let value = match self {
            JobEvent::Accepted { job, frames } => {
                serde_json::json!({"event": "accepted", "job": job, "frames": frames})
            }
            JobEvent::StateChanged { job, state, reason } => {
                serde_json::json!({"event": "state", "job": job, "state": state, "reason": reason})
            }
            _ => return None,
        };
        Some(value.to_string())
    }
}

impl StudyEvent<'_> {
    /// The event as a line of `vtfarm submit --json` of a study, for the
    /// events scripts follow; `variant_name` names a variant by its index.
    pub fn json_line(&self, variant_name: impl Fn(usize) -> String) -> Option<String> {
        let value = match self {
            StudyEvent::Accepted { study, variants } => {
                let frames: u32 = variants.iter().map(|&(_, frames)| frames).sum();
                let jobs: Vec<_> = variants.iter().map(|&(job, _)| job).collect();
                serde_json::json!({"event": "accepted", "job": study, "kind": "study", "frames": frames, "variants": jobs})
            }
            StudyEvent::StateChanged {
                variant,
                job,
                state,
                reason,
            } => {
                let name = variant_name(*variant);
                serde_json::json!({"event": "state", "job": job, "variant": name, "state": state, "reason": reason})
            }
            _ => return None,
        };
        Some(value.to_string())
    }
}

/// The last line of `vtfarm submit --json`: `frames` frames are in, and
/// `key` (`stats` or `summary`) names the file that holds their figures.
pub fn done_json_line(frames: usize, key: &str, path: &std::path::Path) -> String {
    let mut value = serde_json::json!({"event": "done", "frames": frames});
    value[key] = serde_json::json!(path);
    value.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_proto::{JobId, JobSummary, WireJobKind, WireJobState};

    #[test]
    fn utc_times_match_known_dates() {
        assert_eq!(utc_time(0), "1970-01-01 00:00:00");
        // A leap day, and the last second of a century's leap year.
        assert_eq!(utc_time(951_782_400_000), "2000-02-29 00:00:00");
        assert_eq!(utc_time(978_307_199_999), "2000-12-31 23:59:59");
        assert_eq!(utc_time(1_764_672_000_000), "2025-12-02 10:40:00");
    }

    #[test]
    fn the_table_lists_every_column_and_a_finished_jobs_reason() {
        let job = JobSummary {
            id: JobId(7),
            name: "cockpit.toml".into(),
            kind: WireJobKind::Study,
            state: WireJobState::Cancelled,
            priority: -3,
            frames_done: 2,
            frames_failed: 0,
            frames_cancelled: 38,
            frames_total: 40,
            submitted_ms: 1_764_672_000_000,
            started_ms: Some(1_764_672_001_000),
            finished_ms: None,
            host: "127.0.0.1:5000".into(),
            reason: "job 7 was cancelled by submitter (127.0.0.1:6000)".into(),
        };
        let row = JobRow {
            job,
            variants: Vec::new(),
        };
        let text = jobs_table(&[row]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        let fields: Vec<&str> = lines[1].split_whitespace().collect();
        assert_eq!(
            fields,
            [
                "7",
                "cockpit.toml",
                "study",
                "cancelled",
                "-3",
                "2",
                "0",
                "38",
                "40",
                "2025-12-02",
                "10:40:00",
                "2025-12-02",
                "10:40:01",
                "-",
                "127.0.0.1:5000"
            ]
        );
        assert_eq!(
            lines[2].trim(),
            "job 7 was cancelled by submitter (127.0.0.1:6000)"
        );
    }

    #[test]
    fn a_long_name_is_cut_so_the_columns_stay_aligned() {
        let job = |id, name: &str| JobSummary {
            id,
            name: name.into(),
            kind: WireJobKind::Study,
            state: WireJobState::Running,
            priority: 0,
            frames_done: 1,
            frames_failed: 0,
            frames_cancelled: 0,
            frames_total: 40,
            submitted_ms: 1_764_672_000_000,
            started_ms: None,
            finished_ms: None,
            host: "127.0.0.1".into(),
            reason: String::new(),
        };
        let long = "Instrument cover glass designs over sun positions / current";
        let row = |job| JobRow {
            job,
            variants: Vec::new(),
        };
        let text = jobs_table(&[row(job(JobId(1), "short")), row(job(JobId(2), long))]);
        let lines: Vec<&str> = text.lines().collect();
        let column = |line: &str| {
            let at = line.find("study").expect("the kind column");
            line[..at].chars().count()
        };
        assert_eq!(column(lines[1]), column(lines[2]), "{text}");
        assert!(lines[2].contains("Instrument cover glass …"), "{text}");
        assert_eq!(fitted("abc", 3), "abc");
        assert_eq!(fitted("abcd", 3), "ab…");
    }

    #[test]
    fn a_study_is_one_row_with_each_variants_progress_under_it() {
        let listing = |id, name: &str, kind, state, done| JobSummary {
            id,
            name: name.into(),
            kind,
            state,
            priority: 0,
            frames_done: done,
            frames_failed: 0,
            frames_cancelled: 0,
            frames_total: 2 * u32::from(kind == WireJobKind::Study) + 2,
            submitted_ms: 1_764_672_000_000,
            started_ms: None,
            finished_ms: None,
            host: "127.0.0.1".into(),
            reason: String::new(),
        };
        let row = JobRow {
            job: listing(
                JobId(4),
                "sun study",
                WireJobKind::Study,
                WireJobState::Running,
                3,
            ),
            variants: vec![
                listing(
                    JobId(5),
                    "sun study / current",
                    WireJobKind::Variant,
                    WireJobState::Completed,
                    2,
                ),
                listing(
                    JobId(6),
                    "sun study / flat",
                    WireJobKind::Variant,
                    WireJobState::Running,
                    1,
                ),
            ],
        };
        let text = jobs_table(&[row]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        let fields: Vec<&str> = lines[1].split_whitespace().take(9).collect();
        assert_eq!(
            fields,
            ["4", "sun", "study", "study", "running", "0", "3", "0", "0"]
        );
        for (line, (id, state, done)) in lines[2..]
            .iter()
            .zip([(5, "completed", "2/2"), (6, "running", "1/2")])
        {
            let words: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(words[0], "variant", "{text}");
            assert!(line.contains(&format!("job {id:>5} {state}")), "{text}");
            assert!(words.contains(&done), "{text}");
        }
    }
}
