//! The embedded farm behind `vtfarm render` and `vtfarm study`: a master
//! and local workers in one process, joined by in-memory links, so the
//! one-machine path runs the same scheduler and protocol as the cluster.
//! It joins the server (`vtfarm-master`) and the worker (`vtfarm-worker`),
//! which know nothing of each other; submitters talk to it through
//! `vtfarm-submit` over [`LocalFarm::submitter`].

use tokio::task::JoinHandle;
use vtfarm_master::{FarmRules, MasterHandle, Peer, spawn_master};
use vtfarm_transport::Link;
use vtfarm_worker::{DrainSignal, Engine, SessionEnd, WorkerConfig, serve};

/// Attaches a worker to `master` over an in-memory link and runs its session
/// as a task (no scene cache on disk, never drained).
pub fn local_worker(
    master: &MasterHandle,
    name: String,
    threads: u32,
    config: WorkerConfig,
) -> JoinHandle<SessionEnd> {
    let (master_end, worker_end) = Link::pair();
    let peer = Peer::Worker {
        name,
        threads,
        address: "in-process".into(),
    };
    master.attach(peer, master_end, None);
    tokio::spawn(async move {
        serve(
            worker_end,
            &mut Engine::new(None),
            config,
            DrainSignal::never(),
        )
        .await
    })
}

/// A master with local workers (call inside a multi-threaded tokio runtime).
/// End it with [`LocalFarm::shutdown`] before the runtime goes: a task still
/// running while the runtime shuts down panics on its next timer.
pub struct LocalFarm {
    master: MasterHandle,
    master_task: JoinHandle<()>,
    workers: Vec<JoinHandle<SessionEnd>>,
}

impl LocalFarm {
    /// Starts a master and `workers` local workers sharing this process's cores.
    pub fn start(workers: usize, rules: FarmRules) -> LocalFarm {
        let (master, task) = spawn_master(rules);
        let workers = workers.max(1);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as u32;
        let threads = (cores / workers as u32).max(1);
        let workers = (0..workers)
            .map(|k| {
                local_worker(
                    &master,
                    format!("local-{k}"),
                    threads,
                    WorkerConfig::default(),
                )
            })
            .collect();
        LocalFarm {
            master,
            master_task: task,
            workers,
        }
    }

    /// Stops the master and waits for it and every worker task to end.
    /// Returns how many tasks failed (panicked).
    pub async fn shutdown(self) -> usize {
        self.master.stop();
        let mut failed = usize::from(self.master_task.await.is_err());
        for worker in self.workers {
            failed += usize::from(worker.await.is_err());
        }
        failed
    }

    /// A submitter's link to the master.
    pub fn submitter(&self) -> Link {
        let (master_end, client_end) = Link::pair();
        self.master.attach(
            Peer::Submitter {
                address: "in-process".into(),
            },
            master_end,
            None,
        );
        client_end
    }
}
