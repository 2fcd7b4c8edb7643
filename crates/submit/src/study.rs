//! A study as one job on the master: [`run_remote_study`] submits it
//! (`SubmitStudy`, each scene sent when the master asks) or attaches to it
//! by its id, then takes its variants' frames on one connection, in any
//! order, each once; after a lost connection it re-attaches to each variant
//! from the first frame it lacks.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;
use vtfarm_proto::JobId;

use tracing::warn;
use vtfarm_proto::{Message, SceneData, WireJobState, WireStudy};
use vtfarm_transport::Link;
use vtfarm_transport::client::ClientOptions;

use crate::{FinishedFrame, JobError, connect_following, finished_frame, send};

/// What a study run starts from.
pub enum RemoteStudy<'a> {
    /// Submit this study; `scenes` holds every scene its variants name.
    Submit {
        study: WireStudy,
        scenes: &'a [SceneData],
    },
    /// Follow the study the master has under this id.
    Attach { study: JobId },
}

/// What happens while a study runs.
#[derive(Debug)]
pub enum StudyEvent<'a> {
    /// The master has the study: its id and its variants' jobs (id, frames).
    Accepted {
        study: JobId,
        variants: &'a [(JobId, u32)],
    },
    /// A frame of variant `variant` (its index in the study).
    FrameDone {
        variant: usize,
        frame: &'a FinishedFrame,
    },
    /// Something the user should know that does not end the study.
    Warning(String),
    /// A user paused or resumed variant `variant` (its index in the
    /// study), job `job` (`reason` says who).
    StateChanged {
        variant: usize,
        job: JobId,
        state: WireJobState,
        reason: String,
    },
}

/// One variant's frames as they come in.
struct Variant {
    index: usize,
    frames: u32,
    received: BTreeSet<u32>,
}

impl Variant {
    fn first_missing(&self) -> u32 {
        (0..self.frames)
            .find(|f| !self.received.contains(f))
            .unwrap_or(self.frames)
    }

    fn complete(&self) -> bool {
        self.received.len() as u32 >= self.frames
    }
}

/// A study's frames over one connection or several.
#[derive(Default)]
struct StudyFollower {
    study: Option<JobId>,
    /// Its variants' jobs, once accepted.
    variants: Option<BTreeMap<JobId, Variant>>,
}

impl StudyFollower {
    fn complete(&self) -> bool {
        (self.variants.as_ref()).is_some_and(|v| v.values().all(Variant::complete))
    }

    /// Receives until every variant's frames are in (or a variant fails,
    /// the study is cancelled, or the link drops).
    async fn follow(
        &mut self,
        link: &mut Link,
        scenes: &[SceneData],
        attach_variants: bool,
        on_event: &mut impl FnMut(StudyEvent<'_>) -> Result<(), String>,
    ) -> Result<(), JobError> {
        while !self.complete() {
            let Some(message) = link.rx.recv().await else {
                return Err(JobError::Disconnected(link.error()));
            };
            match message {
                Message::SceneRequest { hash } => match scenes.iter().find(|s| s.hash == hash) {
                    Some(scene) => send(link, Message::SceneData(scene.clone()))?,
                    None => return Err(JobError::Protocol("request for an unknown scene".into())),
                },
                Message::StudyAccepted { study, variants } if self.variants.is_none() => {
                    self.study = Some(study);
                    on_event(StudyEvent::Accepted {
                        study,
                        variants: &variants,
                    })
                    .map_err(JobError::Stopped)?;
                    if attach_variants {
                        for &(job, _) in &variants {
                            send(link, Message::AttachJob { job, from_frame: 0 })?;
                        }
                    }
                    let followed = (variants.iter().enumerate())
                        .map(|(index, &(job, frames))| {
                            let received = BTreeSet::new();
                            let variant = Variant {
                                index,
                                frames,
                                received,
                            };
                            (job, variant)
                        })
                        .collect();
                    self.variants = Some(followed);
                }
                Message::StudyAccepted { .. } | Message::Progress { .. } | Message::Heartbeat => {}
                // The answer to attaching to a job that is no study.
                Message::JobAccepted { job, .. } if self.variants.is_none() => {
                    return Err(JobError::Refused(format!(
                        "job {job} is no study (follow it with a job file)"
                    )));
                }
                Message::JobAccepted { .. } => {}
                Message::FrameDone(done) => {
                    let Some(variant) = (self.variants.as_mut()).and_then(|v| v.get_mut(&done.job))
                    else {
                        continue;
                    };
                    if done.frame >= variant.frames || variant.received.contains(&done.frame) {
                        continue;
                    }
                    let finished = finished_frame(done)?;
                    variant.received.insert(finished.frame);
                    let index = variant.index;
                    on_event(StudyEvent::FrameDone {
                        variant: index,
                        frame: &finished,
                    })
                    .map_err(JobError::Stopped)?;
                }
                told @ (Message::FrameMissing { .. } | Message::JournalFailed { .. }) => {
                    if let Some(warning) = crate::warning_of(told)? {
                        on_event(StudyEvent::Warning(warning)).map_err(JobError::Stopped)?;
                    }
                }
                Message::JobFailed { errors, .. } => return Err(JobError::Failed(errors)),
                Message::JobStateChanged { job, state, reason } => {
                    if state == WireJobState::Cancelled {
                        let job = self.study.unwrap_or(job);
                        return Err(JobError::Cancelled { job, reason });
                    }
                    let variant = (self.variants.as_ref())
                        .and_then(|v| v.get(&job))
                        .map(|v| v.index);
                    if let Some(variant) = variant {
                        let event = StudyEvent::StateChanged {
                            variant,
                            job,
                            state,
                            reason,
                        };
                        on_event(event).map_err(JobError::Stopped)?;
                    }
                }
                other => return Err(JobError::Protocol(format!("unexpected {}", other.name()))),
            }
        }
        Ok(())
    }
}

/// Runs a study on the master at `options` until every variant's frames
/// are in, handing each frame to `on_event` once (an error it returns
/// stops the run: [`JobError::Stopped`]); its id. When the
/// connection drops after the master accepted it, it reconnects (as
/// [`crate::run_remote_job`] does) and re-attaches to each variant from
/// the first frame it lacks.
pub async fn run_remote_study(
    options: &ClientOptions,
    start: RemoteStudy<'_>,
    mut on_event: impl FnMut(StudyEvent<'_>) -> Result<(), String>,
) -> Result<JobId, JobError> {
    let (mut submission, scenes, mut follower) = match start {
        RemoteStudy::Submit { study, scenes } => (Some(study), scenes, StudyFollower::default()),
        RemoteStudy::Attach { study } => {
            let follower = StudyFollower {
                study: Some(study),
                variants: None,
            };
            (None, &[][..], follower)
        }
    };
    let mut lost_at: Option<Instant> = None;
    loop {
        let conn = connect_following(options, lost_at).await?;
        let mut link = conn.link;
        let mut attach_variants = false;
        let sent = match (submission.take(), &follower.variants, follower.study) {
            (Some(study), _, _) => send(&link, Message::SubmitStudy { study }),
            (None, Some(variants), _) => (variants.iter())
                .filter(|(_, v)| !v.complete())
                .try_for_each(|(&job, v)| {
                    let from_frame = v.first_missing();
                    send(&link, Message::AttachJob { job, from_frame })
                }),
            (None, None, Some(study)) => {
                attach_variants = true;
                send(
                    &link,
                    Message::AttachJob {
                        job: study,
                        from_frame: 0,
                    },
                )
            }
            (None, None, None) => return Err(JobError::Protocol("no study to attach to".into())),
        };
        let outcome = match sent {
            Ok(()) => (follower.follow(&mut link, scenes, attach_variants, &mut on_event)).await,
            Err(e) => Err(e),
        };
        conn.connection
            .close(vtfarm_transport::CLOSE_NORMAL, b"done");
        conn.endpoint.wait_idle().await;
        match outcome {
            Ok(()) => return Ok(follower.study.unwrap_or_default()),
            Err(JobError::Disconnected(why)) if follower.study.is_some() => {
                let why = why.map(|w| format!(": {w}")).unwrap_or_default();
                warn!("lost the master{why}; reconnecting to follow the study");
                lost_at = Some(Instant::now());
            }
            Err(e) => return Err(e),
        }
    }
}
