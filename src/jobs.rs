//! `vtfarm jobs`: the master's jobs, as a table or as JSON; a study is one
//! row, its variants' progress under it.

use anyhow::Result;
use vtfarm_master::http::JobRowView;
use vtfarm_proto::{JobRow, WireJobKind};

use crate::farm::ClusterArgs;
use crate::shared::{runtime, utc_time};

/// Options of `vtfarm jobs`.
#[derive(clap::Args)]
pub(crate) struct JobsArgs {
    #[command(flatten)]
    cluster: ClusterArgs,
    /// Also list the finished jobs the master keeps (completed, failed,
    /// cancelled).
    #[arg(long)]
    all: bool,
    /// One JSON array of the jobs instead of the table.
    #[arg(long)]
    json: bool,
}

/// `vtfarm jobs`.
pub(crate) fn jobs(args: JobsArgs) -> Result<()> {
    let options = args.cluster.client_options()?;
    let rows = runtime()?.block_on(vtfarm_submit::list_jobs(&options, args.all))?;
    if args.json {
        let rows: Vec<JobRowView> = rows.into_iter().map(JobRowView::from).collect();
        println!("{}", serde_json::to_string(&rows)?);
        return Ok(());
    }
    print!("{}", table(&rows));
    Ok(())
}

/// The table `vtfarm jobs` prints: one line per job under a header; a
/// study's variants each a line under it (`done/total` and state).
fn table(rows: &[JobRow]) -> String {
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
            kind_name(job.kind),
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

/// The name column's width: a longer name is cut, so the columns stay aligned.
const NAME_WIDTH: usize = 24;

/// `text` in at most `width` characters: cut with an ellipsis when longer.
fn fitted(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        return text.to_owned();
    }
    let kept: String = text.chars().take(width.saturating_sub(1)).collect();
    format!("{kept}…")
}

pub(crate) fn kind_name(kind: WireJobKind) -> &'static str {
    match kind {
        WireJobKind::Render => "render",
        WireJobKind::Study => "study",
        WireJobKind::View => "view",
        WireJobKind::Variant => "variant",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_proto::JobId;
    use vtfarm_proto::{JobSummary, WireJobState};

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
        let text = table(&[row]);
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
        let text = table(&[row(job(JobId(1), "short")), row(job(JobId(2), long))]);
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
        let text = table(&[row]);
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
