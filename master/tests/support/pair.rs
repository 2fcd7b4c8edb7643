//! The master's tests run on the farm simulator's test harness
//! ([`vtfarm_farmsim::TestFarm`]: the real core and worker sessions, real
//! rendering, a virtual clock, fault knobs); this adds the server's job
//! journal in a temporary state directory for a persistent master.

use vtfarm_farmsim::{JobJournal, TestFarm};
use vtfarm_master::{FarmRules, Journal, Record, StoredJob};
use vtfarm_master_core::{DamagedJob, JobControlError, JobState};
use vtfarm_proto::JobId;
use vtfarm_proto::{FrameDone, JobAction, JobRow};

/// The harness under its old name.
pub(crate) type Pair = TestFarm;

/// The user who asks, as the listing names them.
pub(crate) const WHO: &str = "tester";

/// Job `job`'s state in the master's table.
pub(crate) fn state(pair: &Pair, job: JobId) -> Option<JobState> {
    pair.master.jobs().get(job).map(|e| e.state)
}

/// `action` on `job` as [`WHO`] asks it; the job's state after it.
pub(crate) fn control(
    pair: &mut Pair,
    job: JobId,
    action: JobAction,
) -> Result<JobState, JobControlError> {
    let summary = pair.act(|m, now| m.control_job(now, job, action, WHO))?;
    Ok(summary.state.into())
}

/// The master's job journal in a temporary state directory it owns.
struct TempJournal {
    journal: Journal,
    _dir: tempfile::TempDir,
}

impl JobJournal for TempJournal {
    fn write(&self, record: Record) -> Result<(), String> {
        self.journal.write(record).map_err(|e| e.to_string())
    }

    fn frame(&self, job: JobId, frame: u32) -> Result<FrameDone, String> {
        self.journal.frame(job, frame).map_err(|e| e.to_string())
    }

    fn load(&self) -> (Vec<StoredJob>, Vec<DamagedJob>) {
        let loaded = self.journal.load();
        (loaded.jobs, loaded.damaged)
    }

    fn load_studies(&self) -> Vec<JobRow> {
        self.journal.load().studies
    }
}

/// A harness whose master journals its jobs in a temporary state directory.
pub(crate) fn persistent(rules: FarmRules) -> Pair {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    TestFarm::persistent(rules, TempJournal { journal, _dir: dir })
}
