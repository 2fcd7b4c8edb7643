//! A progressive frame's stages on the master (the interactive view: one
//! frame per move of the eye, its packages set up once on the workers and
//! advanced `preview` → `refine` → `full`, one result per stage).
//!
//! The frame's image is composited in place, stage by stage: a stage's
//! results go over the base frame as they come while it is the stage being
//! assembled, and a later stage's results (a worker that got ahead) wait
//! until every reflector triangle has delivered the stages before. So when
//! a stage is complete the image is exactly that stage's frame (each
//! package's later results hold only the pixels that changed since its
//! last stage), byte for byte the single-process render at that quality.
//! A result repeated by a second copy of a package (a straggler's copy, or
//! a package requeued after its worker was lost) writes the same values
//! again, so it changes nothing.
//!
//! Per copy of a package (package, worker) the stages must come in order:
//! the next result due is the stage after the copy's last. The scheduler
//! sees the package once, done, with its last stage and the work of all.

use std::collections::BTreeMap;
use std::time::Duration;

use vtfarm_scene::TriangleId;
use vtfarm_vertex::Quality;

use crate::peers::ConnId;

/// Why a result does not fit the stages of its package's frame.
#[derive(Debug, thiserror::Error)]
pub enum StageRejected {
    /// Not the stage the package's copy on this worker is due to send next.
    #[error("a result of stage {found} where stage {expected} is due")]
    OutOfOrder { found: String, expected: String },
}

/// What a copy of a package has done so far (the scheduler hears it once,
/// with its last stage).
#[derive(Clone, Debug, Default)]
pub(crate) struct CopyWork {
    /// The next stage due, an index into the frame's stages.
    next: usize,
    pub(crate) busy: Duration,
    /// Samples per triangle of the package, in package order, over its stages.
    pub(crate) samples: Vec<u64>,
    pub(crate) rays: u64,
    pub(crate) bytes_out: u64,
}

/// One stage's work of a copy, as its result reports it.
pub(crate) struct StageWork<'a> {
    pub(crate) busy: Duration,
    pub(crate) samples: &'a [u32],
    pub(crate) rays: u64,
    pub(crate) bytes_out: u64,
}

/// A progressive frame's stages as its packages deliver them; `P` is a
/// checked result's pixels.
pub(crate) struct StageProgress<P> {
    qualities: Vec<Quality>,
    /// Stages complete so far: the one after them is being composited.
    complete: usize,
    /// The frame's reflector triangles, sorted (indices of `delivered`).
    reflectors: Vec<TriangleId>,
    /// Per reflector triangle, how many stages of its pixels came in.
    delivered: Vec<u8>,
    /// Per stage, how many reflector triangles delivered it.
    counts: Vec<usize>,
    /// Per stage, results that came before the stages before it were complete.
    held: Vec<Vec<P>>,
    copies: BTreeMap<(u64, ConnId), CopyWork>,
}

impl<P> StageProgress<P> {
    /// A frame of `qualities` (more than one, in order) over `reflectors`.
    pub(crate) fn new(qualities: Vec<Quality>, reflectors: &[TriangleId]) -> Self {
        let mut sorted = reflectors.to_vec();
        sorted.sort_unstable();
        let stages = qualities.len();
        StageProgress {
            qualities,
            complete: 0,
            delivered: vec![0; sorted.len()],
            reflectors: sorted,
            counts: vec![0; stages],
            held: (0..stages).map(|_| Vec::new()).collect(),
            copies: BTreeMap::new(),
        }
    }

    /// The stage index of `stage`, a result of `package` from connection
    /// `conn`, if it is the stage that copy is due to send.
    pub(crate) fn check(
        &self,
        package: u64,
        conn: ConnId,
        stage: Option<Quality>,
    ) -> Result<usize, StageRejected> {
        let next = self.copies.get(&(package, conn)).map_or(0, |c| c.next);
        let expected = self.qualities.get(next).copied();
        if stage.is_some() && stage == expected {
            return Ok(next);
        }
        let found = stage.map_or("none (a frame of one stage's)", Quality::name);
        let expected = expected.map_or("none (the package sent all its stages)", Quality::name);
        Err(StageRejected::OutOfOrder {
            found: found.to_owned(),
            expected: expected.to_owned(),
        })
    }

    /// Whether stage `stage` is the frame's last (the one that completes a package).
    pub(crate) fn is_last(&self, stage: usize) -> bool {
        stage + 1 == self.qualities.len()
    }

    /// Adds a checked stage's work to its copy's; the copy's work so far.
    pub(crate) fn record(&mut self, package: u64, conn: ConnId, work: StageWork<'_>) -> &CopyWork {
        let copy = self.copies.entry((package, conn)).or_default();
        copy.next += 1;
        copy.busy += work.busy;
        copy.samples
            .resize(copy.samples.len().max(work.samples.len()), 0);
        for (total, &s) in copy.samples.iter_mut().zip(work.samples) {
            *total += u64::from(s);
        }
        copy.rays += work.rays;
        copy.bytes_out += work.bytes_out;
        copy
    }

    /// A copy of `package` ended (done, failed or lost): its record goes.
    pub(crate) fn forget(&mut self, package: u64) {
        self.copies.retain(|&(p, _), _| p != package);
    }

    /// A copy's record goes (its result was refused: it runs elsewhere).
    pub(crate) fn forget_copy(&mut self, package: u64, conn: ConnId) {
        self.copies.remove(&(package, conn));
    }

    /// Stage `stage`'s checked pixels of `triangles`: composited into
    /// `image` now (`composite`) if it is the stage being assembled, dropped
    /// if it is complete already, else held. Each stage this completes is
    /// told to `completed` with the image as that stage's frame, before the
    /// next stage's held pixels go in.
    pub(crate) fn deliver<I>(
        &mut self,
        stage: usize,
        triangles: &[TriangleId],
        pixels: P,
        image: &mut I,
        composite: impl Fn(&mut I, &P),
        mut completed: impl FnMut(usize, &I),
    ) {
        match stage.cmp(&self.complete) {
            std::cmp::Ordering::Less => {}
            std::cmp::Ordering::Equal => composite(image, &pixels),
            std::cmp::Ordering::Greater => self.held[stage].push(pixels),
        }
        let reached = (stage + 1) as u8;
        for t in triangles {
            let Ok(i) = self.reflectors.binary_search(t) else {
                continue;
            };
            let before = self.delivered[i];
            if reached > before {
                self.delivered[i] = reached;
                for count in &mut self.counts[usize::from(before)..usize::from(reached)] {
                    *count += 1;
                }
            }
        }
        while self.complete < self.qualities.len()
            && self.counts[self.complete] == self.reflectors.len()
        {
            completed(self.complete, image);
            self.complete += 1;
            if let Some(held) = self.held.get_mut(self.complete) {
                for pixels in std::mem::take(held) {
                    composite(image, &pixels);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::view::STAGES;

    /// Pixels as (pixel, value) writes.
    type Writes = Vec<(usize, u32)>;

    /// Delivers `writes` of stage `stage` of `triangles` into `image`;
    /// the stages it completed, each with the image as it was then.
    fn deliver(
        progress: &mut StageProgress<Writes>,
        image: &mut [u32; 4],
        stage: usize,
        triangles: &[u32],
        writes: Writes,
    ) -> Vec<(usize, [u32; 4])> {
        let mut completed = Vec::new();
        let composite = |image: &mut [u32; 4], writes: &Writes| {
            for &(i, v) in writes {
                image[i] = v;
            }
        };
        let triangles: Vec<TriangleId> = triangles.iter().copied().map(TriangleId).collect();
        progress.deliver(
            stage,
            &triangles,
            writes,
            image,
            composite,
            |stage, image| completed.push((stage, *image)),
        );
        completed
    }

    /// Two packages (triangles 1, 2 and 3) on a four-pixel frame; package B
    /// runs ahead: its refine waits until A's preview is in, and each stage
    /// completes with exactly that stage's pixels.
    #[test]
    fn a_later_stage_waits_until_the_one_before_is_complete() {
        let mut progress = StageProgress::new(STAGES.to_vec(), &[3, 1, 2].map(TriangleId));
        let image = &mut [0u32; 4];
        // B (triangle 3, pixels 2 and 3): preview, then refine (held).
        let b_preview = vec![(2, 10), (3, 10)];
        assert_eq!(
            deliver(&mut progress, image, 0, &[3], b_preview.clone()),
            []
        );
        assert_eq!(deliver(&mut progress, image, 1, &[3], vec![(3, 11)]), []);
        assert_eq!(image, &[0, 0, 10, 10]);
        // A (triangles 1 and 2, pixels 0 and 1): its preview completes the
        // preview, shown as it is; B's held refine goes in after it.
        let a_preview = vec![(0, 20), (1, 20)];
        let completed = deliver(&mut progress, image, 0, &[1, 2], a_preview);
        assert_eq!(completed, [(0, [20, 20, 10, 10])]);
        assert_eq!(image, &[20, 20, 10, 11]);
        // A second copy of B repeats its preview: nothing changes.
        assert_eq!(deliver(&mut progress, image, 0, &[3], b_preview), []);
        assert_eq!(image, &[20, 20, 10, 11]);
        let completed = deliver(&mut progress, image, 1, &[1, 2], vec![(0, 21)]);
        assert_eq!(completed, [(1, [21, 20, 10, 11])]);
        assert_eq!(deliver(&mut progress, image, 2, &[1, 2], vec![]), []);
        let completed = deliver(&mut progress, image, 2, &[3], vec![(2, 12)]);
        assert_eq!(completed, [(2, [21, 20, 12, 11])]);
    }

    /// Each copy sends its stages in order; a copy elsewhere starts at the
    /// first; the work adds up over a copy's stages.
    #[test]
    fn each_copy_sends_its_stages_in_order() {
        let mut progress = StageProgress::<()>::new(STAGES.to_vec(), &[1, 2].map(TriangleId));
        let refused = progress.check(7, ConnId(1), Some(Quality::Refine));
        assert_eq!(
            refused.unwrap_err().to_string(),
            "a result of stage refine where stage preview is due"
        );
        assert!(progress.check(7, ConnId(1), None).is_err());
        assert_eq!(
            progress
                .check(7, ConnId(1), Some(Quality::Preview))
                .unwrap(),
            0
        );
        let work = |ms, samples: &'static [u32]| StageWork {
            busy: Duration::from_millis(ms),
            samples,
            rays: samples.iter().map(|&s| u64::from(s)).sum(),
            bytes_out: 100,
        };
        progress.record(7, ConnId(1), work(5, &[3, 4]));
        assert_eq!(
            progress.check(7, ConnId(1), Some(Quality::Refine)).unwrap(),
            1
        );
        assert_eq!(
            progress
                .check(7, ConnId(2), Some(Quality::Preview))
                .unwrap(),
            0
        );
        assert!(
            progress
                .check(7, ConnId(1), Some(Quality::Preview))
                .is_err()
        );
        progress.record(7, ConnId(1), work(7, &[1, 0]));
        let copy = progress.record(7, ConnId(1), work(9, &[2, 2]));
        assert_eq!(copy.busy, Duration::from_millis(21));
        assert_eq!(
            (copy.samples.as_slice(), copy.rays),
            ([6, 6].as_slice(), 12)
        );
        assert_eq!(copy.bytes_out, 300);
        assert!(progress.is_last(2) && !progress.is_last(1));
        assert_eq!(
            progress
                .check(7, ConnId(1), Some(Quality::Full))
                .unwrap_err()
                .to_string(),
            "a result of stage full where stage none (the package sent all its stages) is due"
        );
        progress.forget(7);
        assert_eq!(
            progress
                .check(7, ConnId(1), Some(Quality::Preview))
                .unwrap(),
            0
        );
    }
}
