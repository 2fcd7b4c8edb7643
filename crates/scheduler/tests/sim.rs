//! Scenarios on the simulated farm: balance, scaling, faults. Every scenario
//! checks that each item of each completed frame was accepted exactly once
//! and that the scheduler's invariants held after every step.

mod common;

use std::time::Duration;

use common::sim::{
    SimConfig, SimCrash, SimFailures, SimJob, SimReport, SimSlowdown, SimWorker, Simulation,
};
use common::*;
use vtfarm_scheduler::{Event, JobFailure, JobId, LossCause, WorkerId};

fn checked() -> SimConfig {
    SimConfig {
        validate: true,
        ..SimConfig::default()
    }
}

/// Runs `jobs` on `workers` to the end and checks exactly-once completion.
fn run(config: SimConfig, workers: Vec<SimWorker>, jobs: &[SimJob]) -> SimReport {
    let mut sim = Simulation::new(config, workers);
    for job in jobs {
        sim.submit(job.clone());
    }
    sim.drive();
    let report = sim.into_report();
    assert!(report.finished, "simulation stalled at {:?}", report.end);
    assert_exactly_once(&report, jobs);
    report
}

fn print_frames(label: &str, report: &SimReport) {
    for f in &report.frames {
        println!(
            "{label} {} frame {}: wall {:>9.3?} speed-up {:>5.2} imbalance {:>5.1}% packages {:>3} duplicates {}",
            f.job,
            f.frame,
            f.stats.wall,
            f.stats.speedup(),
            100.0 * f.stats.imbalance(),
            f.stats.packages,
            f.stats.duplicates
        );
    }
}

#[test]
fn scaling_from_1_to_64_workers() {
    // 600 items of 10 to 30 ms with a 3× hot spot: 13 s on one worker.
    let frame = uneven_frame(600, 7, 0.01, 200..260, 3.0);
    let job = repeated_job(1, &frame, 3);
    let mut last_speedup = 0.0;
    for workers in [1, 2, 4, 8, 16, 32, 64] {
        let report = run(
            checked(),
            vec![SimWorker::with_speed(1.0); workers],
            std::slice::from_ref(&job),
        );
        let warm = &report.frames[2].stats;
        println!(
            "{workers:>2} workers (100 Mbit/s): speed-up {:>5.2}, imbalance {:>4.1}% (frame 3); frame 1: {:>5.2}, {:>4.1}%",
            warm.speedup(),
            100.0 * warm.imbalance(),
            report.frames[0].stats.speedup(),
            100.0 * report.frames[0].stats.imbalance(),
        );
        assert!(warm.speedup() > last_speedup, "speed-up grows with workers");
        last_speedup = warm.speedup();
        if workers == 16 {
            assert!(warm.imbalance() < 0.05, "imbalance {}", warm.imbalance());
            assert!(warm.speedup() > 14.0, "speed-up {}", warm.speedup());
        }
    }
}

#[test]
fn heterogeneous_workers_share_the_work_by_speed() {
    let frame = uneven_frame(600, 11, 0.01, 0..0, 1.0);
    let job = repeated_job(1, &frame, 3);
    let speeds = [1.0, 1.0, 3.0];
    let workers = speeds.iter().map(|&s| SimWorker::with_speed(s)).collect();
    let report = run(checked(), workers, std::slice::from_ref(&job));
    print_frames("speeds 1,1,3", &report);
    let last = &report.frames[2];
    let shares = shares(last);
    for (i, speed) in speeds.iter().enumerate() {
        let expected = speed / speeds.iter().sum::<f64>();
        let share = shares[&WorkerId(i as u64)];
        assert!(
            (share - expected).abs() <= 0.1 * expected,
            "worker {i}: share {share:.3}, expected {expected:.3}"
        );
    }
    assert!(last.stats.imbalance() < 0.1, "{}", last.stats.imbalance());
}

#[test]
fn cost_estimates_carry_over_between_frames() {
    // The last 60 items cost 20 times more: the first frame, estimating every
    // item alike, hands them out late in small packages that run long; later
    // frames know them.
    let frame = uneven_frame(600, 3, 0.01, 270..330, 20.0);
    let job = repeated_job(1, &frame, 3);
    let config = SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig {
            straggler: None,
            ..Default::default()
        },
        ..checked()
    };
    let report = run(
        config,
        vec![SimWorker::with_speed(1.0); 8],
        std::slice::from_ref(&job),
    );
    print_frames("hot spot", &report);
    let first = &report.frames[0].stats;
    let third = &report.frames[2].stats;
    assert!(
        third.imbalance() < first.imbalance() / 2.0,
        "imbalance {} → {}",
        first.imbalance(),
        third.imbalance()
    );
    assert!(third.wall < first.wall);
    assert!(third.imbalance() < 0.05, "{}", third.imbalance());
}

/// A 600-item frame of 10 to 30 ms items: 12 s on one worker.
/// A frame of 600 items of uneven cost. Its seed's draw leaves the slowed
/// worker of `a_straggler_is_duplicated_and_the_late_result_ignored` well
/// inside a package at the slowdown (a draw where it is near the package's
/// end leaves little for a straggler copy to save).
fn plain_frame() -> common::sim::SimFrame {
    uneven_frame(600, 1, 0.01, 0..0, 1.0)
}

fn lost_events(report: &SimReport) -> Vec<(Duration, WorkerId, LossCause, usize)> {
    report
        .events
        .iter()
        .filter_map(|(at, e)| match e {
            Event::WorkerLost {
                worker,
                cause,
                requeued,
            } => Some((*at, *worker, *cause, requeued.len())),
            _ => None,
        })
        .collect()
}

#[test]
fn a_crash_mid_frame_requeues_the_packages() {
    let job = repeated_job(1, &plain_frame(), 2);
    let mut workers = vec![SimWorker::with_speed(1.0); 4];
    workers[1].crash = Some(SimCrash {
        at: Duration::from_millis(1500),
        noticed: true,
    });
    let report = run(checked(), workers, std::slice::from_ref(&job));
    assert_eq!(report.frames.len(), 2);
    let lost = lost_events(&report);
    assert_eq!(lost.len(), 1);
    let (at, worker, cause, requeued) = lost[0];
    assert_eq!((worker, cause), (WorkerId(1), LossCause::Left));
    assert!(requeued >= 1 && at < Duration::from_millis(1510));
    assert!(report.frames[0].stats.requeued >= 1);
    // Worker 1 contributed nothing accepted after its crash.
    assert!(!report.frames[1].true_cost.contains_key(&WorkerId(1)));
}

#[test]
fn a_silent_crash_is_found_by_the_heartbeat_timeout() {
    let job = repeated_job(1, &plain_frame(), 2);
    let mut workers = vec![SimWorker::with_speed(1.0); 4];
    workers[2].crash = Some(SimCrash {
        at: Duration::from_millis(1500),
        noticed: false,
    });
    // Without straggler cuts only the timeout brings the package back.
    let config = SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig {
            straggler: None,
            ..Default::default()
        },
        ..checked()
    };
    let report = run(config, workers, std::slice::from_ref(&job));
    let lost = lost_events(&report);
    assert_eq!(lost.len(), 1);
    let (at, worker, cause, requeued) = lost[0];
    assert_eq!(
        (worker, cause, requeued),
        (WorkerId(2), LossCause::HeartbeatTimeout, 1)
    );
    // 10 s after the last message, sent before the crash at 1.5 s.
    assert!(
        at > Duration::from_secs(11) && at < Duration::from_millis(11_501),
        "{at:?}"
    );
    assert!(report.frames[0].at > at, "the frame waited for the package");
    assert_eq!(report.frames.len(), 2);
}

#[test]
fn a_straggler_is_duplicated_and_the_late_result_ignored() {
    let job = repeated_job(1, &plain_frame(), 1);
    let slow = SimWorker {
        slowdown: Some(SimSlowdown {
            at: Duration::from_millis(1500),
            factor: 20.0,
        }),
        honours_cancel: false,
        ..SimWorker::with_speed(1.0)
    };
    let workers = vec![
        slow,
        SimWorker::with_speed(1.0),
        SimWorker::with_speed(1.0),
        SimWorker::with_speed(1.0),
    ];
    let report = run(checked(), workers.clone(), std::slice::from_ref(&job));
    let stats = &report.frames[0].stats;
    assert!(stats.duplicates >= 1 && stats.cancelled_copies >= 1);
    let cancelled_on_slow = report.events.iter().any(
        |(_, e)| matches!(e, Event::PackageCancelled { worker, .. } if *worker == WorkerId(0)),
    );
    assert!(cancelled_on_slow);
    // Worker 0 ignored the cancel; its result arrived after the frame and was refused.
    assert!(
        report.counters.results_finished >= 1,
        "{:?}",
        report.counters
    );
    assert!(
        report
            .refusals
            .iter()
            .any(|(at, _)| *at > report.frames[0].at)
    );

    let without = SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig {
            straggler: None,
            ..Default::default()
        },
        ..checked()
    };
    let waited = run(without, workers, std::slice::from_ref(&job));
    println!(
        "20× slowdown at 1.5 s: frame wall {:?} with straggler cut, {:?} without",
        stats.wall, waited.frames[0].stats.wall
    );
    assert!(stats.wall * 2 < waited.frames[0].stats.wall);
}

fn count<F: Fn(&Event) -> bool>(report: &SimReport, f: F) -> usize {
    report.events.iter().filter(|(_, e)| f(e)).count()
}

#[test]
fn failed_packages_are_retried_on_other_workers() {
    let job = repeated_job(1, &plain_frame(), 1);
    let mut workers = vec![SimWorker::with_speed(1.0); 3];
    workers[2].failures = SimFailures::FirstPackages(2);
    let report = run(checked(), workers, std::slice::from_ref(&job));
    assert_eq!(report.frames[0].stats.failures, 2);
    assert_eq!(
        count(&report, |e| matches!(e, Event::WorkerBlocklisted { .. })),
        0
    );
    assert_eq!(
        count(&report, |e| matches!(e, Event::JobComplete { .. })),
        1
    );
}

#[test]
fn three_failures_blocklist_a_worker_for_the_job() {
    let job = repeated_job(1, &plain_frame(), 2);
    let mut workers = vec![SimWorker::with_speed(1.0); 3];
    workers[1].failures = SimFailures::Always;
    let report = run(checked(), workers, std::slice::from_ref(&job));
    let blocklisted: Vec<&Event> = common::events(&report)
        .into_iter()
        .filter(|e| matches!(e, Event::WorkerBlocklisted { .. }))
        .collect();
    assert_eq!(
        blocklisted,
        [&Event::WorkerBlocklisted {
            worker: WorkerId(1),
            job: JobId(1)
        }]
    );
    let status = report_worker_failures(&report);
    assert_eq!(status, 3, "no work after the blocklist");
    assert_eq!(
        count(&report, |e| matches!(e, Event::JobComplete { .. })),
        1
    );
    assert!(!report.frames[1].true_cost.contains_key(&WorkerId(1)));
}

/// Failed attempts over the whole report.
fn report_worker_failures(report: &SimReport) -> u32 {
    report.frames.iter().map(|f| f.stats.failures).sum()
}

#[test]
fn a_package_failing_on_three_workers_fails_the_job_and_the_next_job_runs() {
    let bad = plain_frame();
    let bad_item = bad.items[300];
    let mut good = plain_frame();
    good.items.iter_mut().for_each(|i| *i += 10_000);
    let jobs = [repeated_job(1, &bad, 1), repeated_job(2, &good, 1)];
    let mut workers = vec![SimWorker::with_speed(1.0); 4];
    for w in &mut workers {
        w.failures = SimFailures::Items(vec![bad_item]);
    }
    let report = run(checked(), workers, &jobs);
    let failed: Vec<&Event> = common::events(&report)
        .into_iter()
        .filter(|e| matches!(e, Event::JobFailed { .. }))
        .collect();
    assert_eq!(failed.len(), 1);
    let Event::JobFailed {
        job,
        reason,
        errors,
    } = failed[0]
    else {
        unreachable!()
    };
    assert_eq!(*job, JobId(1));
    assert!(matches!(reason, JobFailure::PackageFailed(_)));
    let mut workers: Vec<WorkerId> = errors.iter().map(|(w, _)| *w).collect();
    workers.sort();
    workers.dedup();
    assert_eq!((errors.len(), workers.len()), (3, 3), "{errors:?}");
    assert!(errors.iter().all(|(w, e)| e.contains(&w.to_string())));
    // Job 1 never completed its frame; job 2 ran after it.
    assert_eq!(report.frames.len(), 1);
    assert_eq!(report.frames[0].job, JobId(2));
    assert_eq!(
        count(
            &report,
            |e| matches!(e, Event::JobComplete { job } if *job == JobId(2))
        ),
        1
    );
}

#[test]
fn a_job_fails_when_every_worker_is_blocklisted() {
    let job = repeated_job(1, &plain_frame(), 1);
    let mut workers = vec![SimWorker::with_speed(1.0); 2];
    for w in &mut workers {
        w.failures = SimFailures::Always;
    }
    let report = run(checked(), workers, std::slice::from_ref(&job));
    assert_eq!(
        count(&report, |e| matches!(e, Event::WorkerBlocklisted { .. })),
        2
    );
    let failure = report.events.iter().find_map(|(_, e)| match e {
        Event::JobFailed { reason, errors, .. } => Some((*reason, errors.len())),
        _ => None,
    });
    assert_eq!(failure, Some((JobFailure::NoEligibleWorker, 6)));
}

#[test]
fn jobs_run_by_rank_and_the_first_job_starts_when_none_runs() {
    // Job 3 comes first and starts (nothing runs); job 1, submitted at
    // once, outranks it (equal priority, lower id) and takes every worker
    // from its first package on; job 2 comes later, starts on a worker job
    // 1 has nothing for (its last packages run), and still outranks 3.
    let frame = uneven_frame(100, 9, 0.01, 0..0, 1.0);
    let mut jobs: Vec<SimJob> = [3, 1, 2]
        .iter()
        .map(|&id| repeated_job(id, &frame, 2))
        .collect();
    jobs[2].submit_at = Duration::from_millis(100);
    let report = run(checked(), vec![SimWorker::with_speed(1.0); 3], &jobs);
    let order: Vec<String> = common::events(&report)
        .into_iter()
        .filter_map(|e| match e {
            Event::JobStarted { job, .. } => Some(format!("start {}", job.0)),
            Event::FrameComplete { job, frame, .. } => Some(format!("frame {}.{frame}", job.0)),
            Event::JobComplete { job } => Some(format!("end {}", job.0)),
            _ => None,
        })
        .collect();
    assert_eq!(
        order,
        [
            "start 3",
            "start 1",
            "start 2",
            "frame 1.0",
            "frame 1.1",
            "end 1",
            "frame 2.0",
            "frame 2.1",
            "end 2",
            "frame 3.0",
            "frame 3.1",
            "end 3"
        ]
    );
}

#[test]
fn a_frame_completes_while_one_worker_remains() {
    let job = repeated_job(1, &plain_frame(), 2);
    let mut workers = vec![SimWorker::with_speed(1.0); 4];
    for (i, w) in workers.iter_mut().enumerate().skip(1) {
        w.crash = Some(SimCrash {
            at: Duration::from_millis(500 * i as u64),
            noticed: i % 2 == 1,
        });
    }
    let report = run(checked(), workers, std::slice::from_ref(&job));
    assert_eq!(report.frames.len(), 2);
    assert_eq!(lost_events(&report).len(), 3);
    assert_eq!(
        report.frames[1]
            .true_cost
            .keys()
            .copied()
            .collect::<Vec<_>>(),
        [WorkerId(0)]
    );
}

#[test]
fn a_late_joiner_gets_work_mid_frame() {
    let job = repeated_job(1, &plain_frame(), 1);
    let mut workers = vec![SimWorker::with_speed(1.0); 2];
    workers[1].join_at = Duration::from_secs(2);
    let report = run(checked(), workers, std::slice::from_ref(&job));
    let share = shares(&report.frames[0])[&WorkerId(1)];
    // It joined at 2 s of about 7 s, so it did about 5/12 of the work.
    assert!(share > 0.3 && share < 0.5, "{share}");
}

#[test]
fn a_slow_link_gets_smaller_shares() {
    // The paper's mix of 10 and 100 Mbit links with large results.
    let job = repeated_job(1, &plain_frame(), 3);
    let mut workers = vec![SimWorker::with_speed(1.0); 4];
    workers[3].link_bits_per_second = 1e6;
    let config = SimConfig {
        result_bytes_per_item: 8192,
        ..checked()
    };
    let report = run(config, workers, std::slice::from_ref(&job));
    print_frames("1 Mbit/s link", &report);
    let shares = shares(&report.frames[2]);
    assert!(
        shares[&WorkerId(3)] < 0.5 * shares[&WorkerId(0)],
        "{shares:?}"
    );
}

/// The master's rules (pipelined frames with frame affinity) with one
/// shared master link: the results of a frame queue for
/// that link, so a slow master link bounds the frame time from below, and
/// the simulation is deterministic.
#[test]
fn a_shared_master_link_bounds_the_frame_and_runs_repeat_exactly() {
    let frame = uneven_frame(400, 3, 0.005, 100..140, 2.0);
    let job = repeated_job(1, &frame, 3);
    let worker = SimWorker {
        frame_setup: Duration::from_millis(50),
        link_bits_per_second: 1e9,
        ..SimWorker::with_speed(1.0)
    };
    let config = |master_link: Option<f64>| SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT),
        master_link_bits_per_second: master_link,
        master_frame_cost: Duration::from_millis(30),
        result_bytes_per_item: 20_000,
        ..checked()
    };
    let fast = run(
        config(None),
        vec![worker.clone(); 8],
        std::slice::from_ref(&job),
    );
    let slow = run(
        config(Some(10e6)),
        vec![worker.clone(); 8],
        std::slice::from_ref(&job),
    );
    // 400 items × 20 kB through 10 Mbit/s: 6.4 s of results per frame.
    let link_bound = 400.0 * 20_000.0 * 8.0 / 10e6;
    for f in &slow.frames {
        assert!(
            f.stats.wall.as_secs_f64() >= link_bound,
            "{:?}",
            f.stats.wall
        );
        assert!(f.done_at >= f.at);
    }
    // With a fast link the whole job takes less than a quarter of what
    // the slow link needs per frame (frames overlap, so a frame's own wall
    // time says little).
    let fast_end = fast.frames.last().expect("frames").done_at;
    assert!(
        fast_end.as_secs_f64() < link_bound / 4.0 * fast.frames.len() as f64,
        "{fast_end:?}"
    );
    // Every worker asked for work of every frame at least once.
    let requests = |r: &SimReport| {
        (r.inputs.iter())
            .filter(|(_, i)| matches!(i, common::sim::SimInput::Request(_)))
            .count()
    };
    assert!(requests(&fast) >= 8 * 3, "{}", requests(&fast));
    let again = run(
        config(Some(10e6)),
        vec![worker; 8],
        std::slice::from_ref(&job),
    );
    assert_eq!(again.inputs, slow.inputs, "deterministic");
    assert_eq!(again.assignments, slow.assignments);
}

/// With the master's rules frames overlap: frame N+1's first packages go
/// out before frame N completes, results held for a slow base image are
/// never duplicated as stragglers, and every item completes once.
#[test]
fn pipelined_frames_overlap_and_held_results_are_not_duplicated() {
    let frame = uneven_frame(300, 5, 0.002, 100..120, 3.0);
    let job = repeated_job(1, &frame, 4);
    let worker = SimWorker {
        frame_setup: Duration::from_millis(40),
        ..SimWorker::with_speed(1.0)
    };
    let config = SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT),
        // Longer than a frame's tracing: every result waits for it.
        master_frame_cost: Duration::from_secs(2),
        master_result_cost_per_item: Duration::from_micros(20),
        ..checked()
    };
    let report = run(config, vec![worker; 4], std::slice::from_ref(&job));
    assert_eq!(report.frames.len(), 4);
    for f in &report.frames {
        assert_eq!(f.stats.duplicates, 0, "frame {}", f.frame);
        assert!(f.completions.values().all(|&c| c == 1));
    }
    let held = (report.inputs.iter())
        .filter(|(_, i)| matches!(i, common::sim::SimInput::Arrived(..)))
        .count();
    assert!(held > 0, "results waited for the base image");
    for pair in report.frames.windows(2) {
        let first_of_next = (report.assignments.iter())
            .find(|(_, a)| a.frame == pair[1].frame)
            .map(|(at, _)| *at)
            .expect("the next frame has packages");
        assert!(
            first_of_next < pair[0].at,
            "frame {} started at {first_of_next:?}, frame {} completed at {:?}",
            pair[1].frame,
            pair[0].frame,
            pair[0].at
        );
    }
}

/// Frame affinity (the master's rules): each frame's fresh work goes to a
/// crew, so a worker gets packages of far fewer frames than a farm without
/// it, where every worker works on every frame (and sets every one up);
/// every item still completes exactly once and the farm stays as fast.
#[test]
fn frame_affinity_keeps_workers_on_fewer_frames_and_as_fast() {
    let frame = uneven_frame(600, 7, 0.01, 200..240, 3.0);
    let job = repeated_job(1, &frame, 12);
    let worker = SimWorker::with_speed(1.0);
    let config = |frame_affinity: bool| SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig {
            frame_affinity,
            ..vtfarm_scheduler::SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT)
        },
        ..checked()
    };
    let frames_per_worker = |report: &SimReport| {
        let mut seen = std::collections::BTreeSet::new();
        for (_, a) in &report.assignments {
            seen.insert((a.worker, a.frame));
        }
        seen.len() as f64 / 12.0
    };
    let with = run(
        config(true),
        vec![worker.clone(); 12],
        std::slice::from_ref(&job),
    );
    let without = run(config(false), vec![worker; 12], std::slice::from_ref(&job));
    for report in [&with, &without] {
        assert_eq!(report.frames.len(), 12);
        for f in &report.frames {
            assert!(f.completions.values().all(|&c| c == 1), "frame {}", f.frame);
            assert_eq!(f.completions.len(), 600);
        }
    }
    let (a, b) = (frames_per_worker(&with), frames_per_worker(&without));
    // 12 workers over 3 crews of 4: about a third of the frames each.
    assert!(
        a < 0.5 * b,
        "with affinity {a} frames per worker, without {b}"
    );
    let end = |r: &SimReport| r.frames.last().expect("frames").done_at.as_secs_f64();
    assert!(
        end(&with) < 1.05 * end(&without),
        "{} s vs {} s",
        end(&with),
        end(&without)
    );
}

/// The master's rules with a frame set-up that costs as much as a quarter
/// of a frame's tracing on one worker, as vtfarm's does, and a
/// master that makes the base frames of a batch job's last frames ahead, as
/// the master core does.
fn batch_config() -> SimConfig {
    SimConfig {
        scheduler: vtfarm_scheduler::SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT),
        master_frame_cost: Duration::from_millis(20),
        bases_ahead: common::FRAMES_IN_FLIGHT as usize,
        ..checked()
    }
}

/// The workers that got packages of each frame (a worker sets a frame up
/// once for all its packages of it), by frame.
fn crews(
    report: &SimReport,
) -> std::collections::BTreeMap<u32, std::collections::BTreeSet<WorkerId>> {
    let mut crews = std::collections::BTreeMap::<u32, std::collections::BTreeSet<WorkerId>>::new();
    for (_, a) in &report.assignments {
        crews.entry(a.frame).or_default().insert(a.worker);
    }
    crews
}

/// Which frames started whole, by frame.
fn whole_frames(report: &SimReport) -> Vec<bool> {
    (report.events.iter())
        .filter_map(|(_, e)| match e {
            Event::FrameStarted { whole, .. } => Some(*whole),
            _ => None,
        })
        .collect()
}

/// A deep batch job: while more frames are left to start than there are
/// workers, each frame goes to one worker whole, so each is set up once
/// (one worker per frame); the last frames, no more than the workers, are
/// split and spread over several; the farm stays busy throughout. The
/// master's base frame (20 ms) is cheap against a whole frame (about 1 s),
/// so the tail is as wide as the farm: all of the last 8 frames split, and
/// (but for a frame whose items went out before the other workers were
/// free) each on several workers.
#[test]
fn a_deep_batch_job_sets_each_frame_up_once_and_its_tail_spreads() {
    let frame = uneven_frame(200, 11, 0.002, 50..80, 3.0);
    let mut job = repeated_job(1, &frame, 40);
    job.submit_at = Duration::from_millis(1); // after the workers joined
    let report = run(
        batch_config(),
        vec![SimWorker::with_speed(1.0); 8],
        std::slice::from_ref(&job),
    );
    assert_eq!(report.frames.len(), 40);
    // Frame i starts with 40 − i frames not started: whole while that is
    // more than the 8 workers.
    let expected: Vec<bool> = (0..40).map(|i| 40 - i > 8).collect();
    assert_eq!(whole_frames(&report), expected);
    let crews = crews(&report);
    let set_ups: usize = crews.values().map(|c| c.len()).sum();
    for (frame, crew) in &crews {
        if *frame < 32 {
            assert_eq!(crew.len(), 1, "whole frame {frame}: {crew:?}");
        }
    }
    let tail_spread = (32..40).filter(|f| crews[f].len() > 1).count();
    assert!(
        tail_spread >= 6,
        "tail frames on several workers: {tail_spread} of 8"
    );
    // 32 whole frames set up once each; the tail pays more, but far less
    // than every worker on every frame (8 · 40).
    assert!(set_ups < 32 + 8 * 8, "{set_ups} set-ups");
    let work: f64 = frame.costs.iter().sum::<f64>() * 40.0;
    let end = report.frames.last().expect("frames").done_at.as_secs_f64();
    let efficiency = work / 8.0 / end;
    println!("{set_ups} set-ups, efficiency {:.1}%", 100.0 * efficiency);
    assert!(efficiency > 0.85, "efficiency {efficiency}");
}

/// A single-frame job (and a job no longer than the farm is wide) is split:
/// every worker takes part in its frame.
#[test]
fn a_single_frame_job_spreads_over_every_worker() {
    let frame = uneven_frame(400, 12, 0.002, 0..0, 1.0);
    let mut job = repeated_job(1, &frame, 1);
    job.submit_at = Duration::from_millis(1);
    let report = run(
        batch_config(),
        vec![SimWorker::with_speed(1.0); 8],
        std::slice::from_ref(&job),
    );
    assert_eq!(whole_frames(&report), [false]);
    let crews = crews(&report);
    assert_eq!(crews[&0].len(), 8, "{:?}", crews[&0]);
}

/// A worker ten times slower than the others gets whole frames too (its
/// speed is not known in advance), but at the job's end the others take
/// copies of its last whole frames rather than wait: the job ends no later
/// than it would without the slow worker.
#[test]
fn a_slow_workers_last_frame_is_finished_by_the_others() {
    let frame = uneven_frame(200, 13, 0.002, 0..0, 1.0);
    let mut job = repeated_job(1, &frame, 30);
    job.submit_at = Duration::from_millis(1);
    let fast = SimWorker::with_speed(1.0);
    let slow = SimWorker::with_speed(0.1);
    let with_slow = run(
        batch_config(),
        vec![fast.clone(), fast.clone(), fast.clone(), slow],
        std::slice::from_ref(&job),
    );
    let without = run(batch_config(), vec![fast; 3], std::slice::from_ref(&job));
    let end = |r: &SimReport| r.frames.last().expect("frames").done_at.as_secs_f64();
    let duplicates: u32 = with_slow.frames.iter().map(|f| f.stats.duplicates).sum();
    println!(
        "with the slow worker {:.3} s ({duplicates} duplicates), without {:.3} s",
        end(&with_slow),
        end(&without)
    );
    assert!(duplicates >= 1, "no copy of the slow worker's frame");
    // Its last whole frame was finished by another worker.
    let slow_id = WorkerId(3);
    let last = (with_slow.assignments.iter())
        .filter(|(_, a)| a.worker == slow_id && a.whole)
        .map(|(_, a)| a.frame)
        .max()
        .expect("the slow worker got a whole frame");
    let finished = (with_slow.frames.iter())
        .find(|f| f.frame == last)
        .expect("complete");
    assert!(
        finished.stats.workers.iter().all(|w| w.worker != slow_id),
        "frame {last}: {:?}",
        finished.stats.workers
    );
    assert!(
        end(&with_slow) <= end(&without) * 1.02,
        "{} s with the slow worker, {} s without",
        end(&with_slow),
        end(&without)
    );
}

/// A single frame of two big items on four workers, beside a deep job:
/// the two workers the frame cannot use take the deep job's work at once,
/// so no worker idles while work exists and the farm ends when the work
/// over four workers does.
#[test]
fn a_small_job_beside_a_deep_one_leaves_no_worker_idle() {
    let big = common::sim::SimFrame {
        items: vec![1, 2],
        costs: vec![1.0, 1.0],
    };
    let small = SimJob {
        id: JobId(1),
        submit_at: Duration::from_millis(1),
        frames: vec![big],
    };
    let frame = uneven_frame(100, 14, 0.005, 0..0, 1.0);
    let mut deep = repeated_job(2, &frame, 12);
    deep.submit_at = Duration::from_millis(1);
    let jobs = [small, deep];
    for config in [checked(), batch_config()] {
        let report = run(config, vec![SimWorker::with_speed(1.0); 4], &jobs);
        let small_done = (report.frames.iter())
            .find(|f| f.job == JobId(1))
            .expect("complete")
            .at;
        let deep_first = (report.assignments.iter())
            .find(|(_, a)| a.job == JobId(2))
            .expect("assigned")
            .0;
        assert!(
            deep_first < Duration::from_millis(100),
            "the deep job waited until {deep_first:?}"
        );
        assert!(small_done < Duration::from_millis(1200), "{small_done:?}");
        let work = 2.0 + frame.costs.iter().sum::<f64>() * 12.0;
        let end = report.end.as_secs_f64();
        println!("end {end:.3} s, ideal {:.3} s", work / 4.0);
        assert!(end < work / 4.0 * 1.1, "{end} s for {work} s of work on 4");
    }
}

/// The tail splits no more frames than the master's measured costs allow:
/// a whole frame takes about 0.8 s on a worker and the master 0.32 s per
/// base frame, so beside the 2 base frames it made ahead it makes 2 more
/// within a whole frame's time — the last 4 frames split, the others whole
/// (each set up once), however many workers there are. A split frame so
/// never waits for its base frame longer than it would take whole.
#[test]
fn a_deep_batch_jobs_tail_splits_no_more_frames_than_the_measured_costs_allow() {
    let frame = uneven_frame(200, 15, 0.002, 0..0, 1.0);
    let work: f64 = frame.costs.iter().sum();
    let mut job = repeated_job(1, &frame, 40);
    job.submit_at = Duration::from_millis(1);
    let config = SimConfig {
        master_frame_cost: Duration::from_secs_f64(work / 2.5),
        bases_ahead: 2,
        ..batch_config()
    };
    let report = run(
        config,
        vec![SimWorker::with_speed(1.0); 8],
        std::slice::from_ref(&job),
    );
    assert_eq!(report.frames.len(), 40);
    let expected: Vec<bool> = (0..40).map(|i| i < 36).collect();
    assert_eq!(whole_frames(&report), expected);
    let crews = crews(&report);
    for frame in 0..36 {
        assert_eq!(
            crews[&frame].len(),
            1,
            "whole frame {frame}: {:?}",
            crews[&frame]
        );
    }
    let spread = (36..40).filter(|f| crews[f].len() > 1).count();
    assert!(spread >= 3, "tail frames on several workers: {spread} of 4");
    // Every base frame the master made was measured and reported.
    let reported = (report.inputs.iter())
        .filter(|(_, i)| matches!(i, common::sim::SimInput::BaseFrameCost(..)))
        .count();
    assert_eq!(reported, 4, "2 ahead and 2 at their frames' start");
}

/// Until the costs are measured (no base frame made yet) the tail is no
/// wider than the frames in flight, and a job's last frame is always split:
/// a job of 12 frames on 16 workers, where every frame is at the tail,
/// splits them all; on 2 workers the last 2 split.
#[test]
fn unmeasured_tails_split_up_to_the_frames_in_flight_and_the_last_frame_always() {
    let frame = uneven_frame(100, 16, 0.002, 0..0, 1.0);
    let mut job = repeated_job(1, &frame, 12);
    job.submit_at = Duration::from_millis(1);
    let config = SimConfig {
        bases_ahead: 0,
        master_frame_cost: Duration::ZERO,
        ..batch_config()
    };
    for (workers, split) in [(16, common::FRAMES_IN_FLIGHT as usize), (2, 2), (1, 1)] {
        let report = run(
            config.clone(),
            vec![SimWorker::with_speed(1.0); workers],
            std::slice::from_ref(&job),
        );
        let expected: Vec<bool> = (0..12).map(|i| 12 - i > split).collect();
        assert_eq!(whole_frames(&report), expected, "{workers} workers");
    }
}
