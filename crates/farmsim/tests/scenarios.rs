//! Farm scenarios on the real master core and worker sessions: balance,
//! scaling, pipelining, whole frames and faults, on items of known true
//! cost (see `support`). Every scenario checks that each delivered frame
//! traced each of its items exactly once.

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;
use vtfarm_proto::JobId;

use support::*;
use vtfarm_farmsim::WorkerSpec;
use vtfarm_master_core::FarmRules;

/// Runs one job of `frames` copies of `items` on `workers` under `rules`
/// to its end; checks that every frame came, each item traced once.
fn run_job(
    rules: FarmRules,
    model: ItemCosts,
    workers: &[WorkerSpec],
    items: &Items,
    frames: usize,
) -> (ItemFarm, Vec<Delivered>) {
    let mut farm = farm(rules, model);
    join_all(&mut farm, workers);
    submit(&mut farm, items, frames);
    run_to_end(&mut farm, &[frames]);
    let delivered = delivered(&farm);
    assert_eq!(delivered.len(), frames);
    assert_each_item_once(&delivered, items.items.len());
    (farm, delivered)
}

/// A frame of 600 items of 10 to 30 ms: 12 s on one worker.
fn plain_items() -> Items {
    uneven_items(600, 0, 1, 0.01, 0..0, 1.0)
}

/// When the last frame went out, in seconds.
fn end(frames: &[Delivered]) -> f64 {
    frames.last().expect("frames").done_at.as_secs_f64()
}

/// The workers (by index) whose results a frame took.
fn workers_of(frame: &Delivered) -> Vec<usize> {
    (frame.stats.workers.iter())
        .filter(|w| w.triangles > 0)
        .map(|w| worker_index(&w.name))
        .collect()
}

// ----- Balance and scaling -----

/// The farm's speed-up over a 12-frame job (its work over the time to its
/// last frame) grows with every doubling from 1 to 64 workers, and 16
/// workers make it more than 14 times as fast as one.
#[test]
fn the_farms_speed_up_grows_from_1_to_64_workers() {
    // 600 items of 10 to 30 ms with a 3× hot spot: 13 s on one worker.
    let items = uneven_items(600, 0, 7, 0.01, 200..260, 3.0);
    let mut last = 0.0;
    for n in [1, 2, 4, 8, 16, 32, 64] {
        let (_, frames) = run_job(
            split_rules(),
            ItemCosts::default(),
            &vec![worker(1.0); n],
            &items,
            12,
        );
        let speedup = 12.0 * items.work() / end(&frames);
        println!("{n:>2} workers: speed-up {speedup:.2}");
        assert!(speedup > last, "{n} workers: {speedup} after {last}");
        last = speedup;
        if n == 16 {
            assert!(speedup > 14.0, "speed-up {speedup}");
        }
    }
}

#[test]
fn heterogeneous_workers_share_the_work_by_speed() {
    let items = uneven_items(600, 0, 11, 0.01, 0..0, 1.0);
    let speeds = [1.0, 1.0, 3.0];
    let specs: Vec<WorkerSpec> = speeds.iter().map(|&s| worker(s)).collect();
    let (farm, frames) = run_job(split_rules(), ItemCosts::default(), &specs, &items, 3);
    let job = frames[2].job;
    let shares = cost_shares(&farm, job, 2);
    for (i, speed) in speeds.iter().enumerate() {
        let expected = speed / speeds.iter().sum::<f64>();
        assert!(
            (shares[i] - expected).abs() <= 0.1 * expected,
            "worker {i}: share {:.3}, expected {expected:.3}",
            shares[i]
        );
    }
    assert!(
        frames[2].stats.imbalance < 0.1,
        "{}",
        frames[2].stats.imbalance
    );
}

/// Frames are cut into packages by the items' estimated costs, learnt
/// from the results: the first frames, started before any result came
/// (frames are pipelined) and estimating every item alike, hand the 60
/// items that cost 20 times more out late in packages that run long;
/// from the seventh frame on they are known, so no package runs half as
/// long as frame 0's longest, and the frames after the first eight are
/// faster and balance.
#[test]
fn cost_estimates_carry_over_between_frames() {
    let items = uneven_items(600, 0, 3, 0.01, 270..330, 20.0);
    let rules = no_stragglers(split_rules());
    let (farm, frames) = run_job(
        rules,
        ItemCosts::default(),
        &vec![worker(1.0); 8],
        &items,
        12,
    );
    let longest = |frame: u32| -> f64 {
        (0..8)
            .flat_map(|w| runs(&farm, w))
            .filter(|(_, r)| r.frame == frame)
            .map(|(run, _)| run.work)
            .fold(0.0, f64::max)
    };
    let first = &frames[0].stats;
    for later in &frames[6..] {
        let f = later.frame;
        assert!(
            longest(f) < longest(0) / 2.0,
            "frame {f}: {} s, frame 0: {} s",
            longest(f),
            longest(0)
        );
    }
    // The frames after the first eight (in flight at once), but the last.
    let warm = &frames[8..11];
    for f in warm {
        assert!(f.stats.wall_micros < first.wall_micros, "frame {}", f.frame);
    }
    let imbalance = warm.iter().map(|f| f.stats.imbalance).sum::<f64>() / warm.len() as f64;
    assert!(
        imbalance < first.imbalance / 2.0 && imbalance < 0.1,
        "imbalance {} → {imbalance}",
        first.imbalance
    );
}

#[test]
fn a_late_joiner_gets_work_mid_frame() {
    let items = plain_items();
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &[worker(1.0)]);
    submit(&mut farm, &items, 1);
    run_until(&mut farm, Duration::from_secs(2));
    join_all(&mut farm, &[worker(1.0)]);
    run_to_end(&mut farm, &[1]);
    let frames = delivered(&farm);
    assert_each_item_once(&frames, 600);
    let share = cost_shares(&farm, frames[0].job, 0)[1];
    // It joined at 2 s of about 7 s, so it did about 5/12 of the work.
    assert!(share > 0.3 && share < 0.5, "{share}");
}

#[test]
fn a_slow_link_gets_smaller_shares() {
    // The paper's mix of fast and slow links with large results.
    let items = plain_items();
    let mut specs = vec![worker(1.0); 4];
    specs[3].link_bits_per_second = 1e6;
    let model = ItemCosts {
        result_bytes_per_item: 8192,
        ..ItemCosts::default()
    };
    let (farm, frames) = run_job(split_rules(), model, &specs, &items, 3);
    let shares = cost_shares(&farm, frames[2].job, 2);
    assert!(shares[3] < 0.5 * shares[0], "{shares:?}");
}

/// One shared master link: the results of a frame queue for it, so a slow
/// master link bounds the frame time from below (a fast one leaves the job
/// far quicker), and a run repeats exactly.
#[test]
fn a_shared_master_link_bounds_the_frame_and_runs_repeat_exactly() {
    let items = uneven_items(400, 0, 3, 0.005, 100..140, 2.0);
    let spec = WorkerSpec {
        link_bits_per_second: 1e9,
        ..worker(1.0)
    };
    let run = |master_link: f64| {
        let model = ItemCosts {
            frame_setup: 0.05,
            result_bytes_per_item: 20_000,
            master: vtfarm_farmsim::MasterCosts {
                base_frame: 0.03,
                ..Default::default()
            },
            ..ItemCosts::default()
        };
        let mut farm = farm_with_link(FarmRules::default(), model, master_link);
        join_all(&mut farm, &vec![spec.clone(); 8]);
        submit(&mut farm, &items, 3);
        run_to_end(&mut farm, &[3]);
        let frames = delivered(&farm);
        assert_each_item_once(&frames, 400);
        frames
    };
    let (fast, slow) = (run(f64::INFINITY), run(10e6));
    // 400 items × 20 kB through 10 Mbit/s: 6.4 s of results per frame.
    let link_bound = 400.0 * 20_000.0 * 8.0 / 10e6;
    for f in &slow {
        let wall = f.stats.wall_micros as f64 / 1e6;
        assert!(wall >= link_bound, "{wall} s");
        assert!(f.done_at >= f.completed_at);
    }
    // Frames overlap, so a frame's own wall time says little: the whole
    // job takes less than a quarter of what the slow link needs per frame.
    assert!(end(&fast) < link_bound / 4.0 * 3.0, "{} s", end(&fast));
    let again = run(10e6);
    let times =
        |f: &[Delivered]| -> Vec<_> { f.iter().map(|d| (d.done_at, d.stats.clone())).collect() };
    assert_eq!(times(&again), times(&slow), "deterministic");
}

// ----- Pipelined and whole frames -----

/// Frames overlap: frame N+1's first packages run before frame N's last
/// result is in; results held for a slow base image are never duplicated
/// as stragglers, and every item completes once.
#[test]
fn pipelined_frames_overlap_and_held_results_are_not_duplicated() {
    let items = uneven_items(300, 0, 5, 0.002, 100..120, 3.0);
    let model = ItemCosts {
        frame_setup: 0.04,
        master: vtfarm_farmsim::MasterCosts {
            // Longer than a frame's tracing: every result waits for it.
            base_frame: 2.0,
            result_per_item: 20e-6,
            ..Default::default()
        },
        ..ItemCosts::default()
    };
    let (farm, frames) = run_job(split_rules(), model, &vec![worker(1.0); 4], &items, 4);
    let job = frames[0].job;
    for f in &frames {
        assert_eq!(f.stats.duplicates, 0, "frame {}", f.frame);
    }
    let all: Vec<_> = (0..4).flat_map(|w| runs(&farm, w)).collect();
    // Frame 0's tracing was over long before its base image (2 s): its
    // results waited.
    let traced = (all.iter())
        .filter(|(_, r)| r.job == job && r.frame == 0)
        .filter_map(|(run, _)| run.end)
        .max()
        .expect("frame 0 ran");
    assert!(traced + Duration::from_secs(1) < frames[0].completed_at.max(frames[0].done_at));
    for pair in frames.windows(2) {
        let of = |frame: u32| {
            all.iter()
                .filter(move |(_, r)| r.job == job && r.frame == frame)
        };
        let first_of_next = (of(pair[1].frame).map(|(run, _)| run.start).min())
            .expect("the next frame has packages");
        assert!(
            first_of_next < pair[0].done_at,
            "frame {} started at {first_of_next:?}, frame {} went out at {:?}",
            pair[1].frame,
            pair[0].frame,
            pair[0].done_at
        );
    }
}

/// Frame affinity (the master's rules): each frame's fresh work goes to a
/// crew, so with 12 workers over 12 frames a worker gets packages of
/// under half of the frames (every worker on every frame would set each
/// one up), and the farm stays within 10% of the work over its workers.
#[test]
fn frame_affinity_keeps_workers_on_fewer_frames_and_the_farm_busy() {
    let items = uneven_items(600, 0, 7, 0.01, 200..240, 3.0);
    let (farm, frames) = run_job(
        split_rules(),
        ItemCosts::default(),
        &vec![worker(1.0); 12],
        &items,
        12,
    );
    let mut seen = BTreeSet::new();
    for w in 0..12 {
        for (_, r) in runs(&farm, w) {
            seen.insert((w, r.frame));
        }
    }
    let frames_per_worker = seen.len() as f64 / 12.0 / 12.0;
    assert!(frames_per_worker < 0.5, "{frames_per_worker}");
    let ideal = 12.0 * items.work() / 12.0;
    assert!(
        end(&frames) < 1.1 * ideal,
        "{} s, ideal {ideal} s",
        end(&frames)
    );
}

/// The master's costs of the batch scenarios: a base frame of 20 ms.
fn batch_model() -> ItemCosts {
    ItemCosts {
        master: vtfarm_farmsim::MasterCosts {
            base_frame: 0.02,
            ..Default::default()
        },
        ..ItemCosts::default()
    }
}

/// Which workers ran packages of each frame (a worker sets a frame up once
/// for all its packages of it), and whether the frame went whole.
fn crews(farm: &ItemFarm) -> BTreeMap<u32, (BTreeSet<usize>, bool)> {
    let mut crews = BTreeMap::<u32, (BTreeSet<usize>, bool)>::new();
    for w in 0..farm.workers.len() {
        for (_, r) in runs(farm, w) {
            let crew = crews.entry(r.frame).or_default();
            crew.0.insert(w);
            crew.1 |= r.whole;
        }
    }
    crews
}

/// Which frames went whole, by frame.
fn whole_frames(farm: &ItemFarm) -> Vec<bool> {
    crews(farm).values().map(|(_, whole)| *whole).collect()
}

/// A deep batch job: while more frames are left to start than there are
/// workers, each frame goes to one worker whole, so each is set up once;
/// the last frames, no more than the workers, are split and spread over
/// several; the farm stays busy throughout.
#[test]
fn a_deep_batch_job_sets_each_frame_up_once_and_its_tail_spreads() {
    let items = uneven_items(200, 0, 11, 0.002, 50..80, 3.0);
    let (farm, frames) = run_job(
        FarmRules::default(),
        batch_model(),
        &vec![worker(1.0); 8],
        &items,
        40,
    );
    let crews = crews(&farm);
    // Frame i starts with 40 − i frames not started: whole while that is
    // more than the 8 workers.
    let tail = 8;
    let whole = whole_frames(&farm);
    assert_eq!(whole, (0..40).map(|i| 40 - i > tail).collect::<Vec<_>>());
    for (frame, (crew, whole)) in &crews {
        if *whole {
            assert_eq!(crew.len(), 1, "whole frame {frame}: {crew:?}");
        }
    }
    let spread = crews
        .values()
        .filter(|(c, whole)| !whole && c.len() > 1)
        .count();
    assert!(
        spread + 2 >= tail,
        "tail frames on several workers: {spread} of {tail}"
    );
    let set_ups: usize = crews.values().map(|(c, _)| c.len()).sum();
    assert!(set_ups < 40 - tail + 8 * tail, "{set_ups} set-ups");
    let efficiency = 40.0 * items.work() / 8.0 / end(&frames);
    println!(
        "{set_ups} set-ups, {tail} split, efficiency {:.1}%",
        100.0 * efficiency
    );
    assert!(efficiency > 0.85, "efficiency {efficiency}");
}

/// A single-frame job is split: every worker takes part in its frame.
#[test]
fn a_single_frame_job_spreads_over_every_worker() {
    let items = uneven_items(400, 0, 12, 0.002, 0..0, 1.0);
    let (farm, _) = run_job(
        FarmRules::default(),
        batch_model(),
        &vec![worker(1.0); 8],
        &items,
        1,
    );
    assert_eq!(whole_frames(&farm), [false]);
    assert_eq!(crews(&farm)[&0].0.len(), 8);
}

/// A worker ten times slower than the others gets whole frames too (its
/// speed is not known in advance), but the others take copies of its
/// whole frames rather than wait for them, and it stops each copied one.
#[test]
fn a_slow_workers_last_frame_is_finished_by_the_others() {
    let items = uneven_items(200, 0, 13, 0.002, 0..0, 1.0);
    let fast = worker(1.0);
    let (with_farm, with_slow) = run_job(
        FarmRules::default(),
        batch_model(),
        &[fast.clone(), fast.clone(), fast, worker(0.1)],
        &items,
        30,
    );
    let duplicates: u32 = with_slow.iter().map(|f| f.stats.duplicates).sum();
    assert!(duplicates >= 1, "no copy of the slow worker's frame");
    let last = (runs(&with_farm, 3).iter())
        .filter(|(_, r)| r.whole)
        .map(|(_, r)| r.frame)
        .max()
        .expect("the slow worker got a whole frame");
    assert!(
        !workers_of(&with_slow[last as usize]).contains(&3),
        "frame {last}: {:?}",
        with_slow[last as usize].stats.workers
    );
    // Its frames that others finished stopped on it when they went out
    // (the cancel reached it), not at their own end.
    for (run, r) in runs(&with_farm, 3) {
        let out = with_slow[r.frame as usize].done_at;
        let end = run.end.unwrap_or(with_farm.now);
        assert!(
            end <= out + Duration::from_millis(10),
            "frame {}: ran to {end:?}, out at {out:?}",
            r.frame
        );
    }
}

/// A single frame of two big items on four workers, beside a deep job: the
/// two workers the frame cannot use take the deep job's work at once, so
/// no worker idles while work exists and the farm ends when the work over
/// four workers does.
#[test]
fn a_small_job_beside_a_deep_one_leaves_no_worker_idle() {
    let mut big = uneven_items(2, 5000, 1, 1.0, 0..0, 1.0);
    big.costs = vec![1.0, 1.0];
    let deep = uneven_items(100, 0, 14, 0.005, 0..0, 1.0);
    for rules in [split_rules(), FarmRules::default()] {
        let mut farm = farm(rules, batch_model());
        join_all(&mut farm, &vec![worker(1.0); 4]);
        submit(&mut farm, &big, 1);
        submit(&mut farm, &deep, 12);
        run_to_end(&mut farm, &[1, 12]);
        let jobs = accepted_jobs(&farm);
        let frames = delivered(&farm);
        let small_done = (frames.iter())
            .find(|f| f.job == jobs[0])
            .expect("complete")
            .completed_at;
        let first = |job: JobId| {
            (0..4)
                .flat_map(|w| runs(&farm, w))
                .filter(|(_, r)| r.job == job)
                .map(|(run, _)| run.start)
                .min()
                .expect("assigned")
        };
        // From the first package on (the scene's way to the workers
        // comes before).
        let (small_first, deep_first) = (first(jobs[0]), first(jobs[1]));
        assert!(
            deep_first < small_first + Duration::from_millis(100),
            "the deep job waited until {deep_first:?}, the small one ran from {small_first:?}"
        );
        assert!(
            small_done < small_first + Duration::from_millis(1200),
            "{small_done:?}"
        );
        let work = 2.0 + deep.work() * 12.0;
        let end = end(&frames);
        let end = end - small_first.as_secs_f64();
        println!("end {end:.3} s, ideal {:.3} s", work / 4.0);
        assert!(end < work / 4.0 * 1.1, "{end} s for {work} s of work on 4");
    }
}

/// The tail splits no more frames than the master's measured costs allow:
/// the dearer the master's base frame against a whole frame's tracing, the
/// fewer of the last frames split; every frame before them goes whole.
#[test]
fn a_deep_batch_jobs_tail_splits_no_more_frames_than_the_measured_costs_allow() {
    let items = uneven_items(200, 0, 15, 0.002, 0..0, 1.0);
    let tail = |base_frame: f64| {
        let model = ItemCosts {
            master: vtfarm_farmsim::MasterCosts {
                base_frame,
                ..Default::default()
            },
            ..ItemCosts::default()
        };
        let (farm, _) = run_job(
            FarmRules::default(),
            model,
            &vec![worker(1.0); 8],
            &items,
            40,
        );
        let whole = whole_frames(&farm);
        let split = whole.iter().filter(|w| !**w).count();
        assert_eq!(whole, (0..40).map(|i| i < 40 - split).collect::<Vec<_>>());
        // Each split frame's base frame made once.
        let bases: BTreeSet<(JobId, u32)> = farm.base_frames.iter().copied().collect();
        assert_eq!(
            bases.len(),
            farm.base_frames.len(),
            "{:?}",
            farm.base_frames
        );
        assert!((40 - split as u32..40).all(|f| bases.iter().any(|b| b.1 == f)));
        split
    };
    // A cheap base frame: the tail is as wide as the farm; one that
    // costs the master half a whole frame's tracing narrows it; one as
    // dear as the tracing leaves only the last frame split.
    assert_eq!(tail(0.02), 8);
    assert_eq!(tail(items.work() / 2.0), 7);
    assert_eq!(tail(items.work()), 1);
}

/// Until the costs are measured (no base frame made yet) the tail is no
/// wider than the frames in flight, and a job's last frame is always split:
/// a job of 12 frames on 16 workers splits at most the frames in flight; on
/// 2 workers the last 2 split, on one the last.
#[test]
fn unmeasured_tails_split_up_to_the_frames_in_flight_and_the_last_frame_always() {
    let items = uneven_items(100, 0, 16, 0.002, 0..0, 1.0);
    for (workers, split) in [(16, vtfarm_proto::FRAMES_IN_FLIGHT), (2, 2), (1, 1)] {
        let (farm, _) = run_job(
            FarmRules::default(),
            ItemCosts::default(),
            &vec![worker(1.0); workers],
            &items,
            12,
        );
        let expected: Vec<bool> = (0..12).map(|i| 12 - i > split).collect();
        assert_eq!(whole_frames(&farm), expected, "{workers} workers");
    }
}

// ----- Faults -----

#[test]
fn a_crash_mid_frame_requeues_its_packages() {
    let items = plain_items();
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 4]);
    submit(&mut farm, &items, 2);
    run_until(&mut farm, Duration::from_millis(1500));
    crash(&mut farm, 1, true);
    // Lost at once, and only it.
    assert_eq!(connected_workers(&farm), [0, 2, 3]);
    run_to_end(&mut farm, &[2]);
    let frames = delivered(&farm);
    assert_eq!(frames.len(), 2);
    assert_each_item_once(&frames, 600);
    let requeued: u32 = frames.iter().map(|f| f.stats.requeued).sum();
    assert!(requeued >= 1, "{requeued}");
    assert!(!workers_of(&frames[1]).contains(&1));
}

#[test]
fn a_silent_crash_is_found_by_the_heartbeat_timeout() {
    let items = plain_items();
    // Without straggler cuts only the timeout brings the package back.
    let rules = no_stragglers(split_rules());
    let timeout = rules.heartbeat_timeout;
    let mut farm = farm(rules, ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 4]);
    submit(&mut farm, &items, 2);
    let at = Duration::from_millis(1500);
    run_until(&mut farm, at);
    crash(&mut farm, 2, false);
    // The master holds it until the heartbeat timeout, from its last
    // message (at most a heartbeat interval before the crash).
    run_until(&mut farm, at + timeout - Duration::from_secs(1));
    assert_eq!(connected_workers(&farm), [0, 1, 2, 3]);
    run_until(&mut farm, at + timeout);
    assert_eq!(connected_workers(&farm), [0, 1, 3]);
    run_to_end(&mut farm, &[2]);
    let frames = delivered(&farm);
    assert_each_item_once(&frames, 600);
    let requeued: u32 = frames.iter().map(|f| f.stats.requeued).sum();
    // Its running package and the one it held ahead.
    assert!((1..=2).contains(&requeued), "{requeued}");
    // The timeout runs from its last message, sent at most a heartbeat
    // interval before the crash; the frame waited for the package.
    let found = at - Duration::from_secs(1) + timeout;
    assert!(
        frames[0].completed_at > found,
        "{:?}",
        frames[0].completed_at
    );
    assert!(
        frames[0].completed_at < at + timeout + Duration::from_secs(1),
        "{:?}",
        frames[0].completed_at
    );
}

#[test]
fn a_straggler_is_copied_and_the_frame_does_not_wait_for_it() {
    let items = plain_items();
    let run = |rules: FarmRules| {
        let mut farm = farm(rules, ItemCosts::default());
        join_all(&mut farm, &vec![worker(1.0); 4]);
        submit(&mut farm, &items, 1);
        run_until(&mut farm, Duration::from_millis(1500));
        // From its next package on it computes 20 times slower.
        farm.workers[0].spec.speed = 0.05;
        run_to_end(&mut farm, &[1]);
        let frames = delivered(&farm);
        assert_each_item_once(&frames, 600);
        frames
    };
    let cut = run(split_rules());
    let waited = run(no_stragglers(split_rules()));
    println!(
        "20× slowdown at 1.5 s: frame at {} s with straggler copies, {} s without",
        end(&cut),
        end(&waited)
    );
    assert!(cut[0].stats.duplicates >= 1);
    assert_eq!(waited[0].stats.duplicates, 0);
    assert!(end(&cut) * 2.0 < end(&waited));
}

#[test]
fn failed_packages_are_retried_on_other_workers() {
    let items = plain_items();
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 3]);
    farm.workers[2].state.failures = Failures::FirstPackages(2);
    submit(&mut farm, &items, 1);
    run_to_end(&mut farm, &[1]);
    let frames = delivered(&farm);
    assert_each_item_once(&frames, 600);
    assert_eq!(frames[0].stats.failures, 2);
    // Two failures do not blocklist it: it went on to trace.
    assert!(workers_of(&frames[0]).contains(&2));
}

#[test]
fn three_failures_blocklist_a_worker_for_the_job() {
    let items = plain_items();
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 3]);
    farm.workers[1].state.failures = Failures::Always;
    submit(&mut farm, &items, 2);
    run_to_end(&mut farm, &[2]);
    let frames = delivered(&farm);
    assert_eq!(frames.len(), 2);
    assert_each_item_once(&frames, 600);
    // No work after the blocklist: its three failures and at most the
    // package it held ahead when the third one arrived, all of frame 0.
    let ran = runs(&farm, 1);
    assert!((3..=4).contains(&ran.len()), "{ran:?}");
    assert!(ran.iter().all(|(_, r)| r.frame == 0 && r.failed));
    let failures: u32 = frames.iter().map(|f| f.stats.failures).sum();
    assert!(failures >= 3);
    assert!(!workers_of(&frames[1]).contains(&1));
}

#[test]
fn a_package_failing_on_three_workers_fails_the_job_and_the_next_job_runs() {
    let bad = plain_items();
    let bad_item = bad.items[300];
    let good = uneven_items(600, 600, 1, 0.01, 0..0, 1.0);
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 4]);
    for w in 0..4 {
        farm.workers[w].state.failures = Failures::Items(vec![bad_item]);
    }
    submit(&mut farm, &bad, 1);
    submit(&mut farm, &good, 1);
    run_to_end(&mut farm, &[1, 1]);
    let jobs = accepted_jobs(&farm);
    let errors = failure(&farm, jobs[0]).expect("the bad job failed");
    // The reason, then each failure.
    assert!(errors[0].contains("PackageFailed"), "{errors:?}");
    let errors = &errors[1..];
    let names: BTreeSet<String> = (0..4)
        .map(|w| format!("w{w}"))
        .filter(|name| {
            errors
                .iter()
                .any(|e| e.contains(&format!("failed on {name}")))
        })
        .collect();
    assert_eq!((errors.len(), names.len()), (3, 3), "{errors:?}");
    assert!(failure(&farm, jobs[1]).is_none());
    let frames = delivered(&farm);
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].job, jobs[1]);
    assert_each_item_once(&frames, 600);
}

#[test]
fn a_job_fails_when_every_worker_is_blocklisted() {
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 2]);
    for w in 0..2 {
        farm.workers[w].state.failures = Failures::Always;
    }
    submit(&mut farm, &plain_items(), 1);
    run_to_end(&mut farm, &[1]);
    let errors = failure(&farm, accepted_jobs(&farm)[0]).expect("failed");
    assert!(errors[0].contains("NoEligibleWorker"), "{errors:?}");
    for w in 0..2 {
        let name = format!("failed on w{w}");
        let count = errors.iter().filter(|e| e.contains(&name)).count();
        assert_eq!(count, 3, "three from each worker: {errors:?}");
    }
    assert_eq!(errors.len(), 7, "the reason and six failures: {errors:?}");
    for w in 0..2 {
        // Its three failures and at most the package it held ahead.
        assert!((3..=4).contains(&runs(&farm, w).len()));
    }
}

#[test]
fn a_frame_completes_while_one_worker_remains() {
    let items = plain_items();
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(&mut farm, &vec![worker(1.0); 4]);
    submit(&mut farm, &items, 2);
    for w in 1..4 {
        run_until(&mut farm, Duration::from_millis(500 * w as u64));
        crash(&mut farm, w, w % 2 == 1);
    }
    run_to_end(&mut farm, &[2]);
    let frames = delivered(&farm);
    assert_eq!(frames.len(), 2);
    assert_each_item_once(&frames, 600);
    assert_eq!(workers_of(&frames[1]), [0]);
    assert_eq!(connected_workers(&farm), [0], "three lost");
}

/// A worker that failed three packages (blocklisted) and then crashed
/// silently mid-package, beside late joiners on slow links (each takes
/// seconds to get the scene): its package comes back by the heartbeat
/// timeout at the latest, the others' messages never wait behind the
/// slow links' scene, and the frame completes with each item once.
#[test]
fn a_blocklisted_worker_that_crashes_silently_still_lets_the_frame_complete() {
    let items = uneven_items(97, 0, 0, 0.001, 0..0, 1.0);
    let slow_link = |speed: f64| WorkerSpec {
        link_bits_per_second: 1e6,
        ..worker(speed)
    };
    let mut farm = farm(split_rules(), ItemCosts::default());
    join_all(
        &mut farm,
        &[
            worker(1.0),
            WorkerSpec {
                link_bits_per_second: 1e9,
                ..worker(0.2)
            },
        ],
    );
    farm.workers[1].state.failures = Failures::FirstPackages(3);
    submit(&mut farm, &items, 1);
    run_until(&mut farm, Duration::from_millis(66));
    crash(&mut farm, 1, false);
    run_until(&mut farm, Duration::from_millis(859));
    join_all(&mut farm, &[slow_link(0.2)]);
    run_until(&mut farm, Duration::from_millis(895));
    join_all(&mut farm, &[slow_link(1.5), slow_link(2.5)]);
    farm.workers[3].state.failures = Failures::FirstPackages(2);
    run_until(&mut farm, Duration::from_millis(2422));
    join_all(&mut farm, &[slow_link(0.2)]);
    run_to_end(&mut farm, &[1]);
    let frames = delivered(&farm);
    assert_each_item_once(&frames, 97);
    assert!(!workers_of(&frames[0]).contains(&1));
    let timeout = split_rules().heartbeat_timeout;
    let by = Duration::from_millis(66) + timeout + Duration::from_secs(1);
    assert!(frames[0].done_at < by, "{:?}", frames[0].done_at);
}
