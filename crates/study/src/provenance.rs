//! How a study's report was made: the inputs with their hashes (from the
//! plan) and the run (from the caller), written in the report's header and
//! `summary.json` so that an engineer can reproduce what they sign.

use std::path::{Path, PathBuf};

use serde::Serialize;
use sha2::{Digest, Sha256};
use vtfarm_job::SceneSource;
use vtfarm_job::study::{Study, UtcTime};
use vtfarm_vertex::Quality;

use crate::{StudyError, StudyPlan};

/// The hash named in the report for every input file.
pub const HASH: &str = "SHA-256";

/// A file the study read.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InputFile {
    /// "study file", "job file", "scene of variant \"flat\"".
    pub role: String,
    pub path: String,
    /// [`HASH`] of the file's bytes, lower-case hex.
    pub sha256: String,
}

/// The study file, its base job, and every scene file of the base job and
/// the variants (once each; the built-in cockpit has none).
pub(crate) fn input_files(study: &Study) -> Result<Vec<InputFile>, StudyError> {
    let mut files: Vec<(String, PathBuf)> = vec![
        ("study file".into(), study.file.clone()),
        ("job file".into(), study.job.file.clone()),
    ];
    let scene_file = |scene: &SceneSource| match scene {
        SceneSource::Obj(p) | SceneSource::Gltf(p) => Some(p.clone()),
        SceneSource::Cockpit(_) => None,
    };
    if let Some(p) = scene_file(&study.job.scene) {
        files.push(("scene file of the job".into(), p));
    }
    for v in &study.variants {
        match scene_file(&v.scene) {
            Some(p) if !files.iter().any(|(_, f)| *f == p) => {
                files.push((format!("scene file of variant {:?}", v.name), p));
            }
            _ => {}
        }
    }
    files
        .into_iter()
        .map(|(role, path)| {
            Ok(InputFile {
                role,
                path: path.display().to_string(),
                sha256: sha256_of(&path)?,
            })
        })
        .collect()
}

/// [`HASH`] of a file, lower-case hex.
pub(crate) fn sha256_of(path: &Path) -> Result<String, StudyError> {
    let bytes = std::fs::read(path).map_err(|cause| StudyError::Io {
        path: path.to_owned(),
        cause,
    })?;
    Ok(hex::encode(Sha256::digest(&bytes)))
}

/// What the caller knows of the run: the program, when, on what and how.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunInfo {
    /// vtfarm's version with its commit, e.g. `0.1.0 (commit 1a2b3c4d5e6f)`.
    pub version: String,
    /// When the report was written (RFC 3339, UTC).
    pub date: String,
    /// The workers that rendered the frames: "local, 2 workers on 8
    /// threads" or the cluster's worker names.
    pub workers: String,
    /// The command line that made the report.
    pub command: String,
}

impl RunInfo {
    /// This process's run: the date now and its command line.
    pub fn of_this_process(version: &str, workers: String) -> RunInfo {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() as i64);
        RunInfo {
            version: version.to_owned(),
            date: UtcTime { unix_seconds: now }.to_string(),
            workers,
            command: command_line(std::env::args()),
        }
    }
}

/// Arguments joined as a POSIX shell would read them back (single quotes
/// around any argument with characters the shell treats specially).
pub fn command_line(args: impl IntoIterator<Item = String>) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c);
    (args.into_iter())
        .map(|a| {
            if !a.is_empty() && a.chars().all(plain) {
                a
            } else {
                format!("'{}'", a.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// How the report was made, as `summary.json` gives it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Provenance {
    pub vtfarm_version: String,
    pub date: String,
    pub quality: &'static str,
    /// Set when the quality is below `full`: what the figures may lack.
    pub quality_warning: Option<String>,
    pub method: &'static str,
    pub width: u32,
    pub height: u32,
    pub hash: &'static str,
    pub inputs: Vec<InputFile>,
    pub workers: String,
    pub command: String,
}

impl Provenance {
    pub fn new(plan: &StudyPlan, run: &RunInfo) -> Provenance {
        Provenance {
            vtfarm_version: run.version.clone(),
            date: run.date.clone(),
            quality: plan.quality.name(),
            quality_warning: quality_warning(plan.quality),
            method: plan.method.name(),
            width: plan.width,
            height: plan.height,
            hash: HASH,
            inputs: plan.inputs.clone(),
            workers: run.workers.clone(),
            command: run.command.clone(),
        }
    }
}

/// The warning for a quality level below `full`, which samples the
/// reflection more coarsely than the figures were validated at.
pub fn quality_warning(quality: Quality) -> Option<String> {
    (quality < Quality::Full).then(|| {
        format!(
            "quality {:?} is below \"full\": the reflection is sampled more coarsely, so small or sharp reflections (the sun's glint among them) may be missed or misplaced; use \"full\" for figures to sign",
            quality.name()
        )
    })
}
