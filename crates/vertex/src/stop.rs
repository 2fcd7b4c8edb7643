//! Stopping a package early: a cancel flag set from another thread (the
//! worker, when the master cancels the package) and a budget of traced
//! samples that turns a runaway package into a failure. The package's loops
//! check it per edge split and per batch of traced pixels, so a stop takes
//! effect within a few hundred samples; the partial result is then
//! worthless and dropped.

use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// A package's cancel flag and sample budget, shared with the thread that
/// may cancel it.
#[derive(Debug)]
pub struct Stop {
    cancelled: AtomicBool,
    samples: AtomicU64,
    budget: u64,
}

/// Why a package stopped early.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stopped {
    /// [`Stop::cancel`] was called.
    Cancelled,
    /// The package traced more samples than its budget.
    OverBudget { budget: u64 },
}

impl fmt::Display for Stopped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Stopped::Cancelled => f.write_str("cancelled"),
            Stopped::OverBudget { budget } => write!(
                f,
                "stopped after its budget of {budget} traced samples (a runaway: check the job's quality settings)"
            ),
        }
    }
}

impl Stop {
    /// A stop that allows `budget` traced samples.
    pub fn with_budget(budget: u64) -> Self {
        Stop {
            cancelled: AtomicBool::new(false),
            samples: AtomicU64::new(0),
            budget,
        }
    }

    /// Stops the package at its next check.
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }

    /// Counts `samples` traced samples.
    pub fn charge(&self, samples: u64) {
        self.samples.fetch_add(samples, Ordering::Relaxed);
    }

    /// The samples counted so far: every sample the package traced.
    pub fn charged(&self) -> u64 {
        self.samples.load(Ordering::Relaxed)
    }

    /// Why the package must stop, if it must.
    pub fn stopped(&self) -> Option<Stopped> {
        if self.cancelled.load(Ordering::Relaxed) {
            Some(Stopped::Cancelled)
        } else if self.samples.load(Ordering::Relaxed) > self.budget {
            Some(Stopped::OverBudget {
                budget: self.budget,
            })
        } else {
            None
        }
    }
}
