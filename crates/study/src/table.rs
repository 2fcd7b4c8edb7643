//! The study's result as plain text for the terminal: the ranking, each
//! variant's worst case and where the files went.

use std::fmt::Write as _;
use std::path::Path;

use crate::{Culprit, StudyReport};

impl StudyReport {
    /// The ranking table, each variant's worst frame and the outputs
    /// written to `dir`.
    pub fn table(&self, dir: &Path) -> String {
        let mut t = String::new();
        let _ = writeln!(
            t,
            "{:<24} {:>12} {:>12} {:>14} {:>14}  glare culprit (share of the glare area)",
            "variant (best first)", "glare area", "worst area", "low contrast", "mean Lr cd/m²"
        );
        let culprit = |culprits: &[Culprit]| {
            culprits.first().map_or("none (no glare)".to_owned(), |c| {
                format!("{} ({:.1}%)", c.name, c.glare_share * 100.0)
            })
        };
        for s in &self.ranking {
            let _ = writeln!(
                t,
                "{:<24} {:>11.2}% {:>11.2}% {:>13.2}% {:>14.1}  {}",
                s.variant,
                s.mean_glare_area_share * 100.0,
                s.worst_glare_area_share * 100.0,
                s.worst_low_contrast_share * 100.0,
                s.mean_reflected_luminance_cd_m2,
                culprit(&s.glare_culprits)
            );
        }
        for s in &self.ranking {
            if let Some(w) = s.worst_cases.first() {
                // A frame names its sun only in a sweep.
                let sun = match (w.sun_azimuth_deg, w.sun_elevation_deg) {
                    (Some(a), Some(e)) => format!("sun at azimuth {a:.1}°, elevation {e:.1}°, "),
                    _ => String::new(),
                };
                let _ = writeln!(
                    t,
                    "worst for {}: {sun}eye {}: mean Lr {:.1} cd/m², glare culprit {}",
                    s.variant,
                    w.eye_index,
                    w.mean_reflected_luminance_cd_m2,
                    culprit(&w.glare_culprits)
                );
            }
        }
        for s in &self.ranking {
            let glints: Vec<&crate::FrameRow> = (self.frames.iter())
                .filter(|f| f.variant == s.variant && f.glint.reaches_eye())
                .collect();
            let worst = (glints.iter())
                .filter_map(|f| f.glint.worst_instrument())
                .max_by(|a, b| {
                    a.veiling_luminance_cd_m2
                        .total_cmp(&b.veiling_luminance_cd_m2)
                });
            if let Some(w) = worst {
                let _ = writeln!(
                    t,
                    "sun glint at the eye for {}: {} frame(s), worst veiling luminance {:.0} cd/m² on {} at {:.1}°{}",
                    s.variant,
                    glints.len(),
                    w.veiling_luminance_cd_m2,
                    w.name,
                    w.angle_deg,
                    if w.within_validity {
                        ""
                    } else {
                        " (outside the CIE formula's 1-30°)"
                    }
                );
            }
        }
        if !self.missing_frames.is_empty() {
            let _ = writeln!(
                t,
                "partial: {} frame(s) missing (listed in the report)",
                self.missing_frames.len()
            );
        }
        let _ = write!(
            t,
            "wrote {} frame(s), summary.csv, summary.json and report.html to {}",
            self.frames.len(),
            dir.display()
        );
        t
    }
}
