//! The worker's scene cache runs off the session's task: a cache read that
//! blocks (here a FIFO no one writes yet, as a slow or hung disk would)
//! does not hold the heartbeats back, and a bad cached scene makes the
//! worker ask the master for the scene. The cache writes through no
//! symlink. Every wait is bounded and ends on a message from the worker.

use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::time::Duration;

use vtfarm_proto::{Message, SceneData};
use vtfarm_scene::Scene;
use vtfarm_transport::Link;
use vtfarm_worker::{DrainSignal, Engine, WorkerConfig, serve};

/// Every wait for the worker is bounded by this.
const WAIT: Duration = Duration::from_secs(60);

async fn next(link: &mut Link) -> Message {
    (tokio::time::timeout(WAIT, link.rx.recv()).await)
        .expect("the worker spoke in time")
        .expect("the worker's link is up")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cache_read_that_blocks_holds_no_heartbeat_back() {
    let cache = tempfile::tempdir().unwrap();
    let data = SceneData::from_scene(&Scene::default());
    let path = cache.path().join(format!("{}.scene", hex_name(&data.hash)));
    let fifo = CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: a valid C string; mkfifo only creates the node.
    assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
    let (mut master, worker_end) = Link::pair();
    let mut engine = Engine::new(Some(cache.path().to_owned()));
    let worker = tokio::spawn(async move {
        serve(
            worker_end,
            &mut engine,
            WorkerConfig::default(),
            DrainSignal::never(),
        )
        .await
    });
    master
        .tx
        .send(Message::SceneOffer {
            hash: data.hash,
            job: vtfarm_proto::JobId(1),
        })
        .unwrap();
    // The worker now reads the FIFO (blocked until it is written); its
    // heartbeats go on meanwhile.
    let mut heartbeats = 0;
    while heartbeats < 3 {
        match next(&mut master).await {
            Message::Heartbeat => heartbeats += 1,
            other => panic!("unexpected {}", other.name()),
        }
    }
    // A bad cached scene: the worker asks the master for it.
    let writer = tokio::task::spawn_blocking(move || std::fs::write(&path, b"not a scene"));
    loop {
        match next(&mut master).await {
            Message::Heartbeat => {}
            Message::SceneRequest { hash } => {
                assert_eq!(hash, data.hash);
                break;
            }
            other => panic!("unexpected {}", other.name()),
        }
    }
    writer.await.unwrap().unwrap();
    drop(master);
    tokio::time::timeout(WAIT, worker).await.unwrap().unwrap();
}

/// A dangling symlink where the cache keeps a scene (pointing outside the
/// cache) is replaced, never written through; a symlink to a valid scene
/// file is not read.
#[test]
fn the_cache_writes_through_no_symlink_and_reads_none() {
    let cache = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    let data = SceneData::from_scene(&Scene::default());
    let path = cache.path().join(format!("{}.scene", hex_name(&data.hash)));
    let target = outside.path().join("written-through");
    std::os::unix::fs::symlink(&target, &path).unwrap();
    let mut engine = Engine::new(Some(cache.path().to_owned()));
    engine.add_scene(data.clone()).unwrap();
    assert!(!target.exists(), "nothing was written through the link");
    let meta = std::fs::symlink_metadata(&path).unwrap();
    assert!(
        meta.file_type().is_file(),
        "the link was replaced by the scene"
    );
    assert_eq!(std::fs::read(&path).unwrap(), data.bytes);
    assert!(Engine::new(Some(cache.path().to_owned())).has_scene(&data.hash));

    // A link to a good scene file elsewhere is not followed.
    let elsewhere = outside.path().join("scene");
    std::fs::rename(&path, &elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, &path).unwrap();
    assert!(!Engine::new(Some(cache.path().to_owned())).has_scene(&data.hash));
}

fn hex_name(hash: &[u8]) -> String {
    hash.iter().map(|b| format!("{b:02x}")).collect()
}
