//! The farm's jobs as its users see them: each job's state ([`JobState`],
//! whose transitions are the one table [`JobState::may_become`]), priority,
//! progress, times and origin ([`JobEntry`], kept in the [`JobTable`]), and
//! how long finished jobs stay listed ([`Retention`]).
//!
//! | from | to | when |
//! |---|---|---|
//! | Queued | Running | the scheduler starts it |
//! | Queued, Running | Paused | `pause` |
//! | Paused | Queued | `resume` of a job that never started |
//! | Paused | Running | `resume` of a job that had started |
//! | Running, Paused | Completed | its last frame is done (a paused job's running packages finish) |
//! | Running, Paused | Failed | a package failed on too many workers, or no worker may take its work |
//! | Queued, Running, Paused | Cancelled | `cancel` |
//! | Completed, Failed, Cancelled | Queued | `requeue` |
//!
//! Completed, Failed and Cancelled are finished: such a job stays listed
//! (and a persistent master keeps its frames for re-attaching) until
//! [`Retention`] lets it go.
//!
//! A study is one listed job over its variants, each a job of its own
//! (listed under it, never on its own, and controlled only through it).
//! Its state follows from theirs ([`study_state`]) through the same table:
//! finished when every variant is (completed when each completed, else
//! cancelled when one was cancelled, else failed); paused when every
//! unfinished variant is; running once a variant started or finished;
//! queued before. Its frames are its variants' together, and it goes with
//! them when [`Retention`] lets it go.

use std::collections::BTreeMap;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_proto::{JobRow, JobSummary, WireJobKind, WireJobState};

/// A job's state; the module documentation has the transition table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum JobState {
    /// Waiting for the scheduler to start it.
    Queued,
    /// Its frames are being rendered.
    Running,
    /// Hands out no new work; what runs finishes and is kept.
    Paused,
    /// Every frame is done. Finished.
    Completed,
    /// Given up (see its reason). Finished.
    Failed,
    /// Cancelled by a user (or because its embedded submitter left). Finished.
    Cancelled,
}

impl JobState {
    /// Every state, in the order listings count them.
    pub const ALL: [JobState; 6] = [
        JobState::Queued,
        JobState::Running,
        JobState::Paused,
        JobState::Completed,
        JobState::Failed,
        JobState::Cancelled,
    ];

    /// Whether the transition table allows `self → to`. Jobs are created
    /// straight into [`JobState::Queued`].
    pub fn may_become(self, to: JobState) -> bool {
        use JobState::*;
        matches!(
            (self, to),
            (Queued, Running | Paused | Cancelled)
                | (Running, Paused | Completed | Failed | Cancelled)
                | (Paused, Queued | Running | Completed | Failed | Cancelled)
                | (Completed | Failed | Cancelled, Queued)
        )
    }

    /// Whether the job is over (only a requeue leaves the state).
    pub fn is_finished(self) -> bool {
        matches!(
            self,
            JobState::Completed | JobState::Failed | JobState::Cancelled
        )
    }

    /// The lowercase name listings and metrics use: the wire's
    /// ([`WireJobState::name`], the one table of names).
    pub fn name(self) -> &'static str {
        WireJobState::from(self).name()
    }
}

impl std::fmt::Display for JobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl From<JobState> for WireJobState {
    fn from(state: JobState) -> Self {
        match state {
            JobState::Queued => WireJobState::Queued,
            JobState::Running => WireJobState::Running,
            JobState::Paused => WireJobState::Paused,
            JobState::Completed => WireJobState::Completed,
            JobState::Failed => WireJobState::Failed,
            JobState::Cancelled => WireJobState::Cancelled,
        }
    }
}

impl From<WireJobState> for JobState {
    fn from(state: WireJobState) -> Self {
        match state {
            WireJobState::Queued => JobState::Queued,
            WireJobState::Running => JobState::Running,
            WireJobState::Paused => JobState::Paused,
            WireJobState::Completed => JobState::Completed,
            WireJobState::Failed => JobState::Failed,
            WireJobState::Cancelled => JobState::Cancelled,
        }
    }
}

/// How many finished jobs a master keeps listed (with their frames, on a
/// persistent master), and for how long after they finished: the older
/// ones go first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Retention {
    pub max_jobs: usize,
    pub max_age: Duration,
}

impl Retention {
    /// The most finished jobs a master may be told to keep: each keeps its
    /// definition in memory and its listing in every `jobs` reply.
    pub const MAX_JOBS: usize = 10_000;

    /// 100 finished jobs, each for at most a day.
    pub const DEFAULT: Retention = Retention {
        max_jobs: 100,
        max_age: Duration::from_secs(24 * 3600),
    };
}

impl Default for Retention {
    fn default() -> Self {
        Retention::DEFAULT
    }
}

/// The characters of a job's name its listing keeps: a name is the
/// submitter's to choose, and every `jobs` reply carries every listing.
pub const MAX_LISTED_NAME_CHARS: usize = 200;

/// `name` as a listing keeps it: at most [`MAX_LISTED_NAME_CHARS`]
/// characters, an ellipsis where it was cut.
pub fn listed_name(name: &str) -> String {
    match name.char_indices().nth(MAX_LISTED_NAME_CHARS) {
        Some((cut, _)) => format!("{}…", &name[..cut]),
        None => name.to_owned(),
    }
}

/// One job's listing: what `vtfarm jobs` shows and the journal keeps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JobEntry {
    pub id: JobId,
    pub name: String,
    pub kind: WireJobKind,
    pub state: JobState,
    pub priority: i32,
    pub frames_done: u32,
    pub frames_total: u32,
    /// Milliseconds since the Unix epoch.
    pub submitted_ms: u64,
    pub started_ms: Option<u64>,
    pub finished_ms: Option<u64>,
    pub host: String,
    /// Why it failed or who cancelled it.
    pub reason: String,
    /// The study it is a variant of.
    pub study: Option<JobId>,
    /// A study's variants, in order (empty for any other job).
    pub variants: Vec<JobId>,
}

impl JobEntry {
    /// The listing as the wire carries it.
    pub fn summary(&self) -> JobSummary {
        let unfinished = self.frames_total.saturating_sub(self.frames_done);
        let (frames_failed, frames_cancelled) = match self.state {
            JobState::Failed => (unfinished, 0),
            JobState::Cancelled => (0, unfinished),
            _ => (0, 0),
        };
        JobSummary {
            id: self.id,
            name: self.name.clone(),
            kind: self.kind,
            state: self.state.into(),
            priority: self.priority,
            frames_done: self.frames_done,
            frames_failed,
            frames_cancelled,
            frames_total: self.frames_total,
            submitted_ms: self.submitted_ms,
            started_ms: self.started_ms,
            finished_ms: self.finished_ms,
            host: self.host.clone(),
            reason: self.reason.clone(),
        }
    }

    /// The listing back from the journal.
    pub fn from_summary(summary: JobSummary) -> JobEntry {
        JobEntry {
            id: summary.id,
            name: summary.name,
            kind: summary.kind,
            state: summary.state.into(),
            priority: summary.priority,
            frames_done: summary.frames_done,
            frames_total: summary.frames_total,
            submitted_ms: summary.submitted_ms,
            started_ms: summary.started_ms,
            finished_ms: summary.finished_ms,
            host: summary.host,
            reason: summary.reason,
            study: None,
            variants: Vec::new(),
        }
    }

    /// Whether it is a study (its variants listed under it).
    pub fn is_study(&self) -> bool {
        self.kind == WireJobKind::Study && self.study.is_none() && !self.variants.is_empty()
    }
}

/// A study's state from its variants' (the module's documentation has the
/// rule); `None` for a study without variants.
pub fn study_state(variants: &[&JobEntry]) -> Option<JobState> {
    use JobState::*;
    if variants.is_empty() {
        return None;
    }
    let has = |state: JobState| variants.iter().any(|v| v.state == state);
    let unfinished = || variants.iter().filter(|v| !v.state.is_finished());
    Some(if variants.iter().all(|v| v.state.is_finished()) {
        if variants.iter().all(|v| v.state == Completed) {
            Completed
        } else if has(Cancelled) {
            Cancelled
        } else {
            Failed
        }
    } else if unfinished().all(|v| v.state == Paused) {
        Paused
    } else if variants
        .iter()
        .any(|v| v.state == Running || v.state.is_finished() || v.started_ms.is_some())
    {
        Running
    } else {
        Queued
    })
}

/// A transition the table does not allow.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("job {job} is {from} and cannot become {to}")]
pub struct TransitionRefused {
    pub job: JobId,
    pub from: JobState,
    pub to: JobState,
}

/// Why a user's request about a job is refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum JobControlError {
    #[error(
        "the master has no job {0} (finished longer ago than it keeps jobs, or never submitted)"
    )]
    UnknownJob(JobId),
    #[error("job {job} is {state}: {action} applies to {applies_to} jobs")]
    NotNow {
        job: JobId,
        state: JobState,
        action: &'static str,
        applies_to: &'static str,
    },
    #[error("job {0} has no failed frames to requeue")]
    NothingToRequeue(JobId),
    #[error("job {0} is the interactive view's: the dashboard steers it")]
    ViewJob(JobId),
    #[error("job {job} cannot be queued again: {reason}")]
    Requeue { job: JobId, reason: String },
    #[error("job {job} is a variant of study {study}: control the study")]
    InStudy { job: JobId, study: JobId },
}

/// Every listed job, by id (so in submission order).
#[derive(Debug, Default)]
pub struct JobTable {
    entries: BTreeMap<JobId, JobEntry>,
}

impl JobTable {
    pub fn get(&self, id: JobId) -> Option<&JobEntry> {
        self.entries.get(&id)
    }

    pub(crate) fn get_mut(&mut self, id: JobId) -> Option<&mut JobEntry> {
        self.entries.get_mut(&id)
    }

    pub(crate) fn insert(&mut self, entry: JobEntry) {
        self.entries.insert(entry.id, entry);
    }

    pub(crate) fn remove(&mut self, id: JobId) -> Option<JobEntry> {
        self.entries.remove(&id)
    }

    /// Moves job `id` to `to` at `at_ms` (setting its start or finish
    /// time), if the table allows it; `Ok(None)` for a job the table does
    /// not list (a frame rendered again has no state to keep).
    pub(crate) fn set_state(
        &mut self,
        id: JobId,
        to: JobState,
        at_ms: u64,
    ) -> Result<Option<&JobEntry>, TransitionRefused> {
        let Some(entry) = self.entries.get_mut(&id) else {
            return Ok(None);
        };
        if !entry.state.may_become(to) {
            return Err(TransitionRefused {
                job: id,
                from: entry.state,
                to,
            });
        }
        entry.state = to;
        match to {
            JobState::Running => {
                entry.started_ms.get_or_insert(at_ms);
            }
            JobState::Queued => {
                entry.finished_ms = None;
                entry.reason.clear();
            }
            _ if to.is_finished() => entry.finished_ms = Some(at_ms),
            _ => {}
        }
        Ok(Some(entry))
    }

    /// The jobs, oldest first: every one with `all`, else the unfinished;
    /// a study's variants only under it ([`JobTable::row`]).
    pub fn list(&self, all: bool) -> impl Iterator<Item = &JobEntry> {
        (self.entries.values())
            .filter(move |e| e.study.is_none() && (all || !e.state.is_finished()))
    }

    /// A job's row: its listing, and a study's variants' under it.
    pub fn row(&self, entry: &JobEntry) -> JobRow {
        JobRow {
            job: entry.summary(),
            variants: (entry.variants.iter())
                .filter_map(|&v| self.entries.get(&v))
                .map(JobEntry::summary)
                .collect(),
        }
    }

    /// The listed rows, as [`JobTable::list`] picks them.
    pub fn rows(&self, all: bool) -> Vec<JobRow> {
        self.list(all).map(|e| self.row(e)).collect()
    }

    /// Lists `study` over `variants` (listed already): its frames and
    /// state follow theirs from now on.
    pub(crate) fn insert_study(&mut self, mut study: JobEntry, variants: &[JobId]) {
        study.variants = (variants.iter().copied())
            .filter(|v| self.entries.contains_key(v))
            .collect();
        for v in &study.variants {
            if let Some(variant) = self.entries.get_mut(v) {
                variant.study = Some(study.id);
            }
        }
        self.entries.insert(study.id, study);
    }

    /// Brings study `id`'s frames and state in line with its variants' at
    /// `at_ms`; whether its state changed. A state the table does not
    /// allow at once is reached through running (a variant that finished
    /// before any was seen running).
    pub(crate) fn refresh_study(&mut self, id: JobId, at_ms: u64) -> bool {
        let Some(study) = self.entries.get(&id) else {
            return false;
        };
        let variants: Vec<&JobEntry> = (study.variants.iter())
            .filter_map(|v| self.entries.get(v))
            .collect();
        let Some(to) = study_state(&variants) else {
            return false;
        };
        let done = variants.iter().map(|v| v.frames_done).sum();
        let total = variants.iter().map(|v| v.frames_total).sum();
        // A finished study says why from its first variant that did not complete.
        let why = (variants.iter())
            .find(|v| v.state == to && !v.reason.is_empty())
            .map(|v| format!("variant {:?}: {}", v.name, v.reason));
        let from = study.state;
        let study = self.entries.get_mut(&id).expect("looked up above");
        study.frames_done = done;
        study.frames_total = total;
        if from == to {
            return false;
        }
        if !from.may_become(to) && from.may_become(JobState::Running) {
            let _ = self.set_state(id, JobState::Running, at_ms);
        }
        let moved = matches!(self.set_state(id, to, at_ms), Ok(Some(_)));
        if let (true, Some(why)) = (moved && to.is_finished(), why) {
            let study = self.entries.get_mut(&id).expect("looked up above");
            if study.reason.is_empty() {
                study.reason = why;
            }
        }
        moved
    }

    /// How many listed jobs are in `state` (a study counts once, as
    /// [`JobTable::list`] lists it).
    pub fn count(&self, state: JobState) -> usize {
        self.list(true).filter(|e| e.state == state).count()
    }

    /// The finished jobs `retention` lets go at `now_ms`: those beyond its
    /// count (the earliest finished first) and those finished too long ago.
    pub(crate) fn expired(&self, retention: Retention, now_ms: u64) -> Vec<JobId> {
        // A study's variants go with it.
        let mut finished: Vec<(u64, JobId)> = (self.entries.values())
            .filter(|e| e.study.is_none())
            .filter_map(|e| Some((e.finished_ms?, e.id)).filter(|_| e.state.is_finished()))
            .collect();
        finished.sort_unstable();
        let excess = finished.len().saturating_sub(retention.max_jobs);
        let max_age = retention.max_age.as_millis() as u64;
        (finished.iter().enumerate())
            .filter(|&(i, &(at, _))| i < excess || now_ms >= at.saturating_add(max_age))
            .map(|(_, &(_, id))| id)
            .collect()
    }

    /// When the next finished job gets too old, in milliseconds since the epoch.
    pub(crate) fn next_expiry(&self, retention: Retention) -> Option<u64> {
        let max_age = retention.max_age.as_millis() as u64;
        (self.entries.values())
            .filter(|e| e.state.is_finished() && e.study.is_none())
            .filter_map(|e| e.finished_ms)
            .min()
            .map(|at| at.saturating_add(max_age))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_listing_keeps_a_bounded_name_cut_at_a_character() {
        assert_eq!(listed_name("cockpit"), "cockpit");
        let exact = "é".repeat(MAX_LISTED_NAME_CHARS);
        assert_eq!(listed_name(&exact), exact);
        let long = "é".repeat(10 * MAX_LISTED_NAME_CHARS);
        let listed = listed_name(&long);
        assert_eq!(listed.chars().count(), MAX_LISTED_NAME_CHARS + 1);
        assert!(listed.ends_with('…'));
    }

    #[test]
    fn finished_states_leave_only_by_requeue() {
        for from in JobState::ALL.into_iter().filter(|s| s.is_finished()) {
            for to in JobState::ALL {
                assert_eq!(from.may_become(to), to == JobState::Queued, "{from} → {to}");
            }
        }
    }

    #[test]
    fn wire_states_convert_both_ways() {
        for state in JobState::ALL {
            assert_eq!(JobState::from(WireJobState::from(state)), state);
        }
    }

    fn finished(id: JobId, at_ms: u64) -> JobEntry {
        JobEntry {
            id,
            name: format!("job {id}"),
            kind: WireJobKind::Render,
            state: JobState::Completed,
            priority: 0,
            frames_done: 1,
            frames_total: 1,
            submitted_ms: 0,
            started_ms: Some(0),
            finished_ms: Some(at_ms),
            host: "test".into(),
            reason: String::new(),
            study: None,
            variants: Vec::new(),
        }
    }

    fn variant(id: JobId, state: JobState, started: bool) -> JobEntry {
        JobEntry {
            kind: WireJobKind::Variant,
            state,
            frames_done: u32::from(state == JobState::Completed) * 2,
            frames_total: 2,
            started_ms: started.then_some(10),
            finished_ms: state.is_finished().then_some(20),
            ..finished(id, 0)
        }
    }

    #[test]
    fn a_studys_state_follows_its_variants() {
        use JobState::*;
        let cases = [
            (vec![(Queued, false), (Queued, false)], Queued),
            (vec![(Running, true), (Queued, false)], Running),
            // Between two variants (one done, the next not yet started).
            (vec![(Completed, true), (Queued, false)], Running),
            // Resumed after it had started: running though none runs now.
            (vec![(Queued, true), (Queued, false)], Running),
            (vec![(Paused, true), (Paused, false)], Paused),
            (vec![(Completed, true), (Paused, false)], Paused),
            (vec![(Paused, true), (Running, true)], Running),
            (vec![(Completed, true), (Completed, true)], Completed),
            (vec![(Completed, true), (Failed, true)], Failed),
            (vec![(Failed, true), (Cancelled, true)], Cancelled),
            (vec![(Completed, true), (Cancelled, false)], Cancelled),
        ];
        for (states, expected) in cases {
            let variants: Vec<JobEntry> = (states.iter().enumerate())
                .map(|(i, &(state, started))| variant(JobId(i as u64), state, started))
                .collect();
            let refs: Vec<&JobEntry> = variants.iter().collect();
            assert_eq!(study_state(&refs), Some(expected), "{states:?}");
        }
        assert_eq!(study_state(&[]), None);
    }

    /// A table of a study (id 1) over variants 2 and 3, queued.
    fn study_table(a: JobState, b: JobState) -> JobTable {
        let mut table = JobTable::default();
        table.insert(variant(JobId(2), a, a != JobState::Queued));
        table.insert(variant(JobId(3), b, b != JobState::Queued));
        let study = JobEntry {
            kind: WireJobKind::Study,
            state: JobState::Queued,
            frames_done: 0,
            frames_total: 0,
            started_ms: None,
            finished_ms: None,
            ..finished(JobId(1), 0)
        };
        table.insert_study(study, &[JobId(2), JobId(3), JobId(99)]);
        table
    }

    #[test]
    fn a_study_lists_its_variants_under_it_and_sums_their_frames() {
        let mut table = study_table(JobState::Completed, JobState::Running);
        assert!(table.refresh_study(JobId(1), 30));
        let study = table.get(JobId(1)).unwrap();
        // An unknown variant is not listed.
        assert_eq!(study.variants, [JobId(2), JobId(3)]);
        assert_eq!((study.frames_done, study.frames_total), (2, 4));
        assert_eq!(
            (study.state, study.started_ms),
            (JobState::Running, Some(30))
        );
        let listed: Vec<JobId> = table.list(true).map(|e| e.id).collect();
        assert_eq!(listed, [JobId(1)]);
        let row = table.row(table.get(JobId(1)).unwrap());
        let ids: Vec<JobId> = row.variants.iter().map(|v| v.id).collect();
        assert_eq!((row.job.id, ids), (JobId(1), vec![JobId(2), JobId(3)]));
        // Nothing changed: nothing to journal.
        assert!(!table.refresh_study(JobId(1), 40));
    }

    #[test]
    fn a_study_finished_at_once_goes_through_running_by_the_table() {
        let mut table = study_table(JobState::Completed, JobState::Failed);
        table.get_mut(JobId(3)).unwrap().reason = "package failed".into();
        assert!(table.refresh_study(JobId(1), 50));
        let study = table.get(JobId(1)).unwrap();
        assert_eq!(study.state, JobState::Failed);
        assert_eq!((study.started_ms, study.finished_ms), (Some(50), Some(50)));
        assert_eq!(study.reason, "variant \"job 3\": package failed");
        // Its variants go with it, never before it.
        let retention = Retention {
            max_jobs: 0,
            max_age: Duration::from_secs(1),
        };
        assert_eq!(table.expired(retention, 1_000_000), vec![JobId(1)]);
    }

    #[test]
    fn retention_lets_the_earliest_finished_and_the_too_old_go() {
        let mut table = JobTable::default();
        // Job 1 finished last, job 3 first.
        table.insert(finished(JobId(1), 3_000));
        table.insert(finished(JobId(2), 2_000));
        table.insert(finished(JobId(3), 1_000));
        let keep_two = Retention {
            max_jobs: 2,
            max_age: Duration::from_secs(10),
        };
        assert_eq!(table.expired(keep_two, 3_000), vec![JobId(3)]);
        assert_eq!(table.next_expiry(keep_two), Some(11_000));
        // 10 s after job 2 finished, it and job 3 are too old.
        assert_eq!(table.expired(keep_two, 12_000), vec![JobId(3), JobId(2)]);
        let mut running = finished(JobId(4), 0);
        running.state = JobState::Running;
        running.finished_ms = None;
        table.insert(running);
        assert_eq!(
            table.expired(keep_two, 100_000),
            vec![JobId(3), JobId(2), JobId(1)]
        );
    }
}
