//! The submitter's side of the protocol, over any [`Link`]: `vtfarm submit`
//! runs it over QUIC, `vtfarm render` against the embedded master.
//!
//! The job names its scene by hash first; the master asks for the bytes only
//! when it does not have that scene yet.

use vtfarm_imaging::Image;
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    FrameStats, JobScene, Link, Message, SceneData, WireFrameAux, WireFrameSetup, WireImage,
    WireJob,
};
use vtfarm_render::FrameSetup;
use vtfarm_vertex::FrameImage;

/// A finished frame as the submitter receives it.
#[derive(Clone, Debug)]
pub struct FinishedFrame {
    pub frame: u32,
    pub image: Image,
    pub stats: FrameStats,
    /// The colour with the per-pixel components, when the job asked for them.
    pub components: Option<FrameImage>,
}

/// What happens while a job runs, for progress displays.
#[derive(Clone, Debug)]
pub enum JobEvent<'a> {
    Accepted { job: u64, frames: u32 },
    Progress { frame: u32, done: u32, total: u32 },
    FrameDone(&'a FinishedFrame),
}

/// Why a job did not complete.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("the master failed the job:\n  {}", .0.join("\n  "))]
    Failed(Vec<String>),
    #[error("the connection to the master closed{}", .0.as_ref().map(|e| format!(": {e}")).unwrap_or_default())]
    Disconnected(Option<String>),
    #[error("bad answer from the master: {0}")]
    Protocol(String),
}

/// What a job asks the farm for, besides its scene and frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JobOptions {
    /// The reflection method the workers run.
    pub method: MethodKind,
    /// Send the per-pixel components (mask, reflected, transmitted,
    /// reflected object) with each frame.
    pub aux: bool,
}

/// The job message for a scene and its frames.
pub fn wire_job(
    name: &str,
    scene: &SceneData,
    frames: &[FrameSetup],
    reflectors: &[u32],
    options: JobOptions,
) -> WireJob {
    WireJob {
        name: name.to_owned(),
        scene: JobScene::Hash(scene.hash),
        frames: frames.iter().map(WireFrameSetup::from).collect(),
        reflectors: reflectors.to_vec(),
        aux: options.aux,
        method: options.method.into(),
    }
}

/// Submits `job` and waits for all its frames.
pub async fn run_job(
    link: &mut Link,
    job: WireJob,
    scene: &SceneData,
    mut on_event: impl FnMut(JobEvent<'_>),
) -> Result<Vec<FinishedFrame>, JobError> {
    let frames_wanted = job.frames.len();
    let send = |link: &Link, m| {
        link.tx
            .send(m)
            .map_err(|_| JobError::Disconnected(link.error()))
    };
    send(link, Message::SubmitJob { job })?;
    let mut frames = Vec::new();
    while frames.len() < frames_wanted {
        let Some(message) = link.rx.recv().await else {
            return Err(JobError::Disconnected(link.error()));
        };
        match message {
            Message::SceneRequest { hash } if hash == scene.hash => {
                send(link, Message::SceneData(scene.clone()))?
            }
            Message::JobAccepted { job, frames } => on_event(JobEvent::Accepted { job, frames }),
            Message::Progress {
                frame, done, total, ..
            } => on_event(JobEvent::Progress { frame, done, total }),
            Message::FrameDone(done) => {
                let image = image(done.image)?;
                let components = done.aux.map(|aux| components(&image, aux)).transpose()?;
                let finished = FinishedFrame {
                    frame: done.frame,
                    image,
                    stats: done.stats,
                    components,
                };
                on_event(JobEvent::FrameDone(&finished));
                frames.push(finished);
            }
            Message::JobFailed { errors, .. } => return Err(JobError::Failed(errors)),
            Message::Heartbeat => {}
            other => return Err(JobError::Protocol(format!("unexpected {}", other.name()))),
        }
    }
    Ok(frames)
}

fn image(wire: WireImage) -> Result<Image, JobError> {
    let (width, height, pixels) = wire
        .into_pixels()
        .map_err(|e| JobError::Protocol(e.to_string()))?;
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// Rebuilds the frame's components from the wire, checking their sizes.
fn components(color: &Image, aux: WireFrameAux) -> Result<FrameImage, JobError> {
    let n = color.pixels.len();
    let (reflected, transmitted) = (image(aux.reflected)?, image(aux.transmitted)?);
    if reflected.pixels.len() != n
        || transmitted.pixels.len() != n
        || aux.reflected_object.len() != n
        || aux.mask.len() != n
    {
        return Err(JobError::Protocol(
            "frame components of the wrong size".into(),
        ));
    }
    Ok(FrameImage {
        color: color.clone(),
        reflected,
        transmitted,
        reflected_object: aux.reflected_object,
        mask: aux.mask.iter().map(|&m| m != 0).collect(),
    })
}
