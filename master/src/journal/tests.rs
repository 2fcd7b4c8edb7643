//! The journal's records and directories tested on a temporary disk.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_proto::{FrameStats, WireImage};
use vtfarm_render::FrameSetup;
use vtfarm_scene::{Camera, Scene, TriangleId};

use super::*;

fn frame_done(job: u64, frame: u32) -> Record {
    Record::FrameDone(Box::new(FrameDone {
        job: JobId(job),
        frame,
        image: WireImage::from_pixels(1, 1, &[Vec3::splat(frame as f32)]),
        stats: FrameStats::default(),
        aux: None,
    }))
}

/// A job of `frames` one-pixel frames of the empty scene, and its scene.
fn one_pixel_job(frames: usize) -> (Arc<SceneData>, vtfarm_proto::WireJob) {
    let scene = Arc::new(SceneData::from_scene(&Scene::default()));
    let setup = FrameSetup {
        camera: Camera {
            eye: Vec3::ZERO,
            target: Vec3::Z,
            up: Vec3::Y,
            fov_y_deg: 60.0,
            width: 1,
            height: 1,
        },
        lighting: Default::default(),
        trace: Default::default(),
        vertex: Default::default(),
    };
    let options = vtfarm_proto::JobOptions {
        method: vtfarm_method::MethodKind::VertexTracing,
        aux: false,
    };
    let job = vtfarm_proto::wire_job("j", &scene, &vec![setup; frames], &[TriangleId(0)], options);
    (scene, job)
}

#[test]
fn a_job_reads_back_up_to_its_first_missing_frame_and_goes_with_its_scene() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    let (scene, job) = one_pixel_job(3);
    journal
        .write(Record::JobQueued {
            id: JobId(4),
            job: Box::new(job.clone()),
            scene: scene.clone(),
        })
        .unwrap();
    journal.write(frame_done(4, 0)).unwrap();
    journal.write(frame_done(4, 2)).unwrap();
    let stored = journal.load().jobs;
    assert_eq!(stored.len(), 1);
    assert_eq!(
        (stored[0].id, stored[0].frames_done, stored[0].complete),
        (JobId(4), 1, false)
    );
    assert_eq!(stored[0].job.scene, JobScene::Data((*scene).clone()));
    assert_eq!(stored[0].job.frames, job.frames);
    assert_eq!(journal.frame(JobId(4), 2).unwrap().frame, 2);

    journal
        .write(Record::JobForgotten { id: JobId(4) })
        .unwrap();
    assert!(journal.load().jobs.is_empty());
    assert!(journal.frame(JobId(4), 0).is_err());
    let scenes = std::fs::read_dir(dir.path().join("jobs/scenes")).unwrap();
    assert_eq!(scenes.count(), 0, "the scene went with its last job");
}

/// The writer thread keeps the records' order (a job's directory
/// before its frames, its removal after them), and a flush makes
/// everything sent before it readable.
#[test]
fn the_writer_thread_keeps_the_order_and_a_flush_makes_records_readable() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    let (report, reports) = std::sync::mpsc::channel();
    let writer = JournalWriter::new(journal.clone(), move |written| {
        let _ = report.send(written);
    });
    // No JobQueued: the frames need the job's directory, made here.
    std::fs::create_dir_all(journal.job_dir(JobId(3))).unwrap();
    for frame in 0..20 {
        writer.write(frame_done(3, frame));
    }
    writer.flush();
    for frame in 0..20 {
        assert_eq!(
            journal.frame(JobId(3), frame).map(|d| d.frame).ok(),
            Some(frame)
        );
        let written = reports.try_recv().expect("a report per record");
        assert_eq!((written.frame, written.outcome), (Some(frame), Ok(())));
    }
    writer.write(frame_done(3, 20));
    writer.write(Record::JobForgotten { id: JobId(3) });
    writer.write(frame_done(3, 21));
    drop(writer);
    // Removed after frame 20; frame 21 then finds no directory, and
    // the writer says so.
    assert!(journal.frame(JobId(3), 20).is_err());
    assert!(journal.frame(JobId(3), 21).is_err());
    let outcomes: Vec<_> = reports
        .try_iter()
        .map(|w| (w.frame, w.outcome.is_ok()))
        .collect();
    assert_eq!(
        outcomes,
        [(Some(20), true), (None, true), (Some(21), false)]
    );
}

#[test]
fn a_frame_is_kept_compressed_and_reads_back_bit_for_bit() {
    let c = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
        detail: 0.3,
        ..Default::default()
    });
    let camera = Camera {
        width: 160,
        height: 90,
        ..c.camera
    };
    let (image, _) = vtfarm_raster::rasterize(&c.scene, &camera, &c.lighting);
    let done = FrameDone {
        job: JobId(7),
        frame: 3,
        image: WireImage::from_pixels(160, 90, &image.pixels),
        stats: FrameStats::default(),
        aux: None,
    };
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    std::fs::create_dir_all(journal.job_dir(JobId(7))).unwrap();
    journal
        .write(Record::FrameDone(Box::new(done.clone())))
        .unwrap();
    assert_eq!(journal.frame(JobId(7), 3).unwrap(), done);
    let raw = 160 * 90 * 12;
    let kept = std::fs::metadata(journal.frame_path(JobId(7), 3))
        .unwrap()
        .len();
    assert!(kept * 3 < raw, "{kept} bytes for a {raw}-byte frame");
}

/// A journal an older master wrote (format 1: no `format` file, frames
/// compressed whole) or one of an unknown format is refused with an
/// error that names it; an empty or current one opens.
#[test]
fn a_journal_of_another_format_is_refused_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    Journal::open(dir.path()).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.path().join("jobs/format")).unwrap(),
        format!("{JOURNAL_FORMAT}\n")
    );
    Journal::open(dir.path()).expect("the current format opens again");

    let old = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(old.path().join("jobs/000000000001")).unwrap();
    let error = Journal::open(old.path()).expect_err("format 1").to_string();
    assert!(
        error.contains("format 1, but this master reads format 5"),
        "{error}"
    );
    assert!(
        error.contains(&old.path().join("jobs").display().to_string()),
        "{error}"
    );

    // Format 3's jobs carry no priority or kind: they do not decode here.
    std::fs::write(old.path().join("jobs/format"), "3\n").unwrap();
    let error = Journal::open(old.path()).expect_err("format 3").to_string();
    assert!(
        error.contains("format 3, but this master reads format 5"),
        "{error}"
    );
    assert!(
        error.contains("finish its jobs with the master that wrote it"),
        "{error}"
    );

    std::fs::write(old.path().join("jobs/format"), "7\n").unwrap();
    let error = Journal::open(old.path()).expect_err("format 7").to_string();
    assert!(error.contains("format 7"), "{error}");
}

/// Every job state, its priority and times read back as written; the
/// newest listing replaces the one before; a damaged listing is set
/// aside with the job listed as queued, and a job without one has none.
#[test]
fn every_job_state_round_trips_through_the_journal() {
    use vtfarm_proto::{JobSummary, WireJobKind, WireJobState};
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    let (scene, job) = one_pixel_job(1);
    let states = WireJobState::ALL;
    let summary = |id: u64, state: WireJobState| JobSummary {
        id: JobId(id),
        name: format!("job {id}"),
        kind: [WireJobKind::Render, WireJobKind::Study][id as usize % 2],
        state,
        priority: id as i32 - 3,
        frames_done: 0,
        frames_failed: 0,
        frames_cancelled: 0,
        frames_total: 1,
        submitted_ms: 1_000 * id,
        started_ms: (id > 1).then_some(2_000 * id),
        finished_ms: (id > 3).then_some(3_000 * id),
        host: "10.0.0.9:4000".into(),
        reason: format!("why {id}"),
    };
    for (id, &state) in (1..).zip(&states) {
        let queued = Record::JobQueued {
            id: JobId(id),
            job: Box::new(job.clone()),
            scene: scene.clone(),
        };
        journal.write(queued).unwrap();
        // An older listing first: the newest wins.
        let older = summary(id, WireJobState::Queued);
        journal.write(Record::JobState(Box::new(older))).unwrap();
        journal
            .write(Record::JobState(Box::new(summary(id, state))))
            .unwrap();
    }
    let loaded = journal.load();
    assert!(loaded.damaged.is_empty(), "{:?}", loaded.damaged);
    let read: Vec<Option<JobSummary>> = loaded.jobs.into_iter().map(|j| j.summary).collect();
    let written: Vec<Option<JobSummary>> = (1..)
        .zip(&states)
        .map(|(id, &state)| Some(summary(id, state)))
        .collect();
    assert_eq!(read, written);

    flip_listing(&journal.state_path(JobId(2)));
    std::fs::remove_file(journal.state_path(JobId(3))).unwrap();
    let jobs = journal.load().jobs;
    assert_eq!((jobs[1].id, &jobs[1].summary), (JobId(2), &None));
    assert_eq!((jobs[2].id, &jobs[2].summary), (JobId(3), &None));
    assert!(
        journal
            .state_path(JobId(2))
            .with_extension("damaged")
            .exists()
    );
}

fn flip_listing(path: &Path) {
    let mut bytes = std::fs::read(path).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x5a;
    std::fs::write(path, bytes).unwrap();
}

/// Every kind of damage to a frame record is an error naming the file
/// and the check, never a frame: a flipped byte anywhere, a truncated,
/// an emptied, a missing file, another frame's file in its place.
#[test]
fn a_damaged_frame_record_is_an_error_naming_the_file_and_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    std::fs::create_dir_all(journal.job_dir(JobId(1))).unwrap();
    journal.write(frame_done(1, 0)).unwrap();
    journal.write(frame_done(1, 1)).unwrap();
    let path = journal.frame_path(JobId(1), 0);
    let good = std::fs::read(&path).unwrap();
    let check = |bytes: &[u8], needle: &str| {
        std::fs::write(&path, bytes).unwrap();
        let error = journal.frame(JobId(1), 0).expect_err("damaged").to_string();
        assert!(error.contains(&path.display().to_string()), "{error}");
        assert!(error.contains(needle), "{error}");
    };
    for at in 0..good.len() {
        let mut flipped = good.clone();
        flipped[at] ^= 0x10;
        check(&flipped, "checksum mismatch");
    }
    check(&good[..good.len() - 1], "checksum mismatch");
    check(&good[..2], "too short");
    check(b"", "too short");
    std::fs::copy(journal.frame_path(JobId(1), 1), &path).unwrap();
    check(&std::fs::read(&path).unwrap(), "it holds frame 1 of job 1");
    // A valid frame of another job in this job's directory.
    std::fs::create_dir_all(journal.job_dir(JobId(2))).unwrap();
    journal.write(frame_done(2, 0)).unwrap();
    std::fs::copy(journal.frame_path(JobId(2), 0), &path).unwrap();
    check(
        &std::fs::read(&path).unwrap(),
        "it holds a record of job 2, not of job 1",
    );
    // The job's completion marker in a frame's place.
    journal.write(Record::JobComplete { id: JobId(1) }).unwrap();
    std::fs::copy(journal.complete_path(JobId(1)), &path).unwrap();
    check(&std::fs::read(&path).unwrap(), "it holds a complete record");
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(
        journal.frame(JobId(1), 0),
        Err(RecordError::Missing { .. })
    ));
    std::fs::write(&path, &good).unwrap();
    assert_eq!(
        journal.frame(JobId(1), 0).unwrap().frame,
        0,
        "the good bytes read back"
    );
}

fn queue(journal: &Journal, id: u64) {
    let (scene, job) = one_pixel_job(2);
    let job = Box::new(job);
    journal
        .write(Record::JobQueued {
            id: JobId(id),
            job,
            scene,
        })
        .unwrap();
}

/// A second spelling of a job's directory is set aside (never read as
/// a second copy of the job), as is any other stray entry, and a job's
/// directory that is a file; each with its reason, nothing deleted.
#[test]
fn each_job_is_read_in_its_one_spelling_and_strays_are_set_aside_with_reasons() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    queue(&journal, 1);
    journal.write(frame_done(1, 0)).unwrap();
    let jobs = dir.path().join("jobs");
    copy_dir(&journal.job_dir(JobId(1)), &jobs.join("1"));
    std::fs::write(jobs.join("000000000002"), b"not a directory").unwrap();
    std::fs::write(jobs.join("notes"), b"a stray file").unwrap();

    let loaded = journal.load();
    let ids: Vec<u64> = loaded.jobs.iter().map(|j| j.id.0).collect();
    assert_eq!(ids, [1], "job 1 once");
    assert_eq!(loaded.jobs[0].frames_done, 1);
    assert_eq!(loaded.damaged.len(), 1, "{:?}", loaded.damaged);
    let reason = &loaded.damaged[0].reason;
    assert_eq!(loaded.damaged[0].id, JobId(2));
    assert!(
        reason.contains("000000000002: not a directory") && reason.contains("damaged/000000000002"),
        "{reason}"
    );
    let why =
        |name: &str| std::fs::read_to_string(jobs.join("damaged").join(name).join("why")).unwrap();
    assert!(
        why("stray-1")
            .contains("jobs/1 is not how job 1's directory is spelled (jobs/000000000001)"),
        "{}",
        why("stray-1")
    );
    assert!(why("stray-notes").contains("jobs/notes is no job's directory"));
    // Moved, not deleted.
    assert!(jobs.join("damaged/stray-1/job").exists());
    assert!(jobs.join("damaged/stray-notes/notes").exists());
    assert!(jobs.join("damaged/000000000002/000000000002").exists());
    // A second start reads the same, with the same reasons.
    let again = journal.load();
    assert_eq!(again.jobs.len(), 1);
    assert_eq!(again.damaged, loaded.damaged);
}

/// A valid job record copied into another job's directory names its
/// own job: the directory's job is set aside, naming both, never run
/// as the other scene.
#[test]
fn a_job_record_in_another_jobs_directory_is_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    queue(&journal, 1);
    queue(&journal, 2);
    std::fs::copy(journal.job_path(JobId(2)), journal.job_path(JobId(1))).unwrap();
    let loaded = journal.load();
    let ids: Vec<u64> = loaded.jobs.iter().map(|j| j.id.0).collect();
    assert_eq!(ids, [2]);
    assert_eq!(loaded.damaged.len(), 1);
    let reason = &loaded.damaged[0].reason;
    assert!(
        reason.contains("it holds a record of job 2, not of job 1"),
        "{reason}"
    );
}

/// A journal of format 4 (records without their envelope) is upgraded
/// at start: its job, frames, listing and completion read back.
#[test]
fn a_format_4_journal_is_upgraded_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    queue(&journal, 3);
    journal.write(frame_done(3, 0)).unwrap();
    journal.write(frame_done(3, 1)).unwrap();
    journal.write(Record::JobComplete { id: JobId(3) }).unwrap();
    let summary = JobSummary {
        id: JobId(3),
        name: "old".into(),
        kind: vtfarm_proto::WireJobKind::Render,
        state: vtfarm_proto::WireJobState::Completed,
        priority: 2,
        frames_done: 2,
        frames_failed: 0,
        frames_cancelled: 0,
        frames_total: 2,
        submitted_ms: 1,
        started_ms: Some(2),
        finished_ms: Some(3),
        host: "h".into(),
        reason: String::new(),
    };
    journal
        .write(Record::JobState(Box::new(summary.clone())))
        .unwrap();
    let written = journal.load();
    // Strip every envelope: the records as a format-4 master wrote them.
    for entry in std::fs::read_dir(journal.job_dir(JobId(3))).unwrap() {
        let path = entry.unwrap().path();
        let payload = read_record(&path).unwrap();
        let (_, body) = split_envelope(&payload).expect("an envelope");
        std::fs::write(&path, record_bytes(body)).unwrap();
    }
    std::fs::write(dir.path().join("jobs/format"), "4\n").unwrap();

    let upgraded = Journal::open(dir.path()).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.path().join("jobs/format")).unwrap(),
        format!("{JOURNAL_FORMAT}\n")
    );
    let read = upgraded.load();
    assert!(read.damaged.is_empty(), "{:?}", read.damaged);
    let (was, is) = (&written.jobs[0], &read.jobs[0]);
    assert_eq!(
        (is.id, is.frames_done, is.complete, &is.summary),
        (JobId(3), 2, true, &Some(summary))
    );
    assert_eq!((was.frames_done, was.complete), (2, true));
    assert_eq!(
        upgraded.frame(JobId(3), 1).unwrap(),
        journal.frame(JobId(3), 1).unwrap()
    );
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}

/// A FIFO (no writer) or `/dev/zero` in a record's place is an error
/// naming the file, returned at once: a read of either would block the
/// master or never end.
#[test]
fn a_fifo_or_a_device_in_a_records_place_is_an_error_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    queue(&journal, 1);
    journal.write(frame_done(1, 0)).unwrap();
    let frame = journal.frame_path(JobId(1), 1);
    let made = std::process::Command::new("mkfifo")
        .arg(&frame)
        .status()
        .unwrap();
    assert!(made.success());
    std::os::unix::fs::symlink("/dev/zero", journal.state_path(JobId(1))).unwrap();
    let (done, result) = std::sync::mpsc::channel();
    let reader = journal.clone();
    std::thread::spawn(move || {
        let frame = reader
            .frame(JobId(1), 1)
            .map(|_| ())
            .map_err(|e| e.to_string());
        let _ = done.send((frame, reader.load()));
    });
    let (frame_error, loaded) = result
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("read without blocking");
    let error = frame_error.unwrap_err();
    assert!(
        error.contains(&frame.display().to_string())
            && error.contains("a FIFO, not a regular file"),
        "{error}"
    );
    // The FIFO is the frame after the last good one: rendered again.
    let job = &loaded.jobs[0];
    assert_eq!(job.frames_done, 1);
    assert!(
        (job.damaged_frame.as_ref()).is_some_and(|(f, why)| *f == 1 && why.contains("a FIFO")),
        "{:?}",
        job.damaged_frame
    );
    // The device as the listing: lost, the job held (`summary` none).
    assert_eq!(job.summary, None);
}

#[test]
fn a_study_reads_back_over_its_variants_and_a_damaged_one_is_set_aside() {
    use vtfarm_proto::{JobRow, JobSummary, WireJobKind, WireJobState};
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    let (scene, job) = one_pixel_job(1);
    let listing = |id: u64, kind: WireJobKind| JobSummary {
        id: JobId(id),
        name: format!("job {id}"),
        kind,
        state: WireJobState::Running,
        priority: 0,
        frames_done: 0,
        frames_failed: 0,
        frames_cancelled: 0,
        frames_total: 1,
        submitted_ms: 1_000,
        started_ms: Some(2_000),
        finished_ms: None,
        host: "10.0.0.9:4000".into(),
        reason: String::new(),
    };
    // Study 1 over variants 2 and 3 (each journaled as a job).
    for id in [2, 3] {
        let queued = Record::JobQueued {
            id: JobId(id),
            job: Box::new(job.clone()),
            scene: scene.clone(),
        };
        journal.write(queued).unwrap();
        let state = Record::JobState(Box::new(listing(id, WireJobKind::Variant)));
        journal.write(state).unwrap();
    }
    let row = JobRow {
        job: listing(1, WireJobKind::Study),
        variants: vec![
            listing(2, WireJobKind::Variant),
            listing(3, WireJobKind::Variant),
        ],
    };
    journal
        .write(Record::StudyState(Box::new(row.clone())))
        .unwrap();
    let loaded = journal.load();
    assert!(loaded.damaged.is_empty(), "{:?}", loaded.damaged);
    assert_eq!(loaded.studies, [row]);
    let ids: Vec<u64> = loaded.jobs.iter().map(|j| j.id.0).collect();
    assert_eq!(ids, [2, 3]);

    // A damaged study record is set aside with its reason; its variants
    // read back as jobs.
    flip_listing(&journal.study_path(JobId(1)));
    let loaded = journal.load();
    assert!(loaded.studies.is_empty());
    assert_eq!(loaded.jobs.len(), 2);
    let why = std::fs::read_to_string(dir.path().join("jobs/damaged/000000000001/why")).unwrap();
    assert!(why.contains("checksum mismatch"), "{why}");
}
