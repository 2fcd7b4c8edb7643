//! Which frames a worker keeps: the one rule both ends of a worker's
//! session follow, so the master knows, from the messages it sent alone,
//! whether a worker still has a frame's `FrameStart` (announced, being set
//! up or prepared) and sends it again only when not.
//!
//! The rule: a worker keeps the [`FRAMES_IN_FLIGHT`] frames the master
//! named to it last, in a `FrameStart` or a `Package` (a frame named again
//! is the newest again). The worker may keep more for a while (the frame
//! of a package in hand stays until the package is done), never less; the
//! master's copy of the list, fed the same messages in the same order
//! (one link, in order), is so never ahead of the worker.

use std::collections::VecDeque;

use crate::{FRAMES_IN_FLIGHT, JobId, Message};

/// A frame: its job and its index in the job.
pub type FrameKey = (JobId, u32);

/// The frames last named to one worker, newest last, at most
/// [`FRAMES_IN_FLIGHT`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct KeptFrames {
    newest_last: VecDeque<FrameKey>,
}

impl KeptFrames {
    /// Whether frame `key` is among those kept.
    pub fn contains(&self, key: FrameKey) -> bool {
        self.newest_last.contains(&key)
    }

    /// The frame a message from the master names (a `FrameStart`'s or a
    /// `Package`'s), if any.
    pub fn named_by(message: &Message) -> Option<FrameKey> {
        match message {
            Message::FrameStart(start) => Some((start.job, start.frame)),
            Message::Package(package) => Some((package.job, package.frame)),
            _ => None,
        }
    }

    /// `message` went from the master to the worker: the frame it names is
    /// the newest now. Answers the frame that so fell out of the list.
    pub fn saw(&mut self, message: &Message) -> Option<FrameKey> {
        let key = Self::named_by(message)?;
        self.newest_last.retain(|&k| k != key);
        self.newest_last.push_back(key);
        if self.newest_last.len() > FRAMES_IN_FLIGHT {
            return self.newest_last.pop_front();
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Package;

    fn package(job: JobId, frame: u32) -> Message {
        Message::Package(Package {
            id: 1,
            job,
            frame,
            triangles: vec![0],
            whole: None,
        })
    }

    #[test]
    fn the_frames_named_last_are_kept_and_naming_one_again_renews_it() {
        let mut kept = KeptFrames::default();
        assert_eq!(kept.saw(&Message::Heartbeat), None);
        let frames = FRAMES_IN_FLIGHT as u32;
        for frame in 0..frames {
            assert_eq!(kept.saw(&package(JobId(1), frame)), None);
        }
        // Frame 0 named again: frame 1 is now the oldest and goes first.
        assert_eq!(kept.saw(&package(JobId(1), 0)), None);
        assert_eq!(kept.saw(&package(JobId(2), 0)), Some((JobId(1), 1)));
        assert_eq!(kept.saw(&package(JobId(2), 1)), Some((JobId(1), 2)));
        assert!(kept.contains((JobId(1), 0)) && kept.contains((JobId(2), 1)));
        assert!(!kept.contains((JobId(1), 1)) && !kept.contains((JobId(1), 2)));
        assert_eq!(kept.newest_last.len(), FRAMES_IN_FLIGHT);
    }
}
