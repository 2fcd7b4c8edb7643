//! What the master has done so far, for the browser view and `/metrics`:
//! cumulative counters, per-worker totals and the last finished frames.
//! The core updates it as events happen; the HTTP side only reads it
//! (through `MasterHandle::inspect`). Plain data: no I/O, no clock.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;
use vtfarm_proto::JobId;

use vtfarm_proto::{FrameStats, WireImage};

/// How many finished frames the master keeps for flicking through.
pub const KEPT_FRAMES: usize = 16;

/// Upper bounds (seconds) of the frame-duration histogram's buckets; a
/// last, unbounded bucket catches the rest.
pub const FRAME_SECONDS_BUCKETS: [f64; 10] =
    [0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0];

/// Frame wall times as a histogram (all frames, bounded memory).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameDurations {
    /// Frames per bucket of [`FRAME_SECONDS_BUCKETS`] (not cumulative),
    /// then the frames above the last bound.
    pub counts: [u64; FRAME_SECONDS_BUCKETS.len() + 1],
    pub sum_seconds: f64,
    pub count: u64,
}

impl FrameDurations {
    fn observe(&mut self, seconds: f64) {
        let bucket = FRAME_SECONDS_BUCKETS
            .iter()
            .position(|&bound| seconds <= bound)
            .unwrap_or(FRAME_SECONDS_BUCKETS.len());
        self.counts[bucket] += 1;
        self.sum_seconds += seconds;
        self.count += 1;
    }
}

/// Cumulative counts since the master started.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FarmCounters {
    pub jobs_submitted: u64,
    pub jobs_completed: u64,
    pub jobs_failed: u64,
    pub jobs_cancelled: u64,
    pub frames_completed: u64,
    pub packages_done: u64,
    pub packages_failed: u64,
    pub packages_requeued: u64,
    pub packages_duplicated: u64,
    /// Journal records that could not be written (a full disk, say).
    pub journal_write_failures: u64,
    /// Finished frames the journal could not give back, rendered again.
    pub frames_rendered_again: u64,
}

/// One worker's totals since it first joined (kept by name, so a worker
/// that reconnects continues its figures).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WorkerTotals {
    pub samples: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
    /// Jobs the worker may no longer work on (failed too often).
    pub blocklisted_jobs: BTreeSet<JobId>,
}

/// A finished frame as the submitter received it.
#[derive(Clone, Debug)]
pub struct FinishedFrameRecord {
    /// Numbers frames in the order they finished, from 1.
    pub seq: u64,
    pub job: JobId,
    pub frame: u32,
    pub stats: FrameStats,
    /// The image as it went to the submitter (compressed: a few MB where
    /// the linear 1080p frame is 25 MB), decoded when it is looked at.
    pub image: Arc<WireImage>,
}

/// The master's history, bounded.
#[derive(Debug, Default)]
pub struct Telemetry {
    pub counters: FarmCounters,
    pub workers: BTreeMap<String, WorkerTotals>,
    pub frame_durations: FrameDurations,
    /// The last journal write that failed, as the submitters were told.
    pub last_journal_error: Option<String>,
    frames: VecDeque<FinishedFrameRecord>,
    next_seq: u64,
}

impl Telemetry {
    /// Records a finished frame: its counts, and its image among the kept ones.
    pub fn frame_finished(&mut self, job: JobId, frame: u32, stats: FrameStats, image: WireImage) {
        let c = &mut self.counters;
        c.frames_completed += 1;
        c.packages_failed += u64::from(stats.failures);
        c.packages_requeued += u64::from(stats.requeued);
        c.packages_duplicated += u64::from(stats.duplicates);
        (self.frame_durations).observe(stats.wall_micros as f64 / 1e6);
        self.next_seq += 1;
        if self.frames.len() == KEPT_FRAMES {
            self.frames.pop_front();
        }
        self.frames.push_back(FinishedFrameRecord {
            seq: self.next_seq,
            job,
            frame,
            stats,
            image: Arc::new(image),
        });
    }

    /// Counts an accepted package result.
    pub fn package_done(&mut self, worker: &str, samples: u64, bytes_in: u64, bytes_out: u64) {
        self.counters.packages_done += 1;
        let w = self.workers.entry(worker.to_owned()).or_default();
        w.samples += samples;
        w.bytes_in += bytes_in;
        w.bytes_out += bytes_out;
    }

    pub fn blocklisted(&mut self, worker: &str, job: JobId) {
        let w = self.workers.entry(worker.to_owned()).or_default();
        w.blocklisted_jobs.insert(job);
    }

    /// The kept finished frames, oldest first.
    pub fn frames(&self) -> impl Iterator<Item = &FinishedFrameRecord> {
        self.frames.iter()
    }

    /// A kept finished frame by its sequence number.
    pub fn frame(&self, seq: u64) -> Option<&FinishedFrameRecord> {
        self.frames.iter().find(|f| f.seq == seq)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_last_frames_and_counts_all() {
        let mut t = Telemetry::default();
        for k in 0..(KEPT_FRAMES as u32 + 3) {
            let stats = FrameStats {
                failures: 1,
                wall_micros: 200_000,
                ..FrameStats::default()
            };
            t.frame_finished(JobId(1), k, stats, WireImage::default());
        }
        assert_eq!(t.counters.frames_completed, KEPT_FRAMES as u64 + 3);
        assert_eq!(t.counters.packages_failed, KEPT_FRAMES as u64 + 3);
        let seqs: Vec<u64> = t.frames().map(|f| f.seq).collect();
        assert_eq!(seqs, (4..=KEPT_FRAMES as u64 + 3).collect::<Vec<_>>());
        assert!(t.frame(3).is_none() && t.frame(4).is_some());
        let d = &t.frame_durations;
        assert_eq!(
            (d.count, d.counts[2]),
            (KEPT_FRAMES as u64 + 3, KEPT_FRAMES as u64 + 3)
        );
        assert!((d.sum_seconds - 0.2 * d.count as f64).abs() < 1e-9);
    }
}
