//! Random farms on the real master core and worker sessions (speeds,
//! links, late joins, crashes noticed or silent, slowdowns, failing
//! workers) with one reliable worker and up to four jobs submitted at
//! random times: every job always ends with every frame delivered, each
//! item traced exactly once.

mod support;

use std::time::Duration;

use proptest::prelude::*;
use support::*;
use vtfarm_farmsim::WorkerSpec;

/// A random worker and its faults.
#[derive(Clone, Debug)]
struct RandomWorker {
    spec: WorkerSpec,
    join_ms: u64,
    /// When it crashes, and whether its connection drop is noticed.
    crash: Option<(u64, bool)>,
    /// When it slows down, and by how much.
    slowdown: Option<(u64, f64)>,
    /// How many of its first packages fail.
    fails: u32,
}

fn random_worker() -> impl Strategy<Value = RandomWorker> {
    (
        (
            0.2f64..4.0,
            prop::sample::select(vec![1e6, 10e6, 100e6, 1e9]),
        ),
        (0u64..3000, prop::option::of((0u64..4000, any::<bool>()))),
        (prop::option::of((0u64..4000, 2.0f64..30.0)), 0u32..4),
    )
        .prop_map(
            |((speed, bits), (join_ms, crash), (slowdown, fails))| RandomWorker {
                spec: WorkerSpec {
                    link_bits_per_second: bits,
                    ..worker(speed)
                },
                join_ms,
                crash,
                slowdown,
                fails,
            },
        )
}

/// What happens when, in a random farm's timeline (workers by their
/// index among the random ones).
#[derive(Clone, Debug)]
enum Action {
    Join(usize),
    Crash(usize, bool),
    Slow(usize, f64),
    Submit(usize),
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Random farms with one reliable worker and at most two failing ones
    /// (a third could fail one package three times, which rightly fails
    /// its job) always deliver every frame of every job, each item once,
    /// with one to four jobs submitted at random times (several run at
    /// once on workers the first cannot use), under whole or split frames.
    #[test]
    fn random_farms_deliver_every_frame_with_each_item_once(
        mut workers in prop::collection::vec(random_worker(), 0..8),
        items in 1usize..300,
        frames in 1usize..4,
        seed in any::<u64>(),
        later_jobs in prop::collection::vec((0u64..3000, 1usize..4, 1usize..60), 0..3),
        whole_frames in any::<bool>(),
    ) {
        for w in workers.iter_mut().skip(2) {
            w.fails = 0;
        }
        let first = uneven_items(items, 0, seed, 0.001, 0..0, 1.0);
        let mut jobs = vec![(0, first.clone(), frames)];
        for &(at_ms, frames, items) in &later_jobs {
            // A prefix of the first job's frame.
            let items = items.min(first.items.len());
            let prefix = Items {
                items: first.items[..items].to_vec(),
                costs: first.costs[..items].to_vec(),
            };
            jobs.push((at_ms, prefix, frames));
        }
        let rules = if whole_frames { vtfarm_master_core::FarmRules::default() } else { split_rules() };
        let mut farm = farm(rules, ItemCosts::default());
        join_all(&mut farm, &[worker(1.0)]);
        let mut timeline: Vec<(u64, Action)> = Vec::new();
        for (i, w) in workers.iter().enumerate() {
            timeline.push((w.join_ms, Action::Join(i)));
            if let Some((at, noticed)) = w.crash {
                timeline.push((w.join_ms.max(at), Action::Crash(i, noticed)));
            }
            if let Some((at, factor)) = w.slowdown {
                timeline.push((w.join_ms.max(at), Action::Slow(i, factor)));
            }
        }
        for (j, (at, _, _)) in jobs.iter().enumerate() {
            timeline.push((*at, Action::Submit(j)));
        }
        // Joins before the faults at the same time; stable otherwise.
        timeline.sort_by_key(|(at, action)| (*at, !matches!(action, Action::Join(_))));
        let mut submitted = Vec::new();
        // The farm's index of each random worker, once it joined.
        let mut index = vec![0; workers.len()];
        for (at, action) in timeline {
            run_until(&mut farm, Duration::from_millis(at));
            match action {
                Action::Join(i) => {
                    join_all(&mut farm, std::slice::from_ref(&workers[i].spec));
                    index[i] = farm.workers.len() - 1;
                    farm.workers[index[i]].state.failures = Failures::FirstPackages(workers[i].fails);
                }
                Action::Crash(i, noticed) => crash(&mut farm, index[i], noticed),
                Action::Slow(i, factor) => farm.workers[index[i]].spec.speed /= factor,
                Action::Submit(j) => {
                    submit(&mut farm, &jobs[j].1, jobs[j].2);
                    submitted.push(j);
                }
            }
        }
        let frames_per_job: Vec<usize> = submitted.iter().map(|&j| jobs[j].2).collect();
        run_to_end(&mut farm, &frames_per_job);
        let accepted = accepted_jobs(&farm);
        let delivered = delivered(&farm);
        for (&j, job) in submitted.iter().zip(&accepted) {
            prop_assert!(failure(&farm, *job).is_none(), "job {} failed", job);
            let of_job: Vec<Delivered> = delivered.iter().filter(|d| d.job == *job).cloned().collect();
            prop_assert_eq!(of_job.len(), jobs[j].2);
            assert_each_item_once(&of_job, jobs[j].1.items.len());
        }
    }
}
