//! Per-item cost estimates of a job, carried from frame to frame.
//!
//! The first frame estimates every item at
//! [`CostEstimation::initial_item_cost`](crate::CostEstimation::initial_item_cost),
//! which defines the job's cost unit. When a frame completes, each item's
//! share of its package's busy time (seconds on the worker that ran it) is
//! turned back into cost units with that worker's compute rate (cost units
//! per busy second, the median over its recent packages), so a fast and a
//! slow worker measure the same item at the same cost and later frames stay
//! in the unit of the first. The next frame uses the measured cost of an item
//! it has seen and the mean of the last measured frame for an item it has
//! not.
//!
//! Why the median: a worker's rate in a frame is observed against that
//! frame's estimates, so a worker that got only the hot spot of a uniformly
//! estimated first frame would look slow, and its items cheap, for ever (the
//! two explain the same times). Over many packages most estimates are good
//! and the median sees through the few that were not.

use std::collections::BTreeMap;

use crate::frame::Frame;
use crate::{PackageState, WorkerId};

/// A measured cost is never estimated below this fraction of the mean, so a
/// worker that reports zero time cannot make items free (a package of free
/// items would take the whole frame).
const MIN_COST_FRACTION: f64 = 0.01;

/// A job's per-item cost estimates.
#[derive(Debug)]
pub(crate) struct CostModel {
    initial: f64,
    by_item: BTreeMap<u32, f64>,
    /// Mean cost of the items of the last measured frame.
    mean: Option<f64>,
}

impl CostModel {
    pub(crate) fn new(initial_item_cost: f64) -> CostModel {
        let initial = if initial_item_cost.is_finite() && initial_item_cost > 0.0 {
            initial_item_cost
        } else {
            1.0
        };
        CostModel {
            initial,
            by_item: BTreeMap::new(),
            mean: None,
        }
    }

    /// The estimated cost of an item.
    pub(crate) fn estimate(&self, item: u32) -> f64 {
        self.by_item
            .get(&item)
            .copied()
            .or(self.mean)
            .unwrap_or(self.initial)
    }

    /// Learns the costs measured in a complete frame.
    /// `speeds` are the workers' compute rates in cost units per second.
    pub(crate) fn learn(&mut self, frame: &Frame, speeds: &BTreeMap<WorkerId, f64>) {
        let mut learned = Vec::with_capacity(frame.items.len());
        for package in frame.packages.values() {
            if package.state() != PackageState::Done {
                continue;
            }
            let Some(speed) = package.completed_by.and_then(|w| speeds.get(&w)) else {
                continue;
            };
            for position in package.range.clone() {
                let cost = frame.measured[position] * speed;
                if cost.is_finite() {
                    learned.push((frame.items[position], cost));
                }
            }
        }
        if learned.is_empty() {
            return;
        }
        let raw_mean = learned.iter().map(|(_, c)| c).sum::<f64>() / learned.len() as f64;
        let floor = raw_mean * MIN_COST_FRACTION;
        if floor.is_nan() || floor <= 0.0 {
            return;
        }
        let mut sum = 0.0;
        for &(item, cost) in &learned {
            let cost = cost.max(floor);
            sum += cost;
            self.by_item.insert(item, cost);
        }
        self.mean = Some(sum / learned.len() as f64);
    }
}
