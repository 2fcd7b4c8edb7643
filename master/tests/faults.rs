//! Deterministic fault tests: the master's core and real worker sessions in
//! the `Pair` harness (`vtfarm_farmsim::TestFarm`: virtual clock, in-memory
//! queues). Every scenario ends with images equal to the single-process
//! render, bit for bit.

#[path = "support/frame.rs"]
mod frame;
#[path = "support/job.rs"]
mod job;

mod support;

use std::sync::Arc;
use std::time::Duration;

use job::Job;
use support::pair::Pair;
use vtfarm_master::FarmRules;
use vtfarm_master::{JobOptions, wire_job};
use vtfarm_master_core::JobState;
use vtfarm_method::MethodKind;
use vtfarm_proto::{FrameStats, Message, SceneData, WireImage, WireImageFormat};
use vtfarm_render::Renderer;

/// Virtual time a scenario may take at most.
const BOUND: Duration = Duration::from_secs(600);

fn all_frames(frames: usize) -> impl FnMut(&Pair) -> bool {
    move |pair| pair.frames_done().len() == frames || pair.job_failed().is_some()
}

/// The finished frames' stats, after checking every image against the reference.
fn check_images(pair: &Pair, job: &Job) -> Vec<FrameStats> {
    assert_eq!(pair.job_failed(), None);
    let reference = job.reference();
    let done = pair.frames_done();
    assert_eq!(done.len(), reference.len());
    (done.into_iter().zip(&reference))
        .map(|(done, reference)| {
            let (_, _, pixels) = done.image.clone().into_pixels().unwrap();
            assert!(
                &pixels == reference,
                "frame {}: pixels differ from the single-process render",
                done.frame
            );
            done.stats.clone()
        })
        .collect()
}

/// Every frame split into packages (no whole frames), for the scenarios of
/// how split frames are shared.
fn split_frames() -> FarmRules {
    FarmRules {
        whole_frames: false,
        ..FarmRules::default()
    }
}

/// No straggler copies: a lost package must come back through the loss itself.
fn no_stragglers() -> FarmRules {
    FarmRules {
        straggler: None,
        ..FarmRules::default()
    }
}

#[test]
fn a_worker_killed_mid_frame_loses_its_packages_to_the_others() {
    let job = Job::new(1);
    let config = no_stragglers();
    let heartbeat_timeout = config.heartbeat_timeout;
    let mut pair = Pair::new(config);
    let survivor = pair.add_worker("survivor", 1.0);
    let doomed = pair.add_worker("doomed", 4.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    // The trigger is a protocol state, not a time: the doomed worker runs a package.
    pair.drive(BOUND, |p| p.workers[doomed].is_running_a_package());
    let killed_at = pair.now;
    pair.kill(doomed);
    pair.drive(BOUND, all_frames(1));
    let stats = check_images(&pair, &job);
    assert!(
        stats[0].requeued >= 1,
        "its package was requeued: {stats:?}"
    );
    let names: Vec<&str> = stats[0].workers.iter().map(|w| w.name.as_str()).collect();
    assert!(
        stats[0]
            .workers
            .iter()
            .all(|w| w.name.starts_with("survivor") || w.packages == 0),
        "only the survivor's results count: {names:?}"
    );
    assert!(pair.workers[survivor].results_sent > 0);
    assert!(
        pair.now - killed_at < heartbeat_timeout * 2,
        "the loss was noticed within the heartbeat timeout ({:?} after the kill)",
        pair.now - killed_at
    );
}

#[test]
fn a_slowed_worker_gets_a_share_that_follows_its_speed() {
    let job = Job::new(4);
    let mut pair = Pair::new(split_frames());
    pair.add_worker("fast", 1.0);
    pair.add_worker("slow", 3.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    pair.drive(BOUND, all_frames(4));
    let stats = check_images(&pair, &job);
    for s in &stats {
        eprintln!(
            "imbalance {:.1}%, slow share {:.3}",
            s.imbalance * 100.0,
            share(s, "slow")
        );
    }
    // After the first frame (uniform estimates, unmeasured workers) the slow
    // worker traces about a quarter (a third of the fast one's speed).
    // Frames are pipelined, so a worker's share moves between neighbouring
    // frames: the frames after the first are judged together.
    let later = &stats[1..];
    let triangles = |name: &str| -> u32 {
        (later.iter().flat_map(|s| &s.workers))
            .filter(|w| w.name.starts_with(name))
            .map(|w| w.triangles)
            .sum()
    };
    let slow = f64::from(triangles("slow")) / f64::from(triangles("slow") + triangles("fast"));
    assert!(
        (0.20..=0.30).contains(&slow),
        "slow share {slow:.3}: {later:?}"
    );
    for s in later {
        assert!(s.imbalance < 0.25, "imbalance {:.3}: {s:?}", s.imbalance);
    }
}

/// The share of a frame's triangles traced by the worker named `name`.
fn share(stats: &FrameStats, name: &str) -> f64 {
    let total: u32 = stats.workers.iter().map(|w| w.triangles).sum();
    let mine: u32 = (stats.workers.iter())
        .filter(|w| w.name.starts_with(name))
        .map(|w| w.triangles)
        .sum();
    f64::from(mine) / f64::from(total.max(1))
}

#[test]
fn a_worker_whose_heartbeats_are_lost_is_dropped_and_its_work_redone() {
    let job = Job::new(1);
    let mut pair = Pair::new(no_stragglers());
    pair.add_worker("steady", 1.0);
    let cut_off = pair.add_worker("cut-off", 2.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    pair.drive(BOUND, |p| p.workers[cut_off].is_running_a_package());
    // Its session goes on (it keeps tracing and sending), but nothing arrives.
    pair.workers[cut_off].partitioned = true;
    pair.drive(BOUND, all_frames(1));
    let stats = check_images(&pair, &job);
    assert!(stats[0].requeued >= 1, "{stats:?}");
    assert!(
        !pair.workers[cut_off].is_connected(),
        "the master closed the silent worker"
    );
}

#[test]
fn duplicated_results_are_composited_and_counted_once() {
    let job = Job::new(2);
    let mut pair = Pair::new(FarmRules::default());
    let echo = pair.add_worker("echo", 1.0);
    pair.add_worker("plain", 1.0);
    pair.workers[echo].duplicate_results = true;
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    pair.drive(BOUND, all_frames(2));
    check_images(&pair, &job);
    let total = job.reflectors.len() as u32;
    for m in &pair.to_submitter {
        if let Message::Progress { done, .. } = m {
            assert!(
                *done <= total,
                "progress {done} of {total} counts a result twice"
            );
        }
    }
}

#[test]
fn a_draining_worker_finishes_its_package_and_its_queue_goes_back_at_once() {
    let job = Job::new(2);
    let config = no_stragglers();
    let heartbeat_timeout = config.heartbeat_timeout;
    let mut pair = Pair::new(config);
    pair.add_worker("stays", 1.0);
    let leaving = pair.add_worker("leaving", 2.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    pair.drive(BOUND, |p| p.workers[leaving].is_running_a_package());
    let results_before = pair.workers[leaving].results_sent;
    pair.drain(leaving);
    let drained_at = pair.now;
    // Gone from the master's worker list long before a heartbeat timeout.
    pair.drive(heartbeat_timeout / 2, |p| {
        !p.workers[leaving].is_connected() && p.master.status().workers.len() == 1
    });
    assert!(pair.now - drained_at < heartbeat_timeout / 2);
    assert_eq!(
        pair.workers[leaving].results_sent,
        results_before + 1,
        "the running package was finished and sent"
    );
    pair.drive(BOUND, all_frames(2));
    check_images(&pair, &job);
}

#[test]
fn the_same_faults_replay_the_same_schedule() {
    let run = || {
        let job = Job::new(2);
        let mut pair = Pair::new(FarmRules::default());
        pair.add_worker("a", 1.0);
        let b = pair.add_worker("b", 2.5);
        pair.add_worker("c", 1.5);
        let (wire, data) = job.wire();
        pair.submit(wire, data);
        pair.drive(BOUND, |p| p.workers[b].is_running_a_package());
        pair.kill(b);
        pair.drive(BOUND, all_frames(2));
        // Everything but what depends on measured compute times.
        let trace: Vec<String> = (pair.frames_done().iter())
            .map(|d| {
                let s = &d.stats;
                let split = (s.wall_micros, s.packages, s.requeued, s.duplicates);
                // (Result sizes include the measured times too.)
                let workers: Vec<_> = (s.workers.iter())
                    .map(|w| (&w.name, w.busy_micros, w.packages, w.triangles, w.rays))
                    .collect();
                format!("{split:?} {workers:?}")
            })
            .collect();
        (pair.now, trace)
    };
    assert_eq!(run(), run());
}

#[test]
fn a_restarted_master_resumes_the_job_from_its_last_finished_frame() {
    let job = Job::new(4);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("a", 1.0);
    pair.add_worker("b", 1.5);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    // Mid-job: two frames delivered, the third running.
    pair.drive(BOUND, |p| {
        p.frames_done().len() == 2 && p.workers.iter().any(|w| w.is_running_a_package())
    });
    let id = pair.job_id().unwrap();
    let starts_before = pair.frame_starts.len();
    pair.restart_master();
    // The submitter comes back (after its backoff) and re-attaches.
    pair.drive_bounded(Duration::from_secs(1), u64::MAX, &mut |_| false);
    pair.attach_submitter(id);
    pair.drive(BOUND, all_frames(4));
    check_images(&pair, &job);
    let resumed: Vec<u32> = pair.frame_starts[starts_before..]
        .iter()
        .map(|&(_, frame)| frame)
        .collect();
    assert!(
        resumed.iter().all(|&f| f >= 2),
        "finished frames are not rendered again: {resumed:?}"
    );
}

#[test]
fn a_submitter_that_lost_its_connection_re_attaches_and_gets_every_frame() {
    let job = Job::new(3);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("a", 1.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    pair.drive(BOUND, |p| p.frames_done().len() == 1);
    let id = pair.job_id().unwrap();
    pair.drop_submitter();
    // The job goes on without it; the frames finished meanwhile are replayed.
    pair.drive(BOUND, |p| p.frame_starts.iter().any(|&(_, f)| f == 2));
    pair.attach_submitter(id);
    pair.drive(BOUND, all_frames(3));
    check_images(&pair, &job);
}

#[test]
fn unknown_jobs_fail_to_attach_and_journaled_orphans_render_to_the_end() {
    let job = Job::new(3);
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.attach_submitter(vtfarm_proto::JobId(77));
    let errors = pair.job_failed().expect("no job 77");
    assert!(errors[0].contains("no job 77"), "{errors:?}");

    // In memory: nobody can come back for the frames, the job stops at once.
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("a", 1.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data.clone());
    pair.drive(BOUND, |p| p.frames_done().len() == 1);
    let id = pair.job_id().unwrap();
    pair.drop_submitter();
    assert!(pair.master.status().queue.running.is_empty());
    let entry = pair.master.jobs().get(id).expect("listed");
    assert_eq!(entry.state, JobState::Cancelled);
    assert!(entry.reason.contains("submitter left"), "{}", entry.reason);

    // Journaled: the farm renders it to the end (its frames are kept), and
    // a submitter attaching afterwards gets every frame.
    let mut pair = support::pair::persistent(FarmRules::default());
    pair.add_worker("a", 1.0);
    pair.submit(job.wire().0, data);
    pair.drive(BOUND, |p| p.workers[0].is_running_a_package());
    let id = pair.job_id().unwrap();
    pair.drop_submitter();
    pair.drive(BOUND, |p| {
        p.master.jobs().get(id).map(|e| e.state) == Some(JobState::Completed)
    });
    assert_eq!(pair.master.jobs().get(id).unwrap().frames_done, 3);
    pair.attach_submitter(id);
    pair.drive(BOUND, all_frames(3));
    check_images(&pair, &job);
}

/// Later base frames are rasterized into earlier frames' buffers, and
/// nothing of those frames is left in the images.
#[test]
fn frames_in_reused_buffers_stay_byte_identical() {
    let job = Job::new(4);
    // Base frames are the master's for split frames only.
    let mut pair = Pair::new(split_frames());
    pair.add_worker("only", 1.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    pair.drive(BOUND, all_frames(4));
    assert!(
        pair.bases_in_reused_buffers >= 2,
        "{} base frames in reused buffers",
        pair.bases_in_reused_buffers
    );
    check_images(&pair, &job);
}

#[test]
fn pipelined_frames_overlap_and_stay_byte_identical() {
    let job = Job::new(3);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("fast", 1.0);
    pair.add_worker("slow", 3.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    // Frame 1 is announced while frame 0's last packages still run.
    pair.drive(BOUND, |p| p.frame_starts.iter().any(|&(_, f)| f == 1));
    assert!(
        pair.frames_done().is_empty(),
        "frame 1 started before frame 0 was done"
    );
    pair.drive(BOUND, all_frames(3));
    let stats = check_images(&pair, &job);
    assert!(stats.iter().all(|s| s.failures == 0), "{stats:?}");
}

/// While a batch job's whole frames run, the master makes its tail's base
/// frames ahead, one at a time (the last frames, no more than the
/// workers); the split tail frames then use them instead of asking again,
/// and every frame keeps the single-process render's bytes.
#[test]
fn tail_frames_on_base_frames_made_ahead_stay_byte_identical() {
    let job = Job::new(5);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("a", 1.0);
    pair.add_worker("b", 1.0);
    let (wire, data) = job.wire();
    pair.submit(wire, data);
    // Frames 0..3 whole (more frames left than workers), 3 and 4 split.
    pair.drive(BOUND, |p| p.base_frames.len() == 2);
    let id = pair.job_id().expect("submitted");
    assert_eq!(pair.base_frames, [(id, 3), (id, 4)]);
    assert!(
        !(pair.frame_starts.iter()).any(|&(_, f)| f >= 3),
        "made before the tail started: {:?}",
        pair.frame_starts
    );
    pair.drive(BOUND, all_frames(5));
    check_images(&pair, &job);
    assert_eq!(pair.base_frames, [(id, 3), (id, 4)], "none made again");
    let split: Vec<u32> = (pair.frames_done().iter())
        .filter(|d| d.stats.packages > 1)
        .map(|d| d.frame)
        .collect();
    assert!(split.contains(&4), "the last frame split: {split:?}");
}

/// The finished frames of a job whose frames go out in 8-bit sRGB, after
/// checking every image's wire bytes against the single-process render's
/// encoded whole (the master converts each base frame ahead and only the
/// pixels results wrote after: the same bytes, compressed the same way).
fn check_srgb_images(pair: &Pair, job: &Job) {
    assert_eq!(pair.job_failed(), None);
    let done = pair.frames_done();
    assert_eq!(done.len(), job.frames.len());
    for ((done, pixels), setup) in done.iter().zip(job.reference()).zip(&job.frames) {
        let reference = vtfarm_imaging::Image {
            width: setup.camera.width,
            height: setup.camera.height,
            pixels,
        };
        assert_eq!(done.image.format, WireImageFormat::Srgb8);
        assert!(
            done.image == WireImage::encode(&reference, WireImageFormat::Srgb8),
            "frame {}: bytes differ from the single-process render's",
            done.frame
        );
    }
}

/// A job in 8-bit sRGB (what `vtfarm submit` asks): split frames on one
/// and three workers, their base frames converted ahead into the buffers
/// of earlier frames (whose bytes differ: another eye), and a batch job's
/// tail on base frames made ahead, all give the single-process render's
/// bytes.
#[test]
fn srgb_frames_on_bases_converted_ahead_stay_byte_identical() {
    let job = Job::new(4);
    for workers in [1, 3] {
        let mut pair = Pair::new(split_frames());
        for w in 0..workers {
            pair.add_worker(&format!("w{w}"), 1.0);
        }
        let (mut wire, data) = job.wire();
        wire.image = WireImageFormat::Srgb8;
        pair.submit(wire, data);
        pair.drive(BOUND, all_frames(4));
        assert!(
            pair.bases_in_reused_buffers >= 2,
            "{workers} worker(s): {} base frames in reused buffers",
            pair.bases_in_reused_buffers
        );
        check_srgb_images(&pair, &job);
    }
    let job = Job::new(5);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("a", 1.0);
    pair.add_worker("b", 1.0);
    let (mut wire, data) = job.wire();
    wire.image = WireImageFormat::Srgb8;
    pair.submit(wire, data);
    pair.drive(BOUND, all_frames(5));
    let id = pair.job_id().expect("submitted");
    assert_eq!(pair.base_frames, [(id, 3), (id, 4)], "made ahead");
    check_srgb_images(&pair, &job);
}

/// Batch work runs in whole frames (each finished on its worker) and its
/// tail split (composited on the master); both give the single-process
/// render's bytes, colour and components, on 1, 2 and 3 workers (a mixed
/// job: whole frames, then split ones).
#[test]
fn whole_and_split_frames_give_the_single_process_bytes_on_1_2_and_3_workers() {
    let job = Job::new(5);
    let renderer = Renderer::new(Arc::new(job.scene.clone()), job.reflectors.clone());
    let reference: Vec<vtfarm_vertex::FrameImage> = (job.frames.iter())
        .map(|f| {
            renderer
                .render(f, &Default::default(), &mut |_, _| {})
                .image
        })
        .collect();
    for workers in 1..=3 {
        let mut pair = Pair::new(FarmRules::default());
        for w in 0..workers {
            pair.add_worker(&format!("w{w}"), 1.0);
        }
        let data = SceneData::from_scene(&job.scene);
        let options = JobOptions {
            method: MethodKind::VertexTracing,
            aux: true,
        };
        let wire = wire_job("modes", &data, &job.frames, &job.reflectors, options);
        pair.submit(wire, data);
        pair.drive(BOUND, all_frames(5));
        assert_eq!(pair.job_failed(), None);
        let done = pair.frames_done();
        assert_eq!(done.len(), 5);
        for (done, reference) in done.into_iter().zip(&reference) {
            let (width, height, pixels) = done.image.clone().into_pixels().unwrap();
            let color = vtfarm_imaging::Image {
                width,
                height,
                pixels,
            };
            let aux = done.aux.clone().expect("the job asked for the components");
            let image = aux.into_components(color).unwrap();
            assert!(
                &image == reference,
                "{workers} worker(s), frame {}: differs from the single-process render",
                done.frame
            );
            // Frame k starts with 5 − k frames left: whole while that is
            // more than the workers, one package on one worker.
            let whole = 5 - done.frame as usize > workers;
            let stats = &done.stats;
            if whole {
                assert_eq!(
                    (stats.packages, stats.workers.len()),
                    (1, 1),
                    "{workers} worker(s), whole frame {}: {stats:?}",
                    done.frame
                );
            } else if workers > 1 && done.frame == 4 {
                assert!(
                    stats.workers.iter().filter(|w| w.packages > 0).count() > 1,
                    "{workers} workers, the last frame split: {stats:?}"
                );
            }
        }
    }
}
