//! The running frame: its items and their cost estimates, the unassigned
//! items, the queue of packages waiting for a worker, every package cut so
//! far, which items are done, and the statistics gathered on the way.
//!
//! Positions (indices into the frame's item list) are the unit of
//! bookkeeping: a package is a range of positions, and every position is at
//! any time in exactly one of: the unassigned tail `next_fresh..`, a queued or
//! running package, or a done package.

use std::collections::{BTreeMap, VecDeque};
use std::ops::Range;
use std::time::Duration;

use crate::costs::CostModel;
use crate::{FrameStats, PackageId, PackageState, WorkerFrameStats, WorkerId};

/// One running frame of a running job.
#[derive(Debug)]
pub(crate) struct Frame {
    pub(crate) index: u32,
    pub(crate) items: Vec<u32>,
    /// A whole frame: one package of every item, never split (see
    /// [`SchedulerConfig::whole_frames`](crate::SchedulerConfig::whole_frames)).
    pub(crate) whole: bool,
    /// `prefix[i]` is the estimated cost of `items[..i]`, so any range's cost
    /// is a difference and cutting a package is a binary search.
    prefix: Vec<f64>,
    /// Items from here on were never handed out.
    pub(crate) next_fresh: usize,
    /// Packages waiting for a worker, the next one first.
    pub(crate) queue: VecDeque<PackageId>,
    /// Every package of the frame (final ones too, to tell late results).
    pub(crate) packages: BTreeMap<PackageId, Package>,
    pub(crate) done: Vec<bool>,
    pub(crate) done_count: usize,
    /// Each done item's share of its package's busy time, in seconds.
    pub(crate) measured: Vec<f64>,
    /// When the first package was handed out.
    pub(crate) started: Option<Duration>,
    pub(crate) stats: FrameStats,
    pub(crate) worker_stats: BTreeMap<WorkerId, WorkerFrameStats>,
}

/// A package: a contiguous range of the frame's positions.
#[derive(Debug)]
pub(crate) struct Package {
    state: PackageState,
    /// Its positions; its estimated cost is [`Frame::cost`] of them.
    pub(crate) range: Range<usize>,
    /// The workers running it now: one when assigned, two when duplicated.
    pub(crate) attempts: Vec<Attempt>,
    /// Every failure so far, in order.
    pub(crate) failures: Vec<(WorkerId, String)>,
    /// The worker whose result was accepted.
    pub(crate) completed_by: Option<WorkerId>,
}

/// One worker running one package.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Attempt {
    pub(crate) worker: WorkerId,
    pub(crate) assigned_at: Duration,
    pub(crate) expected: Duration,
    /// When its result arrived, if the driver holds it before accepting it.
    pub(crate) arrived_at: Option<Duration>,
}

impl Frame {
    /// A frame whose items are estimated by `costs`; `whole` when it goes
    /// to one worker as one package.
    pub(crate) fn new(index: u32, items: Vec<u32>, whole: bool, costs: &CostModel) -> Frame {
        let prefix = prefix_costs(&items, costs);
        let n = items.len();
        Frame {
            index,
            items,
            whole,
            prefix,
            next_fresh: 0,
            queue: VecDeque::new(),
            packages: BTreeMap::new(),
            done: vec![false; n],
            done_count: 0,
            measured: vec![0.0; n],
            started: None,
            stats: FrameStats {
                items: n,
                ..FrameStats::default()
            },
            worker_stats: BTreeMap::new(),
        }
    }

    /// Estimates the items anew (a frame started before the one before it
    /// completed learns from that one too).
    pub(crate) fn reestimate(&mut self, costs: &CostModel) {
        self.prefix = prefix_costs(&self.items, costs);
    }

    pub(crate) fn is_complete(&self) -> bool {
        self.done_count == self.items.len()
    }

    /// Estimated cost of a range of positions.
    pub(crate) fn cost(&self, range: Range<usize>) -> f64 {
        self.prefix[range.end] - self.prefix[range.start]
    }

    /// Estimated cost of one position.
    pub(crate) fn estimate(&self, position: usize) -> f64 {
        self.cost(position..position + 1)
    }

    /// Estimated cost of the work no worker runs: unassigned items and queued
    /// packages.
    pub(crate) fn unassigned_cost(&self) -> f64 {
        let queued: f64 = self
            .queue
            .iter()
            .filter_map(|id| self.packages.get(id))
            .map(|p| self.cost(p.range.clone()))
            .sum();
        self.cost(self.next_fresh..self.items.len()) + queued
    }

    /// Whether work is left that no worker runs.
    pub(crate) fn has_unassigned(&self) -> bool {
        self.next_fresh < self.items.len() || !self.queue.is_empty()
    }

    /// The end of a package that starts at `range.start`, stays inside
    /// `range` and costs about `target`: at least one item, and the item that
    /// crosses the target is included when that comes closer to it.
    pub(crate) fn cut(&self, range: Range<usize>, target: f64) -> usize {
        if range.is_empty() {
            return range.end;
        }
        let base = self.prefix[range.start];
        let window = &self.prefix[range.start..=range.end];
        // First index whose prefix reaches the target.
        let end = (range.start + window.partition_point(|&p| p - base < target))
            .clamp(range.start + 1, range.end);
        let over = self.prefix[end] - base - target;
        let under = target - (self.prefix[end - 1] - base);
        if end - 1 > range.start && over > under {
            end - 1
        } else {
            end
        }
    }

    /// Statistics of the frame, finished at `now`.
    pub(crate) fn finish_stats(&mut self, now: Duration) -> FrameStats {
        let mut stats = std::mem::take(&mut self.stats);
        stats.wall = self
            .started
            .map_or(Duration::ZERO, |s| now.saturating_sub(s));
        stats.workers = std::mem::take(&mut self.worker_stats)
            .into_values()
            .collect();
        stats
    }
}

impl Package {
    /// A package handed straight to its first worker.
    pub(crate) fn assigned(
        range: Range<usize>,
        attempt: Attempt,
        failures: Vec<(WorkerId, String)>,
    ) -> Package {
        Package {
            state: PackageState::Assigned,
            range,
            attempts: vec![attempt],
            failures,
            completed_by: None,
        }
    }

    pub(crate) fn state(&self) -> PackageState {
        self.state
    }

    /// The one place a package changes state; the table in the crate
    /// documentation lists which function calls it for which transition.
    pub(crate) fn set_state(&mut self, to: PackageState) {
        debug_assert!(
            self.state.may_become(to),
            "package transition {:?} -> {to:?} is not in the table",
            self.state
        );
        self.state = to;
    }

    /// The attempt of `worker`, if it runs this package.
    pub(crate) fn attempt_of(&self, worker: WorkerId) -> Option<usize> {
        self.attempts.iter().position(|a| a.worker == worker)
    }

    /// How many different workers this package failed on.
    pub(crate) fn failed_workers(&self) -> usize {
        let mut workers: Vec<WorkerId> = self.failures.iter().map(|(w, _)| *w).collect();
        workers.sort_unstable();
        workers.dedup();
        workers.len()
    }

    pub(crate) fn failed_on(&self, worker: WorkerId) -> bool {
        self.failures.iter().any(|(w, _)| *w == worker)
    }
}

/// Running sums of the items' estimated costs, from 0.
fn prefix_costs(items: &[u32], costs: &CostModel) -> Vec<f64> {
    let mut prefix = Vec::with_capacity(items.len() + 1);
    let mut sum = 0.0;
    prefix.push(sum);
    for &item in items {
        sum += costs.estimate(item);
        prefix.push(sum);
    }
    prefix
}
