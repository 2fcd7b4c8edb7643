//! The order a study's frames render in: coarse to fine, so that a report
//! written early already spans the sun positions and eye points.
//!
//! Each index axis (sun azimuth, sun elevation or time, eye point) is
//! refined by halving: index 0 is level 0, the middle of a power-of-two span
//! level 1, the quarters level 2, and so on (the interleaved order of render
//! farms' frame lists). A frame's band is the coarsest level that contains
//! all its axes, with the eye axis one level behind the sun's: each band
//! first lights every one of its sun positions from the eyes of the band
//! before, so the sun's polar plot fills before the eye points do.

use crate::StudyPlan;

/// The refinement level of index `i` on an axis of `n` indices.
pub fn level(i: usize, n: usize) -> u32 {
    let bits = n.next_power_of_two().trailing_zeros();
    if i == 0 {
        0
    } else {
        bits - i.trailing_zeros().min(bits)
    }
}

impl StudyPlan {
    /// A variant's frame indices ([`StudyPlan::frame_at`]) coarse to fine.
    pub fn frame_order(&self) -> Vec<usize> {
        let (azimuths, elevations) = self.sun_axes();
        let eyes = self.eyes.len();
        let mut keyed: Vec<((u32, u32, u32), usize)> = (0..self.frames_per_variant())
            .map(|frame| {
                let (sun, eye) = self.frame_at(frame);
                let sun = sun.unwrap_or(0);
                let (la, le) = (
                    level(sun % azimuths, azimuths),
                    level(sun / azimuths, elevations),
                );
                let lv = level(eye, eyes);
                let band = la.max(le).max(lv + 1);
                ((band, lv, la + le), frame)
            })
            .collect();
        keyed.sort();
        keyed.into_iter().map(|(_, frame)| frame).collect()
    }

    /// Every frame of the study as (variant, frame), coarse to fine, the
    /// variants taking turns: the order for one job that holds them all.
    pub fn render_order(&self) -> Vec<(usize, usize)> {
        let order = self.frame_order();
        order
            .iter()
            .flat_map(|&frame| (0..self.variants.len()).map(move |v| (v, frame)))
            .collect()
    }

    /// The sun sweep as (azimuth, elevation) index axes: a grid's two, a
    /// time sweep's times on the first; (1, 1) without a sweep.
    fn sun_axes(&self) -> (usize, usize) {
        match self.sun_grid {
            Some((azimuths, elevations)) => (azimuths, elevations),
            None => (self.suns.len().max(1), 1),
        }
    }
}
