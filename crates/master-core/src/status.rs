//! Status and live frames: the farm's state for `vtfarm status` and the
//! dashboard, read from the scheduler, the peers and the frames being
//! assembled.

use vtfarm_proto::JobId;
use vtfarm_proto::{QueueStatus, RunningJob, StatusReply, WorkerStatus};
use vtfarm_scheduler::{Scheduler, WorkerState};

use crate::frames::Frames;
use crate::peers::{ConnId, Peer, Peers};

/// The frame being assembled, borrowed from the core.
pub struct LiveFrame<'a> {
    pub job: JobId,
    pub frame: u32,
    pub triangles_done: u64,
    pub triangles_total: u64,
    pub image: &'a vtfarm_imaging::Image,
}

/// The frame being assembled of the first running job (in the order jobs
/// get workers) that assembles one: job, frame index, reflector triangles
/// done, and its image so far (base frame with the results composited).
pub(crate) fn live_frame<'a>(scheduler: &Scheduler, frames: &'a Frames) -> Option<LiveFrame<'a>> {
    (scheduler.queue().running.iter()).find_map(|running| {
        let job = frames.jobs.get(&running.job)?;
        // Nothing to show until the base frame is there.
        let current = job.assembly(running.frame).filter(|c| c.ids.is_some())?;
        Some(LiveFrame {
            job: running.job,
            frame: current.start.frame,
            triangles_done: current.triangles_done,
            triangles_total: job.reflectors.len() as u64,
            image: current.image.color(),
        })
    })
}

/// The farm's state for `vtfarm status`: the workers connected, the queue
/// with each running job's progress, and the scene bytes sent so far.
pub(crate) fn status(
    scheduler: &Scheduler,
    peers: &Peers,
    frames: &Frames,
    scene_bytes_sent: u64,
) -> StatusReply {
    let workers = (scheduler.workers().into_iter())
        .filter(|w| w.state != WorkerState::Gone)
        .filter_map(|w| {
            let Some(Peer::Worker { name, address, .. }) = peers.get(ConnId::of_worker(w.worker))
            else {
                return None;
            };
            Some(WorkerStatus {
                name: name.clone(),
                address: address.clone(),
                threads: w.threads,
                state: format!("{:?}", w.state).to_lowercase(),
                throughput: w.rate.unwrap_or(0.0),
                packages_running: w.running as u32,
                packages_done: w.packages_done,
                triangles_done: w.items_done,
                failures: w.failures,
                busy_micros: w.busy.as_micros() as u64,
            })
        })
        .collect();
    let queue = scheduler.queue();
    // Progress in reflector triangles, as `Message::Progress` counts it
    // (work items are reflector groups for per-reflector methods).
    let running = (queue.running.iter())
        .map(|p| {
            let job = frames.jobs.get(&p.job);
            RunningJob {
                job: p.job,
                name: job.map(|j| j.name.clone()).unwrap_or_default(),
                frame: p.frame,
                frames: p.frames,
                triangles_done: (job.and_then(|j| j.assembly(p.frame)))
                    .map_or(0, |c| c.triangles_done),
                triangles_total: job.map_or(0, |j| j.reflectors.len() as u64),
                paused: p.paused,
            }
        })
        .collect();
    StatusReply {
        workers,
        queue: QueueStatus {
            waiting: queue.waiting.clone(),
            running,
        },
        scene_bytes_sent,
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use vtfarm_scheduler::WorkerId;

    use super::*;
    use crate::rules::FarmRules;

    /// The status lists the connected workers by name, and the scene
    /// bytes sent; with no job running there is no live frame.
    #[test]
    fn the_status_names_connected_workers_and_an_idle_farm_has_no_live_frame() {
        let mut scheduler = Scheduler::new(FarmRules::default().scheduler_config());
        let mut peers = Peers::default();
        for (conn, name) in [(3, "w3"), (4, "w4")] {
            scheduler
                .worker_joined(Duration::ZERO, WorkerId(conn), 2)
                .unwrap();
            let address = format!("10.0.0.{conn}:4000");
            let threads = 2;
            peers.joined(
                ConnId(conn),
                Peer::Worker {
                    name: name.into(),
                    threads,
                    address,
                },
            );
        }
        peers.left(ConnId(4));
        let frames = Frames::default();
        let reply = status(&scheduler, &peers, &frames, 123);
        let names: Vec<&str> = reply.workers.iter().map(|w| w.name.as_str()).collect();
        assert_eq!(
            names,
            ["w3"],
            "a worker without its connection is not listed"
        );
        assert_eq!(reply.workers[0].threads, 2);
        assert_eq!(reply.scene_bytes_sent, 123);
        assert!(reply.queue.running.is_empty() && reply.queue.waiting.is_empty());
        assert!(live_frame(&scheduler, &frames).is_none());
    }
}
