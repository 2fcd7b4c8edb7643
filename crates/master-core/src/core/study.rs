//! Studies: a study is one listed job over its variants, each a job of
//! its own (a variant is one scene). Submitting one (its scenes asked for
//! first), attaching to one, the controls on all its variants at once, and
//! a study read back from the journal. Its state follows its variants'
//! (`jobs::study_state`).

use std::collections::BTreeSet;
use std::time::Duration;

use tracing::{info, warn};
use vtfarm_proto::{JobAction, JobRow, JobScene, Message, SceneData, WireJobKind, WireStudy};
use vtfarm_scheduler::JobId;

use crate::jobs::{JobControlError, JobEntry, JobState};
use crate::peers::ConnId;

use super::MasterCore;

impl MasterCore {
    /// A submitted study: queued once the master has every variant's scene
    /// (it asks for each one it lacks, once).
    pub(super) fn submit_study(&mut self, now: Duration, conn: ConnId, study: WireStudy) {
        let missing: BTreeSet<_> = (study.variants.iter())
            .filter_map(|v| match &v.scene {
                JobScene::Hash(hash) if !self.scenes.contains_key(hash) => Some(*hash),
                _ => None,
            })
            .collect();
        if missing.is_empty() {
            return self.queue_study(now, conn, study);
        }
        for &hash in &missing {
            self.send(conn, Message::SceneRequest { hash });
        }
        self.awaiting_scenes.insert(conn, (study, missing));
    }

    /// A scene a study waits for: it goes with the first variant that
    /// names it; the study is queued with the last.
    pub(super) fn study_scene(&mut self, now: Duration, conn: ConnId, data: SceneData) {
        let Some((study, missing)) = self.awaiting_scenes.get_mut(&conn) else {
            return;
        };
        if !missing.remove(&data.hash) {
            return self.close(conn, "scene data nobody asked for".into());
        }
        let hash = data.hash;
        if let Some(variant) = (study.variants.iter_mut()).find(|v| v.scene == JobScene::Hash(hash))
        {
            variant.scene = JobScene::Data(data);
        }
        if missing.is_empty() {
            let (study, _) = self.awaiting_scenes.remove(&conn).expect("looked up above");
            self.queue_study(now, conn, study);
        }
    }

    /// Queues every variant of `study` as a job followed by `conn` and
    /// lists the study over them. A variant the master refuses cancels the
    /// ones queued before it: the study is listed cancelled with why.
    fn queue_study(&mut self, now: Duration, conn: ConnId, study: WireStudy) {
        if study.variants.is_empty() {
            return self.refuse_job(conn, "a study without variants".into());
        }
        let host = self.peers.submitter_host(conn);
        let id = self.next_job;
        self.next_job.0 += 1;
        let frames = study.variants.iter().map(|v| v.frames.len() as u32).sum();
        let entry = JobEntry {
            id,
            name: crate::jobs::listed_name(&study.name),
            kind: WireJobKind::Study,
            state: JobState::Queued,
            priority: study.priority,
            frames_done: 0,
            frames_total: frames,
            submitted_ms: self.wall_ms(now),
            started_ms: None,
            finished_ms: None,
            host: host.clone(),
            reason: String::new(),
            study: None,
            variants: Vec::new(),
        };
        let mut variants = Vec::new();
        let mut refused = None;
        for mut variant in study.variants {
            variant.kind = WireJobKind::Variant;
            variant.priority = study.priority;
            let frames = variant.frames.len() as u32;
            let name = variant.name.clone();
            match self.accept_job(now, BTreeSet::from([conn]), host.clone(), variant) {
                Ok(job) => variants.push((job, frames)),
                Err(e) => {
                    refused = Some(format!("variant {name:?}: {e}"));
                    break;
                }
            }
        }
        let ids: Vec<JobId> = variants.iter().map(|&(job, _)| job).collect();
        self.table.insert_study(entry, &ids);
        info!(study = %id, variants = ids.len(), frames, "study queued");
        if let Some(error) = refused {
            warn!(study = %id, "study refused: {error}");
            if let Some(entry) = self.table.get_mut(id) {
                entry.reason = format!("study {id} was refused: {error}");
            }
            for &job in &ids {
                let reason = format!("its study {id} was refused: {error}");
                self.cancel_reasons.insert(job, reason);
                let _ = self.scheduler.cancel_job(now, job);
            }
            self.persist_study(id);
            return self.refuse_job(conn, error);
        }
        self.persist_study(id);
        self.send(
            conn,
            Message::StudyAccepted {
                study: id,
                variants,
            },
        );
    }

    /// Study `id`'s variants with their frame counts; `None` when `id` is
    /// no study.
    pub(super) fn study_variants(&self, id: JobId) -> Option<Vec<(JobId, u32)>> {
        let entry = self.table.get(id).filter(|e| e.is_study())?;
        let variants = (entry.variants.iter())
            .filter_map(|&v| self.table.get(v))
            .map(|v| (v.id, v.frames_total))
            .collect();
        Some(variants)
    }

    /// [`MasterCore::control_job`] of a study: the action, if it applies to
    /// the study's state, on each variant it applies to.
    pub(super) fn control_study(
        &mut self,
        now: Duration,
        id: JobId,
        action: JobAction,
        who: &str,
    ) -> Result<(), JobControlError> {
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        Self::applies(id, entry.state, &action)?;
        let variants: Vec<(JobId, JobState, bool)> = (entry.variants.iter())
            .filter_map(|&v| self.table.get(v))
            .map(|v| (v.id, v.state, v.frames_done < v.frames_total))
            .collect();
        info!(
            study = %id,
            by = who,
            action = action.command(),
            "controlling the study"
        );
        match action {
            JobAction::Cancel => {
                let reason = format!("study {id} was cancelled by {who}");
                if let Some(entry) = self.table.get_mut(id) {
                    entry.reason = reason.clone();
                }
                for &(job, state, _) in &variants {
                    if !state.is_finished() {
                        self.cancel_reasons.insert(job, reason.clone());
                    }
                }
            }
            JobAction::Requeue { failed_only } => {
                let again: Vec<JobId> = (variants.iter())
                    .filter(|&&(_, state, unfinished)| {
                        state.is_finished() && (!failed_only || unfinished)
                    })
                    .map(|&(job, _, _)| job)
                    .collect();
                if again.is_empty() {
                    return Err(JobControlError::NothingToRequeue(id));
                }
                // Queued again itself: its state follows its variants' from here.
                let at = self.wall_ms(now);
                let _ = self.table.set_state(id, JobState::Queued, at);
                if let Some(entry) = self.table.get_mut(id) {
                    entry.started_ms = None;
                }
                for job in again {
                    self.control_one(now, job, action, who)?;
                }
                self.table.refresh_study(id, at);
                self.persist_study(id);
                return Ok(());
            }
            JobAction::SetPriority(priority) => {
                if let Some(entry) = self.table.get_mut(id) {
                    entry.priority = priority;
                }
                self.persist_study(id);
            }
            JobAction::Pause | JobAction::Resume => {}
        }
        for (job, state, _) in variants {
            if Self::applies(job, state, &action).is_ok() {
                self.control_one(now, job, action, who)?;
            }
        }
        Ok(())
    }

    /// Lists a journaled study over its variants restored before it (at
    /// start): its state follows theirs.
    pub fn restore_study(&mut self, now: Duration, row: JobRow) {
        self.now = now;
        let id = row.job.id;
        self.next_job = self.next_job.max(JobId(id.0 + 1));
        let variants: Vec<JobId> = row.variants.iter().map(|v| v.id).collect();
        let entry = JobEntry::from_summary(row.job);
        self.table.insert_study(entry, &variants);
        if self.table.refresh_study(id, self.wall_ms(now)) {
            self.persist_study(id);
        }
        info!(
            study = %id,
            variants = variants.len(),
            "study restored from the journal"
        );
    }
}
