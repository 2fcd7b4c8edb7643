//! Failures on the workers reach the submitter: a package that fails on
//! every worker fails the job after the scheduler's rules, the submitter
//! gets the workers' error once, and the workers stay up. In-process links,
//! real worker sessions; every wait is bounded.

use std::sync::Arc;
use std::time::Duration;

use tokio::task::JoinHandle;
use tokio::time::timeout;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_embedded::local_worker;
use vtfarm_master::FarmRules;
use vtfarm_master::{MasterHandle, Peer, spawn_master};
use vtfarm_method::MethodKind;
use vtfarm_proto::{Message, SceneData, WireJob};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::Camera;
use vtfarm_submit::{JobError, JobOptions, run_job, wire_job};
use vtfarm_trace::TraceSettings;
use vtfarm_transport::Link;
use vtfarm_vertex::VertexSettings;
use vtfarm_worker::{SessionEnd, WorkerConfig};

/// Long enough for a small frame on a loaded machine; only a hang reaches it.
const BOUND: Duration = Duration::from_secs(120);

fn worker(master: &MasterHandle, name: &str, config: WorkerConfig) -> JoinHandle<SessionEnd> {
    local_worker(master, name.into(), 1, config)
}

fn submitter(master: &MasterHandle) -> Link {
    let (master_end, client_end) = Link::pair();
    let peer = Peer::Submitter {
        address: "in-process".into(),
    };
    master.attach(peer, master_end, None);
    client_end
}

/// A small cockpit frame and its job.
fn small_job() -> (
    WireJob,
    SceneData,
    FrameSetup,
    Vec<vtfarm_scene::TriangleId>,
    vtfarm_scene::Scene,
) {
    let c = cockpit(&CockpitConfig {
        detail: 0.1,
        ..CockpitConfig::default()
    });
    let reflectors = c.cover_glass_triangles();
    let setup = FrameSetup {
        camera: Camera {
            width: 64,
            height: 36,
            ..c.camera
        },
        lighting: c.lighting.clone(),
        trace: TraceSettings::default(),
        vertex: VertexSettings::default(),
    };
    let data = SceneData::from_scene(&c.scene);
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let job = wire_job(
        "failures",
        &data,
        std::slice::from_ref(&setup),
        &reflectors,
        options,
    );
    (job, data, setup, reflectors, c.scene)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_package_failing_on_every_worker_fails_the_job_with_its_error_once() {
    let (master, _task) = spawn_master(FarmRules::default());
    // A budget of no samples at all: every package fails on every worker.
    let starved = WorkerConfig {
        samples_per_pixel_budget: 0,
        ..WorkerConfig::default()
    };
    let workers: Vec<_> = (0..3)
        .map(|k| worker(&master, &format!("starved-{k}"), starved))
        .collect();
    let (job, data, setup, reflectors, scene) = small_job();
    // All three connected first: with fewer, every connected worker is soon
    // blocklisted and the job fails for want of an eligible worker instead.
    let connected = master.wait_for_status(|s| s.workers.len() == 3);
    (timeout(BOUND, connected)
        .await
        .expect("the workers connect"))
    .expect("the master runs");

    let mut link = submitter(&master);
    let outcome = timeout(BOUND, run_job(&mut link, job.clone(), &data, |_| {}))
        .await
        .expect("the job ends instead of hanging");
    let Err(JobError::Failed(errors)) = outcome else {
        panic!("the job must fail: {outcome:?}");
    };
    let budget_lines: Vec<&String> = errors
        .iter()
        .filter(|e| e.contains("stopped after its budget of 0 traced samples"))
        .collect();
    // Workers ask one package ahead, so several packages fail (each its
    // own error); each error is told once, with the workers it hit, and
    // together they name every worker.
    assert!(!budget_lines.is_empty(), "{errors:#?}");
    let mut distinct = budget_lines.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(
        distinct.len(),
        budget_lines.len(),
        "each error once: {errors:#?}"
    );
    for k in 0..3 {
        assert!(
            (budget_lines.iter()).any(|line| line.contains(&format!("starved-{k}"))),
            "{errors:#?}"
        );
    }
    // The workers stay up, and the master goes on serving.
    for w in &workers {
        assert!(!w.is_finished(), "a failed package took a worker down");
    }
    link.tx.send(Message::StatusRequest).expect("link up");
    let status = timeout(BOUND, async {
        loop {
            match link.rx.recv().await {
                Some(Message::StatusReply(status)) => return status,
                Some(_) => continue,
                None => panic!("the master dropped the submitter"),
            }
        }
    })
    .await
    .expect("a status reply");
    assert_eq!(status.workers.len(), 3);

    // A worker joining later gets the next job once the starved ones leave,
    // and renders it exactly like one process.
    for w in &workers {
        w.abort();
    }
    let healthy = worker(&master, "healthy", WorkerConfig::default());
    let mut link = submitter(&master);
    let frames = timeout(BOUND, run_job(&mut link, job, &data, |_| {}))
        .await
        .expect("bounded")
        .expect("the healthy worker renders the job");
    let reference = Renderer::new(Arc::new(scene), reflectors).render(
        &setup,
        &Default::default(),
        &mut |_, _| {},
    );
    assert_eq!(
        frames[0].image.linear().expect("a linear frame").pixels,
        reference.image.color.pixels
    );
    assert!(!healthy.is_finished());
}
