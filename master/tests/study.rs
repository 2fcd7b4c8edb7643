//! A study as one job through the sans-IO core on a virtual clock (`Pair`:
//! the real core and worker sessions, real rendering): one listed job over
//! its variants, its state following theirs through the job table's rules;
//! pause, resume, cancel, requeue and priority acting on every variant;
//! attaching by its id; and the study through a master restart.

#[path = "support/frame.rs"]
mod frame;
#[path = "support/job.rs"]
mod job;

mod support;

use std::time::Duration;
use vtfarm_proto::JobId;

use job::Job;
use support::pair::{Pair, WHO, control, state};
use vtfarm_master::FarmRules;
use vtfarm_master_core::{JobControlError, JobState};
use vtfarm_proto::{JobAction, JobRow, Message, WireJobKind, WireStudy};

/// Virtual time a scenario may take at most.
const BOUND: Duration = Duration::from_secs(600);

/// The study's variants' states, in order.
fn variant_states(pair: &Pair, study: JobId) -> Vec<JobState> {
    let entry = pair.master.jobs().get(study).expect("the study is listed");
    (entry.variants.iter())
        .map(|&v| state(pair, v).expect("a variant is listed"))
        .collect()
}

/// Submits a study of `variants` variants of `job`; its id and its
/// variants' ids.
fn submit_study(pair: &mut Pair, job: &Job, variants: usize) -> (JobId, Vec<JobId>) {
    let (wire, data) = job.wire();
    let study = WireStudy {
        name: "study".into(),
        priority: 0,
        variants: (0..variants)
            .map(|v| vtfarm_proto::WireJob {
                name: format!("variant {v}"),
                kind: WireJobKind::Study,
                ..wire.clone()
            })
            .collect(),
    };
    pair.submit_study(study, data);
    let accepted = |p: &Pair| {
        p.to_submitter.iter().find_map(|m| match m {
            Message::StudyAccepted { study, variants } => Some((*study, variants.clone())),
            _ => None,
        })
    };
    pair.drive(BOUND, |p| accepted(p).is_some());
    let (study, variants) = accepted(pair).expect("accepted");
    (study, variants.into_iter().map(|(job, _)| job).collect())
}

/// The frames the submitter got, by (job, frame), each once.
fn frames_got(pair: &Pair) -> std::collections::BTreeSet<(JobId, u32)> {
    (pair.to_submitter.iter())
        .filter_map(|m| match m {
            Message::FrameDone(done) => Some((done.job, done.frame)),
            _ => None,
        })
        .collect()
}

#[test]
fn a_study_is_one_row_whose_state_follows_its_variants_through_pause_and_resume() {
    use JobState::*;
    let job = Job::new(2);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("w1", 1.0);
    let (study, variants) = submit_study(&mut pair, &job, 2);
    // One row: the study over its two variants, four frames in all.
    let rows: Vec<JobRow> = pair.master.jobs().rows(true);
    assert_eq!(rows.len(), 1, "{rows:?}");
    assert_eq!(rows[0].job.id, study);
    assert_eq!(rows[0].job.kind, WireJobKind::Study);
    assert_eq!(rows[0].job.frames_total, 4);
    let listed: Vec<JobId> = rows[0].variants.iter().map(|v| v.id).collect();
    assert_eq!(listed, variants);
    assert!(
        rows[0]
            .variants
            .iter()
            .all(|v| v.kind == WireJobKind::Variant)
    );
    // A variant is controlled only through its study.
    assert_eq!(
        control(&mut pair, variants[1], JobAction::Pause),
        Err(JobControlError::InStudy {
            job: variants[1],
            study
        })
    );
    pair.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    assert_eq!(state(&pair, study), Some(Running));

    // Paused: every variant is, what runs finishes, nothing new starts.
    assert_eq!(control(&mut pair, study, JobAction::Pause), Ok(Paused));
    assert_eq!(variant_states(&pair, study), [Paused, Paused]);
    // (A worker holds one package ahead of the one it runs: it may start
    // after the pause; none is handed out after it.)
    let paused_at = pair.now;
    let held: usize = (pair.master.packages_by_worker().values())
        .map(Vec::len)
        .sum();
    pair.drive(BOUND, |p| p.master.packages_by_worker().is_empty());
    let quiet_until = pair.now + Duration::from_secs(60);
    pair.drive(2 * BOUND, |p| p.now >= quiet_until);
    let started_after = (pair.busy.iter().flatten()).filter(|run| run.start > paused_at);
    assert!(
        started_after.count() <= held,
        "a package handed out while paused"
    );
    assert!(pair.master.packages_by_worker().is_empty());
    assert!(frames_got(&pair).len() < 4);
    assert_eq!(state(&pair, study), Some(Paused));

    // Resumed, it runs to the end: completed when every variant is, its
    // frames theirs together.
    assert_eq!(control(&mut pair, study, JobAction::Resume), Ok(Running));
    pair.drive(BOUND, |p| state(p, study) == Some(Completed));
    assert_eq!(variant_states(&pair, study), [Completed, Completed]);
    let entry = pair.master.jobs().get(study).unwrap().clone();
    assert_eq!((entry.frames_done, entry.frames_total), (4, 4));
    pair.drive(BOUND, |p| frames_got(p).len() == 4);
    let expected: std::collections::BTreeSet<(JobId, u32)> =
        (variants.iter()).flat_map(|&v| [(v, 0), (v, 1)]).collect();
    assert_eq!(frames_got(&pair), expected);
    // Each variant's frames are the single-process render's.
    let reference = job.reference();
    for m in &pair.to_submitter {
        if let Message::FrameDone(done) = m {
            let (_, _, pixels) = done.image.clone().into_pixels().unwrap();
            assert!(
                pixels == reference[done.frame as usize],
                "job {} frame {}: pixels differ from the single-process render",
                done.job,
                done.frame
            );
        }
    }
    // A finished study takes no priority and no pause.
    assert!(matches!(
        control(&mut pair, study, JobAction::SetPriority(2)),
        Err(JobControlError::NotNow { .. })
    ));
}

#[test]
fn a_cancelled_study_says_who_and_requeue_failed_runs_only_its_unfinished_variants() {
    use JobState::*;
    let job = Job::new(2);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("w1", 1.0);
    let (study, variants) = submit_study(&mut pair, &job, 2);
    assert_eq!(
        control(&mut pair, study, JobAction::SetPriority(4)),
        Ok(Running)
    );
    let priorities: Vec<i32> = (variants.iter())
        .map(|&v| pair.master.jobs().get(v).unwrap().priority)
        .collect();
    assert_eq!(priorities, [4, 4]);
    // The first variant completes; the study is cancelled while the
    // second runs.
    pair.drive(BOUND, |p| state(p, variants[0]) == Some(Completed));
    assert_eq!(control(&mut pair, study, JobAction::Cancel), Ok(Cancelled));
    assert_eq!(variant_states(&pair, study), [Completed, Cancelled]);
    let entry = pair.master.jobs().get(study).unwrap().clone();
    assert_eq!(
        entry.reason,
        format!("study {study} was cancelled by {WHO}")
    );
    assert_eq!(entry.summary().frames_cancelled, 4 - entry.frames_done);
    // Only the cancelled variant runs again; the study completes.
    assert_eq!(
        control(&mut pair, study, JobAction::Requeue { failed_only: true }),
        Ok(Running)
    );
    assert_eq!(state(&pair, variants[0]), Some(Completed));
    pair.drive(BOUND, |p| state(p, study) == Some(Completed));
    assert_eq!(
        control(&mut pair, study, JobAction::Requeue { failed_only: true }),
        Err(JobControlError::NothingToRequeue(study))
    );
    // Requeued whole: every variant again from its first frame.
    assert_eq!(
        control(&mut pair, study, JobAction::Requeue { failed_only: false }),
        Ok(Running)
    );
    assert_eq!(pair.master.jobs().get(study).unwrap().frames_done, 0);
    pair.drive(BOUND, |p| state(p, study) == Some(Completed));
}

#[test]
fn a_study_survives_a_master_restart_and_an_attach_by_its_id_gets_every_frame() {
    use JobState::*;
    let job = Job::new(2);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("w1", 1.0);
    let (study, variants) = submit_study(&mut pair, &job, 2);
    pair.drive(BOUND, |p| !frames_got(p).is_empty());
    let before = pair.master.jobs().rows(true);
    pair.restart_master();
    let after = pair.master.jobs().rows(true);
    assert_eq!(after.len(), 1, "{after:?}");
    assert_eq!(after[0].job.id, study);
    assert_eq!(after[0].job.kind, WireJobKind::Study);
    let ids = |rows: &[JobRow]| rows[0].variants.iter().map(|v| v.id).collect::<Vec<_>>();
    assert_eq!(ids(&after), ids(&before));
    assert_eq!(ids(&after), variants);
    pair.drive(BOUND, |p| state(p, study) == Some(Completed));
    // Attached by the study's id: its variants, then each one's frames.
    pair.forget_records();
    pair.attach_submitter(study);
    let accepted = (pair.to_submitter.iter()).find_map(|m| match m {
        Message::StudyAccepted { study: s, variants } if *s == study => Some(variants.clone()),
        _ => None,
    });
    assert_eq!(accepted, Some(vec![(variants[0], 2), (variants[1], 2)]));
    // (The harness's submitter asks from the first frame it lacks of any
    // job: one variant at a time.)
    for &v in &variants {
        pair.forget_records();
        pair.attach_submitter(v);
        pair.drive(BOUND, |p| frames_got(p) == [(v, 0), (v, 1)].into());
    }
}

#[test]
fn a_study_with_a_variant_the_master_refuses_is_listed_cancelled_with_why() {
    let job = Job::new(2);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("w1", 1.0);
    let (wire, data) = job.wire();
    let refused = vtfarm_proto::WireJob {
        name: "no frames".into(),
        frames: Vec::new(),
        ..wire.clone()
    };
    let study = WireStudy {
        name: "study".into(),
        priority: 0,
        variants: vec![wire, refused],
    };
    pair.submit_study(study, data);
    pair.drive(BOUND, |p| p.job_failed().is_some());
    let errors = pair.job_failed().unwrap().clone();
    assert!(
        errors[0].starts_with("variant \"no frames\": "),
        "{errors:?}"
    );
    // The variant queued before it is cancelled; the study is listed so, saying why.
    let rows = pair.master.jobs().rows(true);
    assert_eq!(rows.len(), 1, "{rows:?}");
    assert_eq!(rows[0].job.state, vtfarm_proto::WireJobState::Cancelled);
    assert!(
        rows[0]
            .job
            .reason
            .contains("was refused: variant \"no frames\""),
        "{}",
        rows[0].job.reason
    );
    assert_eq!(rows[0].variants.len(), 1);
    assert_eq!(
        rows[0].variants[0].state,
        vtfarm_proto::WireJobState::Cancelled
    );
}
