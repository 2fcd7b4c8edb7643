//! The JSON the dashboard and the API read: the core's state mapped at
//! the HTTP boundary (the core's own types know nothing of serde).

use std::collections::{BTreeMap, BTreeSet};
use vtfarm_proto::JobId;

use serde::{Deserialize, Serialize};
use vtfarm_master_core::telemetry::{FarmCounters, WorkerTotals};
use vtfarm_master_core::view::{CurrentView, ViewOutcome};
use vtfarm_proto::{FrameStats, JobRow, JobSummary, StatusReply};

/// Everything the dashboard shows.
#[derive(Serialize)]
pub struct DashboardView {
    pub status: StatusReply,
    /// Every listed job, oldest first (as `GET /api/jobs`).
    pub jobs: Vec<JobRowView>,
    pub counters: CountersView,
    /// Per worker name: totals and the packages it is working on.
    pub workers: BTreeMap<String, WorkerView>,
    pub live: Option<LiveView>,
    /// The kept finished frames, oldest first.
    pub frames: Vec<FrameView>,
    pub view: ViewState,
}

/// The interactive view, as the page shows it.
#[derive(Serialize)]
pub struct ViewState {
    /// The jobs whose scene the view can start from.
    pub sources: Vec<ViewSourceView>,
    /// Half the side of the box the eye moves in (metres).
    pub eye_box: f32,
    pub current: Option<CurrentViewJson>,
    /// The newest finished stage, shown at `/view/image.png`.
    pub latest: Option<LatestView>,
    /// What happened to the last views' jobs, oldest first.
    pub outcomes: Vec<ViewOutcomeView>,
}

#[derive(Serialize)]
pub struct ViewSourceView {
    pub job: JobId,
    pub name: String,
}

#[derive(Serialize)]
pub struct LatestView {
    pub generation: u64,
    pub quality: &'static str,
    /// `null` until computed, after the stage went on view.
    pub glare: Option<vtfarm_glare::Summary>,
    /// The object map's colour (`#rrggbb`) of each of `glare.objects`, in
    /// their order: the page's legend.
    pub object_colors: Vec<String>,
}

#[derive(Serialize)]
pub struct WorkerView {
    #[serde(flatten)]
    pub totals: WorkerTotalsView,
    pub packages: Vec<u64>,
}

/// The master's cumulative counts ([`FarmCounters`]), as the API shows them.
#[derive(Serialize)]
pub struct CountersView {
    pub jobs_submitted: u64,
    pub jobs_completed: u64,
    pub jobs_failed: u64,
    pub jobs_cancelled: u64,
    pub frames_completed: u64,
    pub packages_done: u64,
    pub packages_failed: u64,
    pub packages_requeued: u64,
    pub packages_duplicated: u64,
    pub journal_write_failures: u64,
    pub frames_rendered_again: u64,
}

impl From<&FarmCounters> for CountersView {
    fn from(c: &FarmCounters) -> Self {
        CountersView {
            jobs_submitted: c.jobs_submitted,
            jobs_completed: c.jobs_completed,
            jobs_failed: c.jobs_failed,
            jobs_cancelled: c.jobs_cancelled,
            frames_completed: c.frames_completed,
            packages_done: c.packages_done,
            packages_failed: c.packages_failed,
            packages_requeued: c.packages_requeued,
            packages_duplicated: c.packages_duplicated,
            journal_write_failures: c.journal_write_failures,
            frames_rendered_again: c.frames_rendered_again,
        }
    }
}

/// A worker's totals ([`WorkerTotals`]), as the API shows them.
#[derive(Serialize)]
pub struct WorkerTotalsView {
    pub samples: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
    pub blocklisted_jobs: BTreeSet<JobId>,
}

impl From<WorkerTotals> for WorkerTotalsView {
    fn from(t: WorkerTotals) -> Self {
        WorkerTotalsView {
            samples: t.samples,
            bytes_in: t.bytes_in,
            bytes_out: t.bytes_out,
            blocklisted_jobs: t.blocklisted_jobs,
        }
    }
}

/// The move being rendered ([`CurrentView`]), as the API shows it.
#[derive(Serialize)]
pub struct CurrentViewJson {
    pub generation: u64,
    pub source: JobId,
    pub offset: [f32; 3],
    pub eye: [f32; 3],
    pub job: JobId,
    pub stages_done: usize,
    pub stages_total: usize,
}

impl From<&CurrentView> for CurrentViewJson {
    fn from(v: &CurrentView) -> Self {
        CurrentViewJson {
            generation: v.generation,
            source: v.source,
            offset: v.offset,
            eye: v.eye,
            job: v.job,
            stages_done: v.stages_done,
            stages_total: v.stages_total,
        }
    }
}

/// What happened to a view's job ([`ViewOutcome`]), as the API shows it.
#[derive(Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum ViewOutcomeView {
    Rendered {
        generation: u64,
        job: JobId,
        quality: &'static str,
    },
    Cancelled {
        generation: u64,
        job: JobId,
    },
}

impl From<ViewOutcome> for ViewOutcomeView {
    fn from(outcome: ViewOutcome) -> Self {
        match outcome {
            ViewOutcome::Rendered {
                generation,
                job,
                quality,
            } => ViewOutcomeView::Rendered {
                generation,
                job,
                quality: quality.name(),
            },
            ViewOutcome::Cancelled { generation, job } => {
                ViewOutcomeView::Cancelled { generation, job }
            }
        }
    }
}

/// A move of the view's eye as the API takes it ([`vtfarm_master_core::view::ViewRequest`]).
#[derive(Deserialize)]
pub(super) struct ViewRequestBody {
    pub(super) job: JobId,
    pub(super) offset: [f32; 3],
    #[serde(default)]
    pub(super) page_draws_scene: bool,
    #[serde(default)]
    pub(super) preview_only: bool,
}

#[derive(Serialize)]
pub struct LiveView {
    pub job: JobId,
    pub frame: u32,
    pub triangles_done: u64,
    pub triangles_total: u64,
}

#[derive(Serialize)]
pub struct FrameView {
    pub seq: u64,
    pub job: JobId,
    pub frame: u32,
    pub stats: FrameStats,
}

/// A row of the jobs as JSON (`GET /api/jobs`, `vtfarm jobs --json`): the
/// job's listing, and a study's `variants` (each a listing) with it.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub struct JobRowView {
    #[serde(flatten)]
    pub job: JobSummary,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variants: Vec<JobSummary>,
}

impl From<JobRow> for JobRowView {
    fn from(row: JobRow) -> Self {
        JobRowView {
            job: row.job,
            variants: row.variants,
        }
    }
}
