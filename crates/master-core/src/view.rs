//! The interactive view (the dashboard's "move the eye"): the user picks a
//! job's scene and moves the eye within a box around that job's eye; each
//! move becomes a small farm job of its own, one progressive frame whose
//! stages are the same view at rising quality (`preview`, `refine`,
//! `full`): the master rasterizes its base frame once, each worker sets its
//! packages up once and sends each stage's pixels as they are ready, and
//! the master composites each stage in place (`stages.rs`), so the view
//! sharpens in place. A move cancels the previous move's job, whatever
//! stage it was at: only the newest eye is ever rendered to the end.
//!
//! Plain bookkeeping: the core owns a [`Views`], queues and cancels the jobs
//! and hands finished stages in. The glare figures of a stage
//! (`vtfarm-glare`: reflected luminance, veiling ratio, reflected objects)
//! are no part of showing it: the core asks the driver for them
//! ([`GlareRequest`], `Output::ViewGlare`) once the stage is on view, and
//! they join it when they come, unless a newer stage is on view by then
//! (only the stage shown gets figures). No I/O, no clock.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;
use vtfarm_proto::JobId;

use glam::Vec3;
use vtfarm_imaging::Image;
use vtfarm_method::MethodKind;
use vtfarm_proto::{JobScene, SceneHash, WireError, WireFrameSetup, WireJob, WireMesh};
use vtfarm_render::FrameSetup;
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_vertex::{FrameImage, Quality, StageMesh};

use crate::stream::{Overlay, StageHeader, encode_mesh, encode_overlay};

/// Half the side of the box the eye moves in, in metres, around the picked
/// job's eye (each axis is clamped to it). About a driver's head movement.
pub const EYE_BOX: f32 = 0.15;

/// The stages a move of the eye goes through, in order (a per-reflector
/// method has none: its one frame is `full`).
pub const STAGES: [Quality; 3] = [Quality::Preview, Quality::Refine, Quality::Full];

/// How many submitted jobs' scenes stay pickable for the view.
pub const KEPT_SOURCES: usize = 8;

/// How many view outcomes (finished stages, cancellations) are kept.
const KEPT_OUTCOMES: usize = 64;

/// A submitted job the view can start from: its scene and first frame.
#[derive(Clone, Debug)]
pub struct ViewSource {
    pub name: String,
    pub scene_hash: SceneHash,
    pub scene: Arc<Scene>,
    pub reflectors: Vec<TriangleId>,
    pub method: MethodKind,
    pub setup: FrameSetup,
}

/// A move of the eye: which job's view, and the eye's offset from that
/// job's eye in metres (world axes; clamped to [`EYE_BOX`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewRequest {
    pub job: JobId,
    pub offset: [f32; 3],
    /// Whether the page draws the scene itself (WebGL2): then the move's
    /// frame needs the master's base frame only where its packages look,
    /// not the whole of it, which only the page without WebGL2 shows.
    pub page_draws_scene: bool,
    /// Whether the page shows only the move's preview (a dragging hand's
    /// move): its frame is cancelled once the preview is out, so the farm
    /// traces nothing the hand has already left behind.
    pub preview_only: bool,
}

/// Why a move was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ViewError {
    #[error("job {0} is not among the scenes the master keeps for the view")]
    UnknownSource(JobId),
    #[error("the eye offset must be finite")]
    BadOffset,
    #[error("cannot queue the view: {0}")]
    Queue(String),
}

/// What happened to a view's job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewOutcome {
    /// A stage finished.
    Rendered {
        generation: u64,
        job: JobId,
        quality: Quality,
    },
    /// A newer move cancelled the job (its later stages never ran).
    Cancelled { generation: u64, job: JobId },
}

/// The move being rendered.
#[derive(Clone, Debug)]
pub struct CurrentView {
    /// Moves so far, this one included.
    pub generation: u64,
    /// The job whose scene and eye the view starts from.
    pub source: JobId,
    /// The eye's offset after clamping.
    pub offset: [f32; 3],
    pub eye: [f32; 3],
    /// The farm job rendering this move.
    pub job: JobId,
    /// The qualities its frames render, in order.
    stages: Vec<Quality>,
    /// Stages finished so far.
    pub stages_done: usize,
    pub stages_total: usize,
    /// Stages whose messages went out ([`Views::stream`]): the preview's
    /// may go before the stage finishes ([`Views::corner_mesh_arrived`]).
    streamed: usize,
    /// Only the preview is wanted ([`ViewRequest::preview_only`]).
    preview_only: bool,
    /// Its job was cancelled once the preview went out
    /// ([`Views::take_ended_at_preview`]).
    ended_at_preview: bool,
}

/// A finished stage of a view, with its glare figures once computed.
#[derive(Clone, Debug)]
pub struct ViewFrame {
    pub generation: u64,
    pub quality: Quality,
    /// The stage's frame: its colour ([`ViewFrame::image`]) and components.
    pub frame: Arc<FrameImage>,
    /// Its glare figures, computed after it went on view.
    pub figures: Option<Arc<ViewFigures>>,
}

impl ViewFrame {
    /// The stage's image.
    pub fn image(&self) -> &Image {
        &self.frame.color
    }
}

/// A view stage's glare figures.
#[derive(Clone, Debug)]
pub struct ViewFigures {
    /// The reflected-object map, the frame alone
    /// (`vtfarm_glare::object_map_frame`): the page draws its legend from
    /// the figures' objects, in the same rank order.
    pub object_map: Image,
    pub glare: vtfarm_glare::Summary,
}

/// The glare figures of a stage on view, to compute off the driver's task
/// ([`GlareRequest::compute`]) and hand to `MasterCore::view_figures_ready`.
#[derive(Clone, Debug)]
pub struct GlareRequest {
    pub generation: u64,
    pub quality: Quality,
    frame: Arc<FrameImage>,
    scene: Arc<Scene>,
}

impl GlareRequest {
    /// The stage's reflected-object map and glare summary.
    pub fn compute(&self) -> ViewFigures {
        let (object_map, glare) = glare_of(&self.frame, &self.scene);
        ViewFigures { object_map, glare }
    }
}

/// The view's state, owned by the core.
#[derive(Debug, Default)]
pub struct Views {
    sources: VecDeque<(JobId, ViewSource)>,
    current: Option<CurrentView>,
    /// The newest finished stage (of this move or, until it has one, of an
    /// earlier move).
    latest: Option<ViewFrame>,
    /// Figures to ask the driver for (the newest stage's).
    glare_wanted: Option<GlareRequest>,
    /// A stage's frame no longer on view nor used by anyone, kept to copy
    /// the next stage into: a 1080p frame copied into fresh buffers costs
    /// their page faults too, on the way to the screen.
    spare: Option<FrameImage>,
    outcomes: VecDeque<ViewOutcome>,
    /// The current move's meshes by (stage, reflector triangle) until
    /// their stage is complete: a repeated copy's mesh replaces the same.
    meshes: BTreeMap<(usize, TriangleId), StageMesh>,
    /// The current move's stage messages, in order.
    stream: StageStream,
}

/// The stage messages of the move on view ([`crate::stream`]), each
/// encoded once; a newer move starts an empty list, so nothing of an
/// outdated move is streamed after it.
#[derive(Clone, Debug, Default)]
pub struct StageStream {
    /// The move (0 before the first).
    pub generation: u64,
    /// When the core queued the move.
    moved: Duration,
    pub messages: Vec<StreamedStage>,
}

impl StageStream {
    /// Stage `quality`'s message, made at `now`.
    fn push(&mut self, quality: Quality, bytes: Vec<u8>, now: Duration) {
        let after = now.saturating_sub(self.moved);
        let bytes = bytes.into();
        (self.messages).push(StreamedStage {
            quality,
            bytes,
            after,
        });
    }
}

/// Why a worker's corner mesh was not streamed.
#[derive(Debug, thiserror::Error)]
pub enum CornerMeshRefused {
    #[error(transparent)]
    Wire(#[from] WireError),
    #[error("it has {parts} parts for the view's {reflectors} reflector triangles")]
    NotTheReflectors { parts: usize, reflectors: usize },
}

/// One stage message and its stage.
#[derive(Clone, Debug)]
pub struct StreamedStage {
    pub quality: Quality,
    pub bytes: Arc<[u8]>,
    /// From the move's arrival to the message's making: the server's part
    /// of the stage (`vtfarm bench view`).
    pub after: Duration,
}

impl Views {
    /// Keeps a submitted job's scene pickable (the newest [`KEPT_SOURCES`]).
    pub fn remember(&mut self, job: JobId, source: ViewSource) {
        if self.sources.len() == KEPT_SOURCES {
            self.sources.pop_front();
        }
        self.sources.push_back((job, source));
    }

    /// The pickable jobs: id and name, oldest first.
    pub fn sources(&self) -> impl Iterator<Item = (JobId, &str)> {
        self.sources.iter().map(|(id, s)| (*id, s.name.as_str()))
    }

    /// The kept source `job`, or without one the current move's source,
    /// else the newest kept.
    pub fn source(&self, job: Option<JobId>) -> Option<(JobId, &ViewSource)> {
        let job = job.or(self.current.as_ref().map(|c| c.source));
        let found = match job {
            Some(job) => self.sources.iter().find(|(id, _)| *id == job),
            None => self.sources.back(),
        };
        found.map(|(id, s)| (*id, s))
    }

    /// The job a move should be rendered as, checked: one frame, at the
    /// last stage's quality (the workers' progressive packages take it
    /// through every stage, [`PlannedView::stages`]).
    pub(crate) fn plan(&self, request: &ViewRequest) -> Result<PlannedView, ViewError> {
        if !request.offset.iter().all(|v| v.is_finite()) {
            return Err(ViewError::BadOffset);
        }
        let (_, source) = (self.sources.iter())
            .find(|(id, _)| *id == request.job)
            .ok_or(ViewError::UnknownSource(request.job))?;
        let offset = Vec3::from(request.offset).clamp(Vec3::splat(-EYE_BOX), Vec3::splat(EYE_BOX));
        let mut setup = source.setup.clone();
        // The eye moves; the gaze stays on the same point (the driver keeps
        // looking at the instruments).
        setup.camera.eye += offset;
        // Per-reflector methods have no quality levels: one frame.
        let stages = if source.method.per_reflector() {
            vec![Quality::Full]
        } else {
            STAGES.to_vec()
        };
        setup.vertex.quality = *stages.last().expect("a view has a stage");
        let frames = vec![WireFrameSetup::from(&setup)];
        let job = WireJob {
            name: format!("view of job {}", request.job),
            scene: JobScene::Hash(source.scene_hash),
            frames,
            reflectors: vtfarm_proto::wire_triangles(&source.reflectors),
            // The workers send the reflected and transmitted components
            // and the reflected objects: the glare figures need them.
            aux: true,
            method: source.method.into(),
            image: vtfarm_proto::WireImageFormat::LinearF32,
            // Each move of the eye goes before every other job.
            priority: i32::MAX,
            kind: vtfarm_proto::WireJobKind::View,
        };
        Ok(PlannedView {
            job,
            source: request.job,
            offset: offset.to_array(),
            eye: setup.camera.eye.to_array(),
            // A move of one stage has no preview of its own to end at.
            preview_only: request.preview_only && stages.len() > 1,
            stages,
        })
    }

    /// The farm job of the move being rendered, if it still runs.
    pub(crate) fn running_job(&self) -> Option<JobId> {
        (self.current.as_ref())
            .filter(|c| c.stages_done < c.stages_total && !c.ended_at_preview)
            .map(|c| c.job)
    }

    /// The planned move is queued as farm job `job`.
    pub(crate) fn started(&mut self, planned: PlannedView, job: JobId, now: Duration) {
        let generation = self.current.as_ref().map_or(0, |c| c.generation) + 1;
        self.meshes.clear();
        self.stream = StageStream {
            generation,
            moved: now,
            messages: Vec::new(),
        };
        self.current = Some(CurrentView {
            generation,
            source: planned.source,
            offset: planned.offset,
            eye: planned.eye,
            job,
            stages_total: planned.stages.len(),
            stages: planned.stages,
            stages_done: 0,
            streamed: 0,
            preview_only: planned.preview_only,
            ended_at_preview: false,
        });
    }

    /// The farm job of a move that wanted only its preview, once that went
    /// out and while the job still runs: the job to cancel. Asked once:
    /// the move then counts as ended at its preview.
    pub(crate) fn take_ended_at_preview(&mut self) -> Option<JobId> {
        let job = self.running_job()?;
        let c = (self.current.as_mut()).filter(|c| c.preview_only && c.streamed >= 1)?;
        c.ended_at_preview = true;
        let generation = c.generation;
        self.record(ViewOutcome::Cancelled { generation, job });
        Some(job)
    }

    /// Whether farm job `job` renders a view (view jobs are not journaled).
    pub fn owns(&self, job: JobId) -> bool {
        self.current.as_ref().is_some_and(|c| c.job == job)
            || self.outcomes.iter().any(|o| match *o {
                ViewOutcome::Rendered { job: j, .. } | ViewOutcome::Cancelled { job: j, .. } => {
                    j == job
                }
            })
    }

    /// Stages up to `stage` (an index into the move's stages) of some job's
    /// frame are complete, `image` the last of them: if it is the current
    /// move's, each stage's message goes out (unless it went ahead) and is
    /// recorded, and the last stage's image becomes the view, with its
    /// glare figures (the stages before it carry meshes, no pixels).
    pub(crate) fn stage_finished(
        &mut self,
        job: JobId,
        stage: usize,
        image: &FrameImage,
        scene: &Arc<Scene>,
        now: Duration,
    ) {
        let Some(current) = self.current.as_mut().filter(|c| c.job == job) else {
            return;
        };
        let Some(&quality) = current.stages.get(stage) else {
            return;
        };
        let reached = (current.stages_done..=stage).map(|s| current.stages[s]);
        let reached: Vec<Quality> = reached.collect();
        let first = current.stages_done;
        current.stages_done = stage + 1;
        let generation = current.generation;
        let eye = Vec3::from(current.eye);
        for (s, &quality) in (first..).zip(&reached) {
            if s < current.streamed {
                continue;
            }
            current.streamed = s + 1;
            let header = StageHeader {
                generation,
                quality,
                eye,
            };
            let bytes = if quality < Quality::Full {
                let meshes: Vec<StageMesh> = (self
                    .meshes
                    .range((s, TriangleId(0))..=(s, TriangleId(u32::MAX))))
                .map(|(_, m)| m.clone())
                .collect();
                encode_mesh(&header, &meshes)
            } else {
                encode_overlay(&header, &Overlay::of(image))
            };
            self.meshes.retain(|&(m, _), _| m > s);
            self.stream.push(quality, bytes, now);
        }
        let records = reached.into_iter().map(|quality| ViewOutcome::Rendered {
            generation,
            job,
            quality,
        });
        let records: Vec<ViewOutcome> = records.collect();
        // The stages before the last carry meshes, no pixels: only the
        // last has an image to show and figures.
        let pixels = stage + 1 == current.stages.len();
        if pixels {
            self.show(generation, quality, image, scene);
        }
        for outcome in records {
            self.record(outcome);
        }
    }

    /// The move's frame goes on view (a copy), and its figures are asked for.
    fn show(&mut self, generation: u64, quality: Quality, image: &FrameImage, scene: &Arc<Scene>) {
        let frame = Arc::new(match self.spare.take() {
            Some(mut spare) => {
                spare.clone_from(image);
                spare
            }
            None => image.clone(),
        });
        self.glare_wanted = Some(GlareRequest {
            generation,
            quality,
            frame: frame.clone(),
            scene: scene.clone(),
        });
        let shown = ViewFrame {
            generation,
            quality,
            frame,
            figures: None,
        };
        if let Some(before) = self.latest.replace(shown) {
            // Unless its figures are still being computed.
            self.spare = Arc::try_unwrap(before.frame).ok();
        }
    }

    /// A checked result of stage `stage` of farm job `job` brought its
    /// package's meshes: kept for the stage's message if the job is the
    /// current move's and the stage still to come. Only the parts of
    /// `triangles` (the package's, sorted) count.
    pub(crate) fn mesh_arrived(
        &mut self,
        job: JobId,
        stage: usize,
        triangles: &[TriangleId],
        mesh: &WireMesh,
    ) -> Result<(), WireError> {
        let Some(current) = self.current.as_ref().filter(|c| c.job == job) else {
            return Ok(());
        };
        if stage < current.streamed {
            return Ok(());
        }
        for part in mesh.decode()? {
            if triangles.binary_search(&part.triangle).is_ok() {
                self.meshes.insert((stage, part.triangle), part);
            }
        }
        Ok(())
    }

    /// A worker's corner mesh of frame `frame` of farm job `job`
    /// (`Message::FrameMesh`): if it is the current move's, whose preview
    /// has not gone out, and has one part for each of the view's reflector
    /// triangles, it goes out at once as the move's `preview` message; the
    /// stage's results then only make its image. A mesh of an older move
    /// (or a second worker's) is dropped.
    pub(crate) fn corner_mesh_arrived(
        &mut self,
        job: JobId,
        frame: u32,
        mesh: &WireMesh,
        now: Duration,
    ) -> Result<(), CornerMeshRefused> {
        let Some(current) = self.current.as_mut().filter(|c| c.job == job && frame == 0) else {
            return Ok(());
        };
        if current.streamed > 0 || current.stages.first() != Some(&Quality::Preview) {
            return Ok(());
        }
        let source = (self.sources.iter()).find(|(id, _)| *id == current.source);
        let Some((_, source)) = source else {
            return Ok(());
        };
        let meshes = mesh.decode()?;
        let mut covered: Vec<TriangleId> = meshes.iter().map(|m| m.triangle).collect();
        covered.sort_unstable();
        let mut reflectors = source.reflectors.clone();
        reflectors.sort_unstable();
        reflectors.dedup();
        if covered != reflectors {
            return Err(CornerMeshRefused::NotTheReflectors {
                parts: covered.len(),
                reflectors: reflectors.len(),
            });
        }
        current.streamed = 1;
        let header = StageHeader {
            generation: current.generation,
            quality: Quality::Preview,
            eye: Vec3::from(current.eye),
        };
        self.meshes.retain(|&(s, _), _| s > 0);
        self.stream
            .push(Quality::Preview, encode_mesh(&header, &meshes), now);
        Ok(())
    }

    /// The stage messages of the move on view, so far.
    pub fn stream(&self) -> &StageStream {
        &self.stream
    }

    /// A newer move cancelled the current move's job.
    pub(crate) fn superseded(&mut self) {
        if let Some(c) = &self.current {
            let (generation, job) = (c.generation, c.job);
            self.record(ViewOutcome::Cancelled { generation, job });
        }
    }

    /// The figures to compute for the stage just put on view, once.
    pub(crate) fn take_glare_request(&mut self) -> Option<GlareRequest> {
        self.glare_wanted.take()
    }

    /// A stage's figures came: they join it if it is still the one on view.
    pub(crate) fn figures_ready(
        &mut self,
        generation: u64,
        quality: Quality,
        figures: ViewFigures,
    ) {
        if let Some(latest) =
            (self.latest.as_mut()).filter(|l| (l.generation, l.quality) == (generation, quality))
        {
            latest.figures = Some(Arc::new(figures));
        }
    }

    fn record(&mut self, outcome: ViewOutcome) {
        if self.outcomes.len() == KEPT_OUTCOMES {
            self.outcomes.pop_front();
        }
        self.outcomes.push_back(outcome);
    }

    pub fn current(&self) -> Option<&CurrentView> {
        self.current.as_ref()
    }

    pub fn latest(&self) -> Option<&ViewFrame> {
        self.latest.as_ref()
    }

    /// What happened to the views' jobs, oldest first (the last 64).
    pub fn outcomes(&self) -> impl Iterator<Item = &ViewOutcome> {
        self.outcomes.iter()
    }
}

/// A move checked and turned into a job, not yet queued.
pub(crate) struct PlannedView {
    pub(crate) job: WireJob,
    source: JobId,
    offset: [f32; 3],
    eye: [f32; 3],
    stages: Vec<Quality>,
    preview_only: bool,
}

impl PlannedView {
    /// The qualities its frame goes through, in order.
    pub(crate) fn stages(&self) -> &[Quality] {
        &self.stages
    }
}

/// The reflected-object map and the glare summary of a composited frame.
/// Without a study there are no instrument or marking masks, so the
/// contrast figures stay empty; reflection, veiling and objects are there.
fn glare_of(image: &FrameImage, scene: &Scene) -> (Image, vtfarm_glare::Summary) {
    let components = image.components();
    let none = vec![false; components.mask.len()];
    let names: Vec<String> = scene.objects.iter().map(|o| o.name.clone()).collect();
    let input = vtfarm_glare::GlareInput::from_components(&components, &none, &none, &names);
    let params = vtfarm_glare::Params::default();
    // The frame's buffers are all width × height and the parameters are the
    // defaults, so neither call can fail.
    let analysis =
        vtfarm_glare::analyze(&input, &params).expect("a composited frame is consistent");
    let (map, _) =
        vtfarm_glare::object_map_frame(&input, &params).expect("a composited frame is consistent");
    (map, analysis.summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_raster::PixelRect;

    /// A view rendering job 7 in the three stages, as `started` leaves it.
    fn rendering() -> Views {
        Views {
            current: Some(moving(1, JobId(7), STAGES.to_vec())),
            ..Views::default()
        }
    }

    /// Move `generation` rendered as farm job `job` in `stages`.
    fn moving(generation: u64, job: JobId, stages: Vec<Quality>) -> CurrentView {
        CurrentView {
            generation,
            source: JobId(1),
            offset: [0.0; 3],
            eye: [0.0; 3],
            job,
            stages_total: stages.len(),
            stages,
            stages_done: 0,
            streamed: 0,
            preview_only: false,
            ended_at_preview: false,
        }
    }

    /// A 6x4 frame in `shade`, its components over a 3x2 rectangle.
    fn frame(shade: f32) -> FrameImage {
        let bounds = PixelRect {
            x0: 1,
            y0: 1,
            x1: 4,
            y1: 3,
        };
        FrameImage::new(Image::new(6, 4, Vec3::splat(shade)), bounds)
    }

    /// Only a move's last stage goes on view (the stages before it carry
    /// meshes, no pixels), and each is recorded. Each frame on view is a
    /// copy of the stage's frame as it was; a frame nobody uses any more is
    /// copied into, not allocated afresh, and one whose figures are still
    /// being computed is left be.
    #[test]
    fn moves_on_view_are_copies_into_the_buffers_of_one_no_longer_used() {
        let scene = Arc::new(Scene::default());
        let mut views = rendering();
        let address = |views: &Views| views.latest().unwrap().image().pixels.as_ptr();
        let shade = |views: &Views| views.latest().unwrap().image().pixels[0];

        views.stage_finished(JobId(7), 0, &frame(0.1), &scene, Duration::ZERO);
        views.stage_finished(JobId(7), 1, &frame(0.2), &scene, Duration::ZERO);
        assert!(views.latest().is_none(), "a mesh stage has no image");
        assert!(views.take_glare_request().is_none());
        views.stage_finished(JobId(7), 2, &frame(0.25), &scene, Duration::ZERO);
        let first = address(&views);
        assert_eq!(shade(&views), Vec3::splat(0.25));
        let rendered = |g| ViewOutcome::Rendered {
            generation: g,
            job: JobId(7),
            quality: Quality::Full,
        };
        assert_eq!(views.outcomes().count(), 3);
        assert_eq!(views.outcomes().last(), Some(&rendered(1)));
        // The first move's figures are computed and done with.
        drop(views.take_glare_request());
        views.current = Some(moving(2, JobId(8), vec![Quality::Full]));
        views.stage_finished(JobId(8), 0, &frame(0.5), &scene, Duration::ZERO);
        assert_ne!(address(&views), first, "the first move is still on view");
        // The second move's figures are still being computed.
        let computing = views.take_glare_request().unwrap();
        views.current = Some(moving(3, JobId(9), vec![Quality::Full]));
        views.stage_finished(JobId(9), 0, &frame(0.75), &scene, Duration::ZERO);
        assert_eq!(address(&views), first, "into the first move's buffers");
        assert_eq!(shade(&views), Vec3::splat(0.75));
        assert_eq!(
            views.latest().unwrap().frame.components(),
            frame(0.75).components()
        );
        assert!(
            views.spare.is_none(),
            "the second move's frame is still in use"
        );
        assert_eq!(computing.generation, 2);
        assert_eq!(computing.frame.color.pixels[0], Vec3::splat(0.5));
    }

    /// [`rendering`] with job 1 as its source, reflector triangles 3 and 5.
    fn rendering_with_source() -> Views {
        let source = ViewSource {
            name: "source".into(),
            scene_hash: [0; 32],
            scene: Arc::new(Scene::default()),
            reflectors: vec![TriangleId(5), TriangleId(3)],
            method: MethodKind::VertexTracing,
            setup: FrameSetup {
                camera: vtfarm_scene::Camera {
                    eye: Vec3::ZERO,
                    target: Vec3::Z,
                    up: Vec3::Y,
                    fov_y_deg: 60.0,
                    width: 8,
                    height: 8,
                },
                lighting: Default::default(),
                trace: Default::default(),
                vertex: Default::default(),
            },
        };
        let mut views = rendering();
        views.sources.push_back((JobId(1), source));
        views
    }

    /// A corner mesh with a part for each of `triangles`.
    fn corners(triangles: &[u32]) -> WireMesh {
        let meshes: Vec<StageMesh> = (triangles.iter())
            .map(|&triangle| StageMesh {
                triangle: TriangleId(triangle),
                positions: vec![Vec3::X, Vec3::Y, Vec3::Z],
                samples: vec![
                    vtfarm_vertex::PixelValue {
                        index: 0,
                        color: Vec3::ONE,
                        reflected: Vec3::ONE,
                        transmitted: Vec3::ZERO,
                        object: 2,
                    };
                    3
                ],
                slabs: vec![vtfarm_vertex::SlabWeights::OPAQUE; 3],
                faces: vec![[0, 1, 2]],
            })
            .collect();
        WireMesh::from(&meshes[..])
    }

    /// The current move's corner mesh goes out at once as its preview, once;
    /// one of another job or that misses a reflector triangle does not; the
    /// preview stage's end sends nothing more, the refine its own message.
    #[test]
    fn the_moves_corner_mesh_is_its_preview_message_once() {
        let scene = Arc::new(Scene::default());
        let mut views = rendering_with_source();
        let qualities = |views: &Views| -> Vec<Quality> {
            (views.stream().messages.iter())
                .map(|m| m.quality)
                .collect()
        };
        let ms = Duration::from_millis;
        views
            .corner_mesh_arrived(JobId(8), 0, &corners(&[3, 5]), ms(1))
            .unwrap();
        assert_eq!(qualities(&views), []);
        let refused = views.corner_mesh_arrived(JobId(7), 0, &corners(&[3]), ms(2));
        assert!(
            matches!(
                refused,
                Err(CornerMeshRefused::NotTheReflectors {
                    parts: 1,
                    reflectors: 2
                })
            ),
            "{refused:?}"
        );
        assert_eq!(qualities(&views), []);
        views
            .corner_mesh_arrived(JobId(7), 0, &corners(&[5, 3]), ms(3))
            .unwrap();
        assert_eq!(qualities(&views), [Quality::Preview]);
        assert_eq!(views.stream().messages[0].after, ms(3));
        let decoded = crate::stream::decode(&views.stream().messages[0].bytes).unwrap();
        assert_eq!(decoded.header().generation, 1);
        // A second worker's mesh.
        views
            .corner_mesh_arrived(JobId(7), 0, &corners(&[3, 5]), ms(4))
            .unwrap();
        views.stage_finished(JobId(7), 0, &frame(0.25), &scene, ms(5));
        assert_eq!(qualities(&views), [Quality::Preview]);
        views.stage_finished(JobId(7), 1, &frame(0.5), &scene, ms(6));
        assert_eq!(qualities(&views), [Quality::Preview, Quality::Refine]);
    }
}
