//! Base frames made ahead and the master's measured time per base frame.
//!
//! A batch job's tail is split (the scheduler's whole frames): each of its
//! last frames needs the master's base frame and ID buffer, made one at a
//! time, which would hold a wide farm's tail while the workers wait. While
//! the job's whole frames run the master has little else to do, so it makes
//! the base frames of the job's last frames ahead, one at a time, and the
//! scheduler counts them as free ([`Scheduler::base_frame_ahead`]). A base
//! frame that was in the making alone (no other meanwhile) is the master's
//! measure of its time per base frame ([`Scheduler::base_frame_cost`]),
//! which with a whole frame's time bounds how many frames the tail splits.
//!
//! Memory: the base frames made ahead and those of the split frames being
//! assembled are together at most [`AHEAD_BYTES`] (1 GiB: 19 base frames
//! with their ID buffers and sRGB bytes at 1080p, 27 bytes a pixel), or the frames in flight
//! where those are more (the bound the split frames in flight alone had);
//! one made ahead becomes its split frame's when that starts. A wide
//! farm's tail needs them: 256 workers at the paper's work per frame end a
//! 560-frame job with 40 or so split frames, and the master makes a base
//! frame in 0.06 s, three times a worker's share of a frame there. The images do not change: a base frame is the same
//! `BaseFrameRequest::rasterize` of the same scene and set-up, whenever it
//! is made.
//!
//! [`Scheduler::base_frame_ahead`]: vtfarm_scheduler::Scheduler::base_frame_ahead
//! [`Scheduler::base_frame_cost`]: vtfarm_scheduler::Scheduler::base_frame_cost

use std::collections::BTreeMap;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_proto::FrameKey;

use super::base::BaseFrame;

/// The memory the base frames the master holds may take (made ahead and
/// those of the split frames being assembled).
pub(crate) const AHEAD_BYTES: u64 = 1 << 30;

/// Bytes of a base frame per pixel: linear RGB in `f32`, object, triangle
/// and depth of 4 bytes each in its ID buffer, and its 8-bit sRGB bytes
/// (converted ahead for a job whose frames go out in sRGB).
const BASE_BYTES_PER_PIXEL: u64 = 27;

/// How many base frames of `width` × `height` the master holds at most:
/// [`AHEAD_BYTES`] of them, or the `frames_in_flight` split frames' own.
pub(crate) fn frames_held_at_most(frames_in_flight: usize, width: u32, height: u32) -> usize {
    let bytes = u64::from(width) * u64::from(height) * BASE_BYTES_PER_PIXEL;
    let fit = AHEAD_BYTES / bytes.max(1);
    usize::try_from(fit)
        .unwrap_or(usize::MAX)
        .max(frames_in_flight)
}

/// The base frames in the making and those made ahead.
#[derive(Default)]
pub(crate) struct Bases {
    /// Requested from the driver and not back yet: when, whether alone so
    /// far (no other base frame in the making meanwhile), and whether made
    /// ahead of its frame's start.
    making: BTreeMap<FrameKey, Making>,
    /// Made ahead, for frames not started yet.
    ready: BTreeMap<FrameKey, BaseFrame>,
}

#[derive(Clone, Copy)]
struct Making {
    since: Duration,
    alone: bool,
    ahead: bool,
}

impl Bases {
    /// A base frame was asked of the driver at `now` (`ahead`: before its
    /// frame started). Every other in the making is no longer alone.
    pub(crate) fn requested(&mut self, key: FrameKey, now: Duration, ahead: bool) {
        let alone = self.making.is_empty();
        for other in self.making.values_mut() {
            other.alone = false;
        }
        let making = Making {
            since: now,
            alone,
            ahead,
        };
        self.making.insert(key, making);
    }

    /// The driver handed the base frame back: how long it took, when it
    /// was made alone (the master's time per base frame).
    pub(crate) fn arrived(&mut self, key: FrameKey, now: Duration) -> Option<Duration> {
        let making = self.making.remove(&key)?;
        making.alone.then(|| now.saturating_sub(making.since))
    }

    /// Whether the base frame of `key` is in the making ahead of its frame.
    pub(crate) fn making_ahead(&self, key: FrameKey) -> bool {
        self.making.get(&key).is_some_and(|m| m.ahead)
    }

    /// Whether the base frame of `key` is in the making or made ahead.
    pub(crate) fn has(&self, key: FrameKey) -> bool {
        self.making.contains_key(&key) || self.ready.contains_key(&key)
    }

    /// Whether any base frame is in the making ahead (they are made one at
    /// a time).
    pub(crate) fn any_making_ahead(&self) -> bool {
        self.making.values().any(|m| m.ahead)
    }

    /// Base frames held or coming: made ahead, or in the making.
    pub(crate) fn held(&self) -> usize {
        self.ready.len() + self.making.len()
    }

    /// Keeps a base frame made ahead.
    pub(crate) fn keep(&mut self, key: FrameKey, base: BaseFrame) {
        self.ready.insert(key, base);
    }

    /// The base frame made ahead for `key`, taken for its frame (split) or
    /// to be dropped (whole).
    pub(crate) fn take(&mut self, key: FrameKey) -> Option<BaseFrame> {
        self.ready.remove(&key)
    }

    /// Forgets a job that ended: its base frames made ahead go; those in
    /// the making are dropped when they come (the job is gone then).
    pub(crate) fn forget(&mut self, job: JobId) {
        self.ready.retain(|&(j, _), _| j != job);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    /// A base frame made alone is a measure; two made at once are not
    /// (each shared the master's cores), and one requested while another
    /// was in the making is not either.
    #[test]
    fn only_a_base_frame_made_alone_measures_the_masters_time() {
        let mut bases = Bases::default();
        bases.requested((JobId(1), 7), 10 * MS, true);
        assert!(bases.making_ahead((JobId(1), 7)));
        assert_eq!(bases.arrived((JobId(1), 7), 70 * MS), Some(60 * MS));
        assert!(!bases.has((JobId(1), 7)));

        bases.requested((JobId(1), 1), 100 * MS, false);
        bases.requested((JobId(1), 2), 110 * MS, false);
        assert_eq!(bases.arrived((JobId(1), 1), 200 * MS), None);
        assert_eq!(bases.arrived((JobId(1), 2), 220 * MS), None);
        assert_eq!(
            bases.arrived((JobId(1), 2), 230 * MS),
            None,
            "not in the making"
        );
    }

    /// 1 GiB holds 19 base frames at 1080p, never fewer than the frames in
    /// flight, and many small ones.
    #[test]
    fn the_budget_is_a_gibibyte_of_base_frames_or_the_frames_in_flight() {
        assert_eq!(frames_held_at_most(8, 1920, 1080), 19);
        assert_eq!(frames_held_at_most(8, 7680, 4320), 8);
        assert_eq!(frames_held_at_most(8, 320, 180), 690);
    }

    /// Base frames made ahead are held until taken, and go with their job.
    #[test]
    fn base_frames_made_ahead_are_held_until_taken_or_their_job_ends() {
        let mut bases = Bases::default();
        let base = || BaseFrame {
            image: vtfarm_imaging::Image::black(2, 1),
            ids: vtfarm_raster::IdBuffer::new(2, 1),
            srgb: Default::default(),
        };
        bases.keep((JobId(1), 8), base());
        bases.keep((JobId(2), 3), base());
        bases.requested((JobId(1), 9), MS, true);
        assert_eq!(bases.held(), 3);
        assert!(bases.take((JobId(2), 3)).is_some());
        assert!(bases.take((JobId(2), 3)).is_none());
        bases.forget(JobId(1));
        assert_eq!(bases.held(), 1, "the one in the making comes back still");
        assert!(!bases.has((JobId(1), 8)));
        assert!(bases.has((JobId(1), 9)));
    }
}
