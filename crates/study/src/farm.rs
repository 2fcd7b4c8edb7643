//! A study as farm jobs: every variant is one job whose frames are its sun
//! positions times its eye points, sent coarse to fine
//! ([`StudyPlan::frame_order`]), so the farm balances the study frame by
//! frame and the workers keep the variant's scene and BVH for all of them
//! (a sun position changes only the lighting). The embedded farm runs the
//! variants one after the other; a cluster takes them as one study
//! ([`wire_study`]).

use vtfarm_proto::{JobId, JobOptions, SceneData, WireJob, WireJobKind, WireStudy, wire_job};
use vtfarm_vertex::FrameImage;

use crate::{StudyError, StudyPlan, StudyWriter};

/// The job of variant `v`: its frames in `order` (the plan's
/// [`StudyPlan::frame_order`]), components kept for measuring; its scene.
pub fn variant_job(plan: &StudyPlan, v: usize, order: &[usize]) -> (WireJob, SceneData) {
    let variant = &plan.variants[v];
    let data = SceneData::from_scene(&variant.scene);
    let name = format!("{} / {}", plan.name, variant.name);
    let options = JobOptions {
        method: plan.method,
        aux: true,
    };
    let setups: Vec<_> = order.iter().map(|&f| variant.setups[f].clone()).collect();
    let job = WireJob {
        kind: WireJobKind::Study,
        ..wire_job(&name, &data, &setups, &variant.reflectors, options)
    };
    (job, data)
}

/// The study as one farm job with `priority`, and the scenes its variants
/// name (each once).
pub fn wire_study(plan: &StudyPlan, priority: i32) -> (WireStudy, Vec<SceneData>) {
    let order = plan.frame_order();
    let mut scenes: Vec<SceneData> = Vec::new();
    let variants = (0..plan.variants.len())
        .map(|v| {
            let (job, data) = variant_job(plan, v, &order);
            if !scenes.iter().any(|s| s.hash == data.hash) {
                scenes.push(data);
            }
            job
        })
        .collect();
    let study = WireStudy {
        name: plan.name.clone(),
        priority,
        variants,
    };
    (study, scenes)
}

impl StudyPlan {
    /// Checks that the master's study `study`, whose variants have `has`
    /// frames each, is the one this plan makes (a study followed again by
    /// its id must be followed with the file it was submitted from).
    pub fn check_variant_frames(&self, study: JobId, has: &[u32]) -> Result<(), StudyError> {
        let planned: Vec<u32> = (self.variants.iter())
            .map(|v| v.setups.len() as u32)
            .collect();
        if has == planned {
            return Ok(());
        }
        Err(StudyError::OtherStudy {
            study,
            has: has.to_vec(),
            file: self.file.clone(),
            planned,
        })
    }
}

impl StudyWriter<'_> {
    /// Measures and writes frame `sent` of variant `v` as the farm sent it
    /// (its number in the variant's job: `order` maps it back to the
    /// plan's frame), with its colour and components; the line that says
    /// so, with the frame's mean reflected luminance.
    pub fn sent_frame(
        &mut self,
        (v, sent): (usize, u32),
        order: &[usize],
        components: Option<&FrameImage>,
    ) -> Result<String, StudyError> {
        let Some(&at) = order.get(sent as usize) else {
            return Err(StudyError::Frame {
                variant: v,
                eye: 0,
                why: format!("the master sent frame {sent}, beyond the variant's frames"),
            });
        };
        let plan = self.plan;
        let (name, eye) = (plan.frame_name(at), plan.frame_at(at).1);
        let Some(components) = components else {
            return Err(StudyError::Frame {
                variant: v,
                eye,
                why: "the master sent no components".into(),
            });
        };
        let mean = self.frame(v, at, components)?;
        let mean = mean.summary.mean_reflected_luminance_cd_m2;
        Ok(format!(
            "{} {name}: mean reflected luminance {mean:.1} cd/m²",
            plan.variants[v].name
        ))
    }
}
