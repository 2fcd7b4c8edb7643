//! A job as the master renders it: its scene, frames and reflectors, the
//! frames being assembled and those on their way out. A job is checked
//! once, as it is queued ([`Job::checked`]).

use std::collections::BTreeSet;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use vtfarm_proto::JobId;

use vtfarm_method::{MethodKind, reflector_groups};
use vtfarm_proto::{
    FrameStart, SceneHash, WireFrameAux, WireFrameSetup, WireImage, WireImageFormat, WireJob,
    check_triangle_ids, wire_triangles,
};
use vtfarm_render::{BaseExtent, FrameSetup, morton_order, reflector_flags};
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_scheduler::FrameWork;
use vtfarm_vertex::Quality;

use super::assembly::FrameAssembly;
use super::base::{BaseFrame, BaseFrameRequest};
use super::finish::FinishQueue;
use crate::error::{JobRejected, ResultRejected};
use crate::peers::ConnId;

pub(crate) struct Job {
    pub(crate) name: String,
    /// The submitters following the job: each gets every frame. Empty
    /// while none is attached (lost, or not back after a restart): a
    /// persistent master renders it on, journaling its frames.
    pub(crate) submitters: BTreeSet<ConnId>,
    /// Frames before this one were finished before a restart: they are
    /// journaled, and the scheduler's empty stand-ins for them are skipped.
    pub(crate) resume_from: u32,
    /// Frames finished so far (resumed ones included).
    pub(crate) frames_done: u32,
    pub(crate) scene: Arc<Scene>,
    pub(crate) scene_hash: SceneHash,
    pub(crate) reflectors: Vec<TriangleId>,
    /// [`reflector_flags`] of `reflectors`.
    pub(crate) is_reflector: Arc<[bool]>,
    /// Whether its base frames' glass that is no reflector was warned about.
    pub(crate) warned_glass: Arc<AtomicBool>,
    pub(crate) frames: Vec<FrameSetup>,
    /// Send the per-pixel components with each frame.
    pub(crate) aux: bool,
    /// How finished frames travel (and are journaled).
    pub(crate) image: WireImageFormat,
    pub(crate) method: MethodKind,
    /// For per-reflector methods, the reflector groups the work items
    /// index; `None` when the items are the reflector triangles themselves.
    pub(crate) groups: Option<Vec<Vec<TriangleId>>>,
    /// The frames being assembled, oldest first (two while pipelined).
    pub(crate) assembling: Vec<FrameAssembly>,
    /// A progressive job's stages (the interactive view's moves), in
    /// order; empty for one stage at each frame's quality.
    pub(crate) stages: Vec<Quality>,
    /// How much of each frame its base frame covers: only what its
    /// packages look at for a view whose page draws the scene itself.
    pub(crate) base_extent: BaseExtent,
    /// Finished frames on their way out, and the job's end after them.
    pub(crate) finishing: FinishQueue,
}

impl Job {
    /// The request for frame `job`/`frame`'s base frame (its set-up must
    /// exist), into `spare`'s buffers where given; converted to sRGB ahead
    /// when the job's frames go out so (`finish.rs`).
    pub(crate) fn base_request(
        &self,
        job: JobId,
        frame: u32,
        spare: Option<BaseFrame>,
    ) -> BaseFrameRequest {
        BaseFrameRequest {
            job,
            frame,
            scene: self.scene.clone(),
            is_reflector: self.is_reflector.clone(),
            warned_glass: self.warned_glass.clone(),
            setup: self.frames[frame as usize].clone(),
            srgb: self.image == WireImageFormat::Srgb8,
            extent: self.base_extent,
            spare: spare.map(Box::new),
        }
    }

    /// The frame `frame` if it is being assembled.
    pub(crate) fn assembly(&self, frame: u32) -> Option<&FrameAssembly> {
        self.assembling.iter().find(|a| a.start.frame == frame)
    }

    pub(crate) fn assembly_mut(&mut self, frame: u32) -> Option<&mut FrameAssembly> {
        self.assembling.iter_mut().find(|a| a.start.frame == frame)
    }

    /// The reflector triangles that work `items` cover, sorted: the
    /// triangles whose pixels the package's result may write.
    pub(crate) fn triangles_in(&self, items: &[u32]) -> Vec<TriangleId> {
        let mut triangles: Vec<TriangleId> = match &self.groups {
            Some(groups) => (items.iter())
                .filter_map(|&g| groups.get(g as usize))
                .flatten()
                .copied()
                .collect(),
            None => items.iter().copied().map(TriangleId).collect(),
        };
        triangles.sort_unstable();
        triangles
    }

    /// The index of the next frame to start: frames start and complete in
    /// order.
    pub(crate) fn next_to_start(&self) -> u32 {
        let assembling = self.assembling.iter().map(|a| a.start.frame + 1).max();
        let finishing = self.finishing.last_frame().map(|f| f + 1);
        (assembling.max(finishing)).unwrap_or(self.frames_done)
    }

    /// Frame `frame`'s start as the workers get it (its set-up must exist).
    pub(crate) fn frame_start(&self, job: JobId, frame: u32) -> FrameStart {
        FrameStart {
            job,
            frame,
            scene: self.scene_hash,
            setup: WireFrameSetup::from(&self.frames[frame as usize]),
            reflectors: wire_triangles(&self.reflectors),
            method: self.method.into(),
            aux: self.aux,
            image: self.image,
            stages: self.stages.iter().map(|&q| q.into()).collect(),
        }
    }

    /// Checks a job whose scene is `scene` (`job` names it by hash): the
    /// job and its frames' work for the scheduler, frames before
    /// `resume_from` being finished already (they get no work).
    pub(crate) fn checked(
        job: WireJob,
        scene: Arc<Scene>,
        scene_hash: SceneHash,
        submitters: BTreeSet<ConnId>,
        resume_from: u32,
    ) -> Result<(Job, Vec<FrameWork>), JobRejected> {
        let reflectors = check_triangle_ids("reflectors", &job.reflectors, scene.triangles.len())
            .map_err(JobRejected::BadReflectors)?;
        if reflectors.is_empty() || job.frames.is_empty() {
            return Err(JobRejected::Empty);
        }
        if job.aux && job.image != WireImageFormat::LinearF32 {
            return Err(JobRejected::ComponentsNeedLinearFrames);
        }
        let frames: Result<Vec<FrameSetup>, _> =
            job.frames.into_iter().map(FrameSetup::try_from).collect();
        let frames = frames.map_err(JobRejected::BadFrame)?;
        let reflectors = morton_order(&scene, reflectors);
        let method = MethodKind::from(job.method);
        // Per-reflector methods take whole reflectors: their work items are
        // reflector groups, which the workers derive from the same list.
        let groups = (method.per_reflector()).then(|| reflector_groups(&scene, &reflectors));
        let items: Vec<u32> = match &groups {
            Some(groups) => (0..groups.len() as u32).collect(),
            None => wire_triangles(&reflectors),
        };
        // Finished frames get no work: the scheduler completes them at once.
        let work = (0..frames.len() as u32)
            .map(|f| FrameWork {
                items: if f < resume_from {
                    Vec::new()
                } else {
                    items.clone()
                },
            })
            .collect();
        let is_reflector = reflector_flags(&scene, &reflectors).into();
        let job = Job {
            name: job.name,
            submitters,
            resume_from,
            frames_done: resume_from,
            scene,
            scene_hash,
            reflectors,
            is_reflector,
            warned_glass: Arc::default(),
            frames,
            aux: job.aux,
            image: job.image,
            method,
            groups,
            assembling: Vec::new(),
            stages: Vec::new(),
            base_extent: BaseExtent::Whole,
            finishing: FinishQueue::default(),
        };
        Ok((job, work))
    }

    /// Checks a whole frame's finished image (and components) against what
    /// the job asks for: the frame's size, the job's format, components
    /// when the job asks for them, linear and of the frame's size. The
    /// compressed bytes themselves are the submitter's to decode: its
    /// decoder decompresses into exactly the size the sides imply.
    pub(crate) fn check_finished(
        &self,
        frame: u32,
        image: WireImage,
        aux: Option<WireFrameAux>,
    ) -> Result<(WireImage, Option<WireFrameAux>), ResultRejected> {
        let job = self;
        let camera = job.frames.get(frame as usize).map(|setup| setup.camera);
        let expected = camera.map_or((0, 0), |c| (c.width, c.height));
        let mismatch = |what, found: String, expected: String| {
            Err(ResultRejected::FinishedFrameMismatch {
                what,
                found,
                expected,
            })
        };
        let size = |image: &WireImage| (image.width, image.height);
        let show = |(w, h): (u32, u32)| format!("{w}x{h}");
        if size(&image) != expected {
            return mismatch("size", show(size(&image)), show(expected));
        }
        if image.format != job.image {
            return mismatch(
                "format",
                format!("{:?}", image.format),
                format!("{:?}", job.image),
            );
        }
        match &aux {
            Some(_) if !job.aux => return mismatch("components", "sent".into(), "none".into()),
            None if job.aux => return mismatch("components", "none".into(), "asked for".into()),
            Some(aux) => {
                for component in [&aux.reflected, &aux.transmitted] {
                    if size(component) != expected || component.format != WireImageFormat::LinearF32
                    {
                        let found = format!("{} {:?}", show(size(component)), component.format);
                        let wanted = format!("{} LinearF32", show(expected));
                        return mismatch("component image", found, wanted);
                    }
                }
            }
            None => {}
        }
        Ok((image, aux))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testkit;

    fn checked(job: WireJob, resume_from: u32) -> Result<(Job, Vec<FrameWork>), JobRejected> {
        let (_, scene, hash) = testkit::job(1);
        Job::checked(job, scene, hash, BTreeSet::new(), resume_from)
    }

    /// A job is checked once, as queued: reflectors in the scene, some
    /// frames, components only with linear frames.
    #[test]
    fn a_job_without_reflectors_or_with_components_in_srgb_is_rejected() {
        let (mut job, _, _) = testkit::job(2);
        job.reflectors = vec![2];
        assert!(matches!(
            checked(job, 0),
            Err(JobRejected::BadReflectors(_))
        ));
        let (mut job, _, _) = testkit::job(2);
        job.reflectors.clear();
        assert!(matches!(checked(job, 0), Err(JobRejected::Empty)));
        let (mut job, _, _) = testkit::job(2);
        (job.aux, job.image) = (true, WireImageFormat::Srgb8);
        let rejected = checked(job, 0).err();
        assert!(matches!(
            rejected,
            Some(JobRejected::ComponentsNeedLinearFrames)
        ));
    }

    /// Frames finished before a restart get no work; the others every
    /// reflector. Frames start in order from the first unfinished one.
    #[test]
    fn a_resumed_job_has_work_only_from_its_first_unfinished_frame() {
        let (job, _, _) = testkit::job(3);
        let (job, work) = checked(job, 1).unwrap();
        let items: Vec<usize> = work.iter().map(|w| w.items.len()).collect();
        assert_eq!(items, [0, 2, 2]);
        assert_eq!(job.next_to_start(), 1);
        assert_eq!(job.triangles_in(&[1, 0]), [0, 1].map(TriangleId));
        assert_eq!(job.frame_start(JobId(7), 2).frame, 2);
    }

    /// A whole frame's finished image must be the frame's size and the
    /// job's format.
    #[test]
    fn a_whole_frame_of_another_size_or_format_is_refused() {
        let (job, _) = checked(testkit::job(1).0, 0).unwrap();
        let side = testkit::SIDE;
        let image = |w, format| WireImage::encode(&vtfarm_imaging::Image::black(w, side), format);
        assert!(job.check_finished(0, image(side, job.image), None).is_ok());
        let small = job.check_finished(0, image(side - 1, job.image), None);
        assert!(matches!(
            small,
            Err(ResultRejected::FinishedFrameMismatch { what: "size", .. })
        ));
        let srgb = job.check_finished(0, image(side, WireImageFormat::Srgb8), None);
        assert!(matches!(
            srgb,
            Err(ResultRejected::FinishedFrameMismatch { what: "format", .. })
        ));
    }
}
