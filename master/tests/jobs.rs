//! Managing jobs through the sans-IO core on a virtual clock (`Pair`: the
//! real core and worker sessions, real rendering): every transition of the
//! job table and no other, priority order, pause and resume, cancel (with
//! `CancelPackage` to exactly the workers that hold the job's packages),
//! requeue, and every state through a master restart on the journal.

#[path = "support/frame.rs"]
mod frame;
#[path = "support/job.rs"]
mod job;

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;
use vtfarm_proto::JobId;

use job::Job;
use support::pair::{Pair, WHO, control, state};
use vtfarm_master::{ConnId, FarmRules, Output};
use vtfarm_master_core::{JobControlError, JobState};
use vtfarm_proto::{FrameDone, JobAction, Message, PackageFailed, WireJob, WireJobState};

/// Virtual time a scenario may take at most.
const BOUND: Duration = Duration::from_secs(600);

/// The ids the master gave the submitter's jobs, in order.
fn accepted(pair: &Pair) -> Vec<JobId> {
    (pair.to_submitter.iter())
        .filter_map(|m| match m {
            Message::JobAccepted { job, .. } => Some(*job),
            _ => None,
        })
        .collect()
}

/// A harness of `workers` (name, slowdown) that copies no straggler's
/// package: which worker holds what follows from the speeds alone.
fn without_stragglers(workers: &[(&str, f64)]) -> Pair {
    let mut pair = Pair::new(FarmRules {
        straggler: None,
        ..FarmRules::default()
    });
    for &(name, slowdown) in workers {
        pair.add_worker(name, slowdown);
    }
    pair
}

/// Submits `wire` at `priority`; returns its id.
fn submit(pair: &mut Pair, job: &Job, priority: i32) -> JobId {
    let (wire, data) = job.wire();
    let before = accepted(pair).len();
    pair.submit(WireJob { priority, ..wire }, data);
    // The master may ask for the scene first.
    pair.drive(BOUND, |p| accepted(p).len() > before);
    let ids = accepted(pair);
    assert_eq!(ids.len(), before + 1, "the job is accepted");
    ids[before]
}

/// The finished frames of `job` the submitter got, first copy of each.
fn frames_of(pair: &Pair, job: JobId) -> Vec<&FrameDone> {
    let mut frames: Vec<&FrameDone> = Vec::new();
    for m in &pair.to_submitter {
        if let Message::FrameDone(done) = m {
            if done.job == job && done.frame as usize == frames.len() {
                frames.push(done);
            }
        }
    }
    frames
}

/// Runs until job `id` is complete and the submitter has its `frames`
/// frames (they reach it a latency after the core finished them).
fn complete(pair: &mut Pair, id: JobId, frames: usize) {
    pair.drive(BOUND, |p| {
        state(p, id) == Some(JobState::Completed) && frames_of(p, id).len() == frames
    });
}

/// Packages held per worker name (`packages_by_worker`) as the
/// (connection, package) pairs a cancel tells.
fn by_connection(pair: &Pair, held: &BTreeMap<String, Vec<u64>>) -> BTreeSet<(ConnId, u64)> {
    (pair.workers.iter())
        .flat_map(|w| {
            let ids = held.get(&w.name).cloned().unwrap_or_default();
            ids.into_iter().map(move |p| (w.conn(), p))
        })
        .collect()
}

/// No frame of `id` had a package requeued or failed: nothing was taken
/// back from a worker.
fn assert_nothing_taken_back(pair: &Pair, id: JobId) {
    for done in frames_of(pair, id) {
        assert_eq!(
            (done.stats.requeued, done.stats.failures),
            (0, 0),
            "{:?}",
            done.stats
        );
    }
}

/// Checks `job`'s delivered frames against the single-process render.
fn check_images(pair: &Pair, id: JobId, job: &Job) {
    let reference = job.reference();
    let done = frames_of(pair, id);

    assert_eq!(done.len(), reference.len(), "job {id}: frames delivered");
    for (done, reference) in done.into_iter().zip(&reference) {
        let (_, _, pixels) = done.image.clone().into_pixels().unwrap();
        assert!(
            &pixels == reference,
            "job {id} frame {}: pixels differ from the single-process render",
            done.frame
        );
    }
}

/// Fails every package the workers hold (as `PackageFailed` from each)
/// until the job fails: a package failed on three workers fails it.
fn fail_until_the_job_fails(pair: &mut Pair, id: JobId) {
    for _ in 0..30 {
        if state(pair, id) == Some(JobState::Failed) {
            return;
        }
        pair.drive(BOUND, |p| {
            !p.master.packages_by_worker().is_empty() || p.master.jobs().get(id).is_none()
        });
        let held = pair.master.packages_by_worker();
        let failures: Vec<(ConnId, u64)> = (pair.workers.iter())
            .flat_map(|w| {
                let ids = held.get(&w.name).cloned().unwrap_or_default();
                ids.into_iter().map(move |p| (w.conn(), p))
            })
            .collect();
        for (conn, package) in failures {
            let failed = PackageFailed {
                id: package,
                error: "injected failure".into(),
            };
            pair.act(|m, now| m.message(now, conn, Message::PackageFailed(failed)));
        }
    }
    assert_eq!(state(pair, id), Some(JobState::Failed));
}

/// Rules under which a worker takes a whole small frame as one package.
fn whole_frame_packages() -> FarmRules {
    let mut rules = FarmRules {
        straggler: None,
        ..FarmRules::default()
    };
    rules.sizing.min_duration = Duration::from_secs(3600);
    rules.sizing.max_duration = Duration::from_secs(3600);
    rules
}

/// The transitions a test saw, checked against the job's state as it goes.
#[derive(Default)]
struct Seen(BTreeSet<(JobState, JobState)>);

impl Seen {
    /// Job `id` went through `path` (its first state the one before) and
    /// is in the last now; each step must be one the table allows.
    fn went(&mut self, pair: &Pair, id: JobId, path: &[JobState]) {
        for step in path.windows(2) {
            assert!(step[0].may_become(step[1]), "{:?} → {:?}", step[0], step[1]);
            self.0.insert((step[0], step[1]));
        }
        assert_eq!(
            state(pair, id),
            path.last().copied(),
            "job {id} after {path:?}"
        );
    }
}

#[test]
fn every_transition_of_the_table_happens_and_no_other_is_allowed() {
    use JobState::*;
    let job = Job::new(2);
    let mut seen = Seen::default();
    let mut pair = support::pair::persistent(FarmRules::default());

    // The first job starts at once (no worker yet), the second waits.
    let a = submit(&mut pair, &job, 0);
    seen.went(&pair, a, &[Queued, Running]);
    let b = submit(&mut pair, &job, 0);
    seen.went(&pair, b, &[Queued]);
    control(&mut pair, b, JobAction::Pause).unwrap();
    seen.went(&pair, b, &[Queued, Paused]);
    // Never started: back to the queue.
    control(&mut pair, b, JobAction::Resume).unwrap();
    seen.went(&pair, b, &[Paused, Queued]);
    control(&mut pair, b, JobAction::Cancel).unwrap();
    seen.went(&pair, b, &[Queued, Cancelled]);
    control(&mut pair, b, JobAction::Requeue { failed_only: false }).unwrap();
    seen.went(&pair, b, &[Cancelled, Queued]);

    pair.add_worker("w1", 1.0);
    pair.add_worker("w2", 1.0);
    pair.add_worker("w3", 1.0);
    pair.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    control(&mut pair, a, JobAction::Pause).unwrap();
    seen.went(&pair, a, &[Running, Paused]);
    control(&mut pair, a, JobAction::Resume).unwrap();
    seen.went(&pair, a, &[Paused, Running]);
    complete(&mut pair, a, 2);
    seen.went(&pair, a, &[Running, Completed]);
    check_images(&pair, a, &job);
    // b starts behind it; a requeued waits behind b.
    pair.drive(BOUND, |p| state(p, b) == Some(Running));
    seen.went(&pair, b, &[Queued, Running]);
    control(&mut pair, a, JobAction::Requeue { failed_only: false }).unwrap();
    seen.went(&pair, a, &[Completed, Queued]);
    // b paused while running, then cancelled: a starts, and is cancelled.
    control(&mut pair, b, JobAction::Pause).unwrap();
    control(&mut pair, b, JobAction::Cancel).unwrap();
    seen.went(&pair, b, &[Running, Paused, Cancelled]);
    pair.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    control(&mut pair, a, JobAction::Cancel).unwrap();
    seen.went(&pair, a, &[Queued, Running, Cancelled]);

    // A package failed on three workers fails its job.
    let c = submit(&mut pair, &job, 0);
    fail_until_the_job_fails(&mut pair, c);
    seen.went(&pair, c, &[Queued, Running, Failed]);
    let reason = &pair.master.jobs().get(c).unwrap().reason;
    assert!(reason.contains("injected failure"), "{reason}");
    control(&mut pair, c, JobAction::Requeue { failed_only: true }).unwrap();
    seen.went(&pair, c, &[Failed, Queued, Running]);
    // Paused, a running package that fails for good fails it too (here
    // the first failure is final).
    let mut strict = support::pair::persistent(FarmRules {
        retry: vtfarm_scheduler::RetryPolicy {
            package_failures: 1,
            ..Default::default()
        },
        ..FarmRules::default()
    });
    strict.add_worker("w1", 1.0);
    let g = submit(&mut strict, &job, 0);
    strict.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    control(&mut strict, g, JobAction::Pause).unwrap();
    fail_until_the_job_fails(&mut strict, g);
    seen.went(&strict, g, &[Running, Paused, Failed]);

    // Paused while its one package runs: the package finishes the job.
    let mut whole = Pair::new(whole_frame_packages());
    whole.add_worker("w1", 1.0);
    let one = Job::new(1);
    let d = submit(&mut whole, &one, 0);
    whole.drive(BOUND, |p| p.workers[0].is_running_a_package());
    control(&mut whole, d, JobAction::Pause).unwrap();
    assert_eq!(
        whole.master.packages_by_worker().values().flatten().count(),
        1
    );
    whole.drive(BOUND, |p| state(p, d) != Some(Paused));
    complete(&mut whole, d, 1);
    seen.went(&whole, d, &[Running, Paused, Completed]);
    check_images(&whole, d, &one);
    // An in-memory master cannot queue a job again: it keeps no definition.
    let answer = control(&mut whole, d, JobAction::Requeue { failed_only: false });
    assert!(
        matches!(answer, Err(JobControlError::Requeue { .. })),
        "{answer:?}"
    );

    // Every pair the table allows happened.
    let allowed: BTreeSet<(JobState, JobState)> = (JobState::ALL.into_iter())
        .flat_map(|from| JobState::ALL.into_iter().map(move |to| (from, to)))
        .filter(|&(from, to)| from.may_become(to))
        .collect();
    assert_eq!(seen.0, allowed);
    // Any other request is refused and changes nothing.
    let e = submit(&mut pair, &job, 0);
    let f = submit(&mut pair, &job, 0);
    control(&mut pair, f, JobAction::Pause).unwrap();
    let refused = [
        (a, JobAction::Pause),
        (a, JobAction::Resume),
        (a, JobAction::Cancel),
        (e, JobAction::Resume),
        (e, JobAction::Requeue { failed_only: false }),
        (f, JobAction::Pause),
        (f, JobAction::Requeue { failed_only: true }),
    ];
    for (job, action) in refused {
        let before = state(&pair, job);
        let answer = control(&mut pair, job, action);
        assert!(
            matches!(answer, Err(JobControlError::NotNow { .. })),
            "{action:?} of a {before:?} job: {answer:?}"
        );
        assert_eq!(state(&pair, job), before);
    }
    assert_eq!(
        control(&mut pair, JobId(99), JobAction::Cancel),
        Err(JobControlError::UnknownJob(JobId(99)))
    );
}

#[test]
fn jobs_run_by_priority_then_submission_and_a_higher_one_goes_first() {
    let job = Job::new(1);
    let mut pair = Pair::new(FarmRules::default());
    // No worker yet: the first job starts (none runs), the others wait
    // for a worker to ask, in priority order.
    let first = submit(&mut pair, &job, 0);
    let low = submit(&mut pair, &job, -1);
    let normal = submit(&mut pair, &job, 0);
    let high = submit(&mut pair, &job, 5);
    let high_later = submit(&mut pair, &job, 5);
    let raised = submit(&mut pair, &job, 0);
    assert_eq!(running_jobs(&pair), vec![first]);
    assert_eq!(
        control(&mut pair, raised, JobAction::SetPriority(9)),
        Ok(JobState::Queued)
    );
    assert_eq!(
        pair.master.status().queue.waiting,
        vec![raised, high, high_later, normal, low]
    );
    pair.add_worker("w1", 1.0);
    pair.drive(BOUND, |p| {
        (p.master.jobs().list(true)).all(|e| e.state == JobState::Completed)
            && frames_of(p, low).len() == 1
    });
    let finished: Vec<JobId> = (pair.to_submitter.iter())
        .filter_map(|m| match m {
            Message::FrameDone(done) => Some(done.job),
            _ => None,
        })
        .collect();
    assert_eq!(finished, vec![raised, high, high_later, first, normal, low]);
    for id in [first, low, raised] {
        check_images(&pair, id, &job);
    }
}

#[test]
fn a_pause_hands_out_nothing_new_and_keeps_what_runs() {
    let job = Job::new(2);
    let mut pair = without_stragglers(&[("slow", 3.0), ("fast", 1.0)]);
    let slow = 0; // the first worker
    let id = submit(&mut pair, &job, 0);
    pair.drive(BOUND, |p| p.workers[slow].is_running_a_package());
    assert_eq!(
        control(&mut pair, id, JobAction::Pause),
        Ok(JobState::Paused)
    );
    let paused_at = pair.now;
    let running: usize = (pair.master.packages_by_worker().values())
        .map(Vec::len)
        .sum();
    assert!(running > 0);
    // What runs finishes and is kept; nothing new starts.
    pair.drive(BOUND, |p| p.master.packages_by_worker().is_empty());
    let started_after = (pair.busy.iter().flatten()).filter(|run| run.start > paused_at);
    assert_eq!(started_after.count(), 0, "a package started while paused");
    let done_while_paused = (pair.busy.iter().flatten())
        .filter(|run| run.start <= paused_at && run.end.is_some_and(|e| e > paused_at))
        .count();
    assert_eq!(done_while_paused, running, "the running packages finished");
    // A long while later still nothing moves; then it resumes and completes
    // with the kept results in its images.
    let frames_before = frames_of(&pair, id).len();
    let quiet_until = pair.now + Duration::from_secs(60);
    pair.drive(2 * BOUND, |p| p.now >= quiet_until);
    assert_eq!(frames_of(&pair, id).len(), frames_before);
    assert!(pair.master.packages_by_worker().is_empty());
    assert_eq!(
        control(&mut pair, id, JobAction::Resume),
        Ok(JobState::Running)
    );
    complete(&mut pair, id, 2);
    check_images(&pair, id, &job);
    let changes: Vec<WireJobState> = (pair.to_submitter.iter())
        .filter_map(|m| match m {
            Message::JobStateChanged { state, .. } => Some(*state),
            _ => None,
        })
        .collect();
    assert_eq!(changes, [WireJobState::Paused, WireJobState::Running]);
}

#[test]
fn a_cancel_sends_cancel_package_to_exactly_the_workers_holding_the_job() {
    let job = Job::new(1);
    let mut pair = without_stragglers(&[("a", 1.0), ("b", 4.0), ("c", 8.0)]);
    let id = submit(&mut pair, &job, 0);
    // Near the frame's end some workers hold nothing while others work.
    pair.drive(BOUND, |p| {
        let held = p.master.packages_by_worker();
        !held.is_empty() && held.len() < p.workers.len()
    });
    let held = pair.master.packages_by_worker();
    let expected = by_connection(&pair, &held);
    // The core's outputs straight: which connection is told what.
    let now = pair.now;
    let summary = (pair.master)
        .control_job(now, id, JobAction::Cancel, WHO)
        .expect("running jobs may be cancelled");
    assert_eq!(summary.state, WireJobState::Cancelled);
    let mut cancels = BTreeSet::new();
    let mut told = None;
    while let Some(output) = pair.master.poll_output() {
        if let Output::Send(conn, message) = output {
            match *message {
                Message::CancelPackage { id } => {
                    assert!(cancels.insert((conn, id)), "package {id} cancelled twice");
                }
                Message::JobStateChanged { reason, .. } => told = Some(reason),
                _ => {}
            }
        }
    }
    assert_eq!(cancels, expected);
    assert_eq!(told, Some(format!("job {id} was cancelled by {WHO}")));
    assert_eq!(pair.master.jobs().get(id).unwrap().frames_done, 0);
    assert!(pair.master.status().queue.running.is_empty());
}

#[test]
fn requeue_failed_renders_only_the_frames_a_cancelled_job_did_not_finish() {
    let job = Job::new(3);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("w1", 1.0);
    let id = submit(&mut pair, &job, 0);
    pair.drive(BOUND, |p| frames_of(p, id).len() == 1);
    assert_eq!(
        control(&mut pair, id, JobAction::Cancel),
        Ok(JobState::Cancelled)
    );
    let done = pair.master.jobs().get(id).unwrap().frames_done;
    assert!(done >= 1);
    let summary = pair.master.jobs().get(id).unwrap().summary();
    assert_eq!(summary.frames_cancelled, 3 - done);
    assert_eq!(
        summary.frames_failed, 0,
        "cancelled frames are not failed ones"
    );
    let starts_before = pair.frame_starts.len();
    assert_eq!(
        control(&mut pair, id, JobAction::Requeue { failed_only: true }),
        Ok(JobState::Running)
    );
    pair.drive(BOUND, |p| state(p, id) == Some(JobState::Completed));
    // The set of frames: a frame's start may reach a worker in any order
    // (a whole frame's travels with its package).
    let again: BTreeSet<u32> = (pair.frame_starts[starts_before..].iter())
        .filter(|&&(job, _)| job == id)
        .map(|&(_, frame)| frame)
        .collect();
    assert_eq!(
        again,
        (done..3).collect::<BTreeSet<u32>>(),
        "only the unfinished frames"
    );
    // A submitter attaching afterwards gets all three, from the journal.
    pair.forget_records();
    pair.attach_submitter(id);
    pair.drive(BOUND, |p| frames_of(p, id).len() == 3);
    check_images(&pair, id, &job);
    assert_eq!(
        control(&mut pair, id, JobAction::Requeue { failed_only: true }),
        Err(JobControlError::NothingToRequeue(id))
    );
}

#[test]
fn every_state_and_the_list_survive_a_master_restart() {
    let job = Job::new(2);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("w1", 1.0);
    pair.add_worker("w2", 1.0);
    pair.add_worker("w3", 1.0);
    let completed = submit(&mut pair, &job, 0);
    pair.drive(BOUND, |p| state(p, completed) == Some(JobState::Completed));
    let failed = submit(&mut pair, &job, 0);
    fail_until_the_job_fails(&mut pair, failed);
    // Running (and priority 2), then three waiting behind it.
    let running = submit(&mut pair, &job, 2);
    let paused = submit(&mut pair, &job, 1);
    let queued = submit(&mut pair, &job, 0);
    let cancelled = submit(&mut pair, &job, 0);
    assert_eq!(
        control(&mut pair, paused, JobAction::Pause),
        Ok(JobState::Paused)
    );
    assert_eq!(
        control(&mut pair, cancelled, JobAction::Cancel),
        Ok(JobState::Cancelled)
    );
    pair.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    let before: Vec<_> = pair.master.jobs().list(true).cloned().collect();
    let states: Vec<JobState> = before.iter().map(|e| e.state).collect();
    use JobState::*;
    assert_eq!(
        states,
        [Completed, Failed, Running, Paused, Queued, Cancelled]
    );

    pair.restart_master();
    let after: Vec<_> = pair.master.jobs().list(true).cloned().collect();
    assert_eq!(after, before);
    // And they go on: the running one, then the queued one, completes; the
    // paused one waits for its resume.
    pair.drive(BOUND, |p| state(p, queued) == Some(Completed));
    assert_eq!(state(&pair, running), Some(Completed));
    assert_eq!(state(&pair, paused), Some(Paused));
    // Never started, it is queued again, and starts at once: nothing else runs.
    assert_eq!(control(&mut pair, paused, JobAction::Resume), Ok(Running));
    pair.drive(BOUND, |p| state(p, paused) == Some(Completed));
    // (The harness's submitter asks from the first frame it lacks of any job.)
    pair.forget_records();
    pair.attach_submitter(paused);
    pair.drive(BOUND, |p| frames_of(p, paused).len() == 2);
    check_images(&pair, paused, &job);
}

#[test]
fn finished_jobs_beyond_retention_are_forgotten_with_their_frames() {
    let job = Job::new(1);
    let rules = FarmRules {
        retention: vtfarm_master_core::Retention {
            max_jobs: 2,
            max_age: Duration::from_secs(3600),
        },
        ..FarmRules::default()
    };
    let mut pair = support::pair::persistent(rules);
    pair.add_worker("w1", 1.0);
    let ids: Vec<JobId> = (0..3)
        .map(|_| {
            let id = submit(&mut pair, &job, 0);
            pair.drive(BOUND, |p| state(p, id) == Some(JobState::Completed));
            id
        })
        .collect();
    // Three finished, two kept: the earliest went.
    let listed: Vec<JobId> = pair.master.jobs().list(true).map(|e| e.id).collect();
    assert_eq!(listed, ids[1..]);
    pair.attach_submitter(ids[0]);
    let errors = pair.job_failed().expect("job 1 is forgotten");
    assert!(
        errors[0].contains(&format!("no job {}", ids[0])),
        "{errors:?}"
    );
    // An hour after they finished, the others go too.
    let expired = pair.now + Duration::from_secs(3601);
    pair.drive(2 * 3600 * BOUND, |p| p.now >= expired);
    assert_eq!(pair.master.jobs().list(true).count(), 0);
}

/// The running jobs, in the order they get workers.
fn running_jobs(pair: &Pair) -> Vec<JobId> {
    (pair.master.status().queue.running.iter())
        .map(|r| r.job)
        .collect()
}

/// The frames of `job` the master started, in order.
fn starts_of(pair: &Pair, job: JobId) -> Vec<u32> {
    (pair.frame_starts.iter())
        .filter(|&&(j, _)| j == job)
        .map(|&(_, frame)| frame)
        .collect()
}

#[test]
fn a_higher_priority_job_takes_the_workers_as_their_packages_finish() {
    let (long, short) = (Job::new(3), Job::new(1));
    let mut pair = without_stragglers(&[("w1", 1.0), ("w2", 2.0)]);
    let low = submit(&mut pair, &long, 0);
    pair.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    let submitted_at = pair.now;
    let high = submit(&mut pair, &short, 5);
    // The high one starts as soon as a worker asks (each asks one package
    // ahead) and gets every worker first; the low one runs beside it on
    // the workers it cannot use.
    pair.drive(BOUND, |p| !starts_of(p, high).is_empty());
    assert_eq!(running_jobs(&pair), vec![high, low]);
    assert!(pair.master.status().queue.waiting.is_empty());
    complete(&mut pair, high, 1);
    assert_eq!(state(&pair, low), Some(JobState::Running), "not done yet");
    let low_done_before = frames_of(&pair, low).len();
    assert!(
        low_done_before < 3,
        "{low_done_before} frames of the low job"
    );
    complete(&mut pair, low, 3);
    assert!(pair.now > submitted_at);
    check_images(&pair, high, &short);
    check_images(&pair, low, &long);
    // Nothing was taken back from a worker for it.
    assert_nothing_taken_back(&pair, low);
}

#[test]
fn a_view_job_overtakes_a_running_batch_job_at_the_next_package_boundary() {
    use vtfarm_master::view::ViewRequest;
    let batch = Job::new(3);
    let mut pair = without_stragglers(&[("w1", 1.0), ("w2", 1.0)]);
    let id = submit(&mut pair, &batch, 0);
    pair.drive(BOUND, |p| !p.master.packages_by_worker().is_empty());
    let request = ViewRequest {
        job: id,
        offset: [0.01, 0.0, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    let view = pair.act(|m, now| m.steer_view(now, request)).unwrap();
    let steered_at = pair.now;
    // The batch job's packages out at the workers finish; the view comes
    // first from the next package on.
    pair.drive(BOUND, |p| !starts_of(p, view).is_empty());
    assert_eq!(running_jobs(&pair).first(), Some(&view));
    pair.drive(BOUND, |p| {
        let current = p.master.views().current().unwrap();
        current.stages_done == current.stages_total
    });
    // Each worker starts at most the batch package it held (it asks one
    // package ahead) before the view's.
    for runs in &pair.busy {
        let after: Vec<JobId> = (runs.iter())
            .filter(|run| run.start > steered_at)
            .map(|run| run.job)
            .collect();
        let first_view = after.iter().position(|&job| job == view);
        assert!(first_view.is_some_and(|i| i <= 1), "{after:?}");
    }
    // Between the view's stages a worker that has no view package to run
    // takes the batch job's (several jobs run at once), so the batch job
    // may be done by now; it is never cancelled or failed for the view.
    assert!(
        matches!(
            state(&pair, id),
            Some(JobState::Running | JobState::Completed)
        ),
        "{:?}",
        state(&pair, id)
    );
    complete(&mut pair, id, 3);
    check_images(&pair, id, &batch);
    assert_nothing_taken_back(&pair, id);
}

#[test]
fn two_jobs_run_at_once_and_a_cancel_of_one_tells_exactly_its_holders() {
    let (single, deep) = (Job::new(1), Job::new(3));
    let mut pair = without_stragglers(&[("a", 1.0), ("b", 3.0), ("c", 5.0)]);
    let first = submit(&mut pair, &single, 0);
    let second = submit(&mut pair, &deep, 0);
    // Near the first job's end its last packages run while the workers it
    // has nothing for take the second job's: both hold packages at once.
    pair.drive(BOUND, |p| {
        !p.master.job_packages_by_worker(first).is_empty()
            && !p.master.job_packages_by_worker(second).is_empty()
    });
    assert_eq!(running_jobs(&pair), vec![first, second]);
    let held = pair.master.job_packages_by_worker(second);
    let expected = by_connection(&pair, &held);
    let now = pair.now;
    (pair.master)
        .control_job(now, second, JobAction::Cancel, WHO)
        .expect("running jobs may be cancelled");
    let mut cancels = BTreeSet::new();
    while let Some(output) = pair.master.poll_output() {
        if let Output::Send(conn, message) = output {
            if let Message::CancelPackage { id } = *message {
                assert!(cancels.insert((conn, id)), "package {id} cancelled twice");
            }
        }
    }
    assert_eq!(cancels, expected);
    assert!(!pair.master.job_packages_by_worker(first).is_empty());
    complete(&mut pair, first, 1);
    check_images(&pair, first, &single);
    assert_eq!(state(&pair, second), Some(JobState::Cancelled));
}

/// One worker, a low job's one split frame under way and a high job taking
/// the worker at its next package boundary: when the worker comes back to
/// the low frame it still keeps it (no `FrameStart` again) unless more
/// frames than it keeps came between (then the start comes once more).
/// Either way nothing is taken back and both jobs' images are right.
#[test]
fn a_worker_gets_a_frames_start_again_only_when_it_let_the_frame_go() {
    let kept = vtfarm_proto::FRAMES_IN_FLIGHT;
    for (high_frames, low_starts) in [(1, 1), (kept + 2, 2)] {
        let (low_job, high_job) = (Job::new(1), Job::new(high_frames));
        let mut pair = without_stragglers(&[("w", 1.0)]);
        let low = submit(&mut pair, &low_job, 0);
        pair.drive(BOUND, |p| !p.master.job_packages_by_worker(low).is_empty());
        let high = submit(&mut pair, &high_job, 5);
        complete(&mut pair, high, high_frames);
        complete(&mut pair, low, 1);
        // The jobs did interleave: low, then high, then low again. (While
        // the high job's unmeasured whole frames are at their limit, two
        // per worker, the worker may turn to the low job in between too.)
        let mut jobs: Vec<JobId> = pair.busy[0].iter().map(|run| run.job).collect();
        jobs.dedup();
        let interleaved = jobs.starts_with(&[low, high]) && jobs.last() == Some(&low);
        assert!(interleaved, "{high_frames} high frames: {jobs:?}");
        let got = &pair.workers[0].frame_starts_got;
        let low_got = got.iter().filter(|&&(job, _)| job == low).count();
        assert_eq!(low_got, low_starts, "{high_frames} high frames: {got:?}");
        // Each of the high job's split frames is announced once (its
        // whole frames' starts come with their packages).
        let high_got: Vec<_> = got.iter().filter(|&&(job, _)| job == high).collect();
        let once: BTreeSet<_> = high_got.iter().collect();
        assert_eq!(once.len(), high_got.len(), "{got:?}");
        check_images(&pair, low, &low_job);
        check_images(&pair, high, &high_job);
        assert_nothing_taken_back(&pair, low);
        assert_nothing_taken_back(&pair, high);
    }
}
