//! The farm end to end over real QUIC on 127.0.0.1: a master (in-process
//! tasks, or the `vtfarm` binary's workers as child processes) and workers
//! render the cockpit; the images must equal the single-process render bit
//! for bit, whatever the split, slow or dying workers, or bad clients.

use std::path::PathBuf;
use std::process::{Child, Command};
use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use tokio::task::JoinHandle;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_embedded::LocalFarm;
use vtfarm_master::FarmRules;
use vtfarm_master::{MasterHandle, server, spawn_master};
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    HandshakePolicy, Hello, Message, PROTOCOL_VERSION, RefuseCode, Role, SceneData, StatusReply,
    encode_message,
};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::{Camera, Scene, TriangleId};
use vtfarm_submit::{
    FinishedFrame, JobError, JobOptions, RemoteJob, run_job, run_remote_job, wire_job,
};
use vtfarm_trace::TraceSettings;
use vtfarm_transport::client::{ClientOptions, connect};
use vtfarm_transport::{ClusterConfig, ProtoError, SERVER_NAME, client_config};
use vtfarm_vertex::{Quality, VertexSettings};
use vtfarm_worker::{DrainSignal, Engine, WorkerConfig, run_worker};

/// The farm tests measure load balance: run them one at a time, so that they
/// do not compete for the machine's cores.
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// A small cockpit, its reflectors and a few frames from slightly different eyes.
struct Job {
    scene: Scene,
    reflectors: Vec<TriangleId>,
    frames: Vec<FrameSetup>,
}

fn job(frames: usize, width: u32, height: u32) -> Job {
    job_with_glass(
        frames,
        width,
        height,
        CockpitConfig::default().glass_segments,
    )
}

/// A job whose cover glass has `glass_segments` subdivisions (finer glass:
/// more, smaller reflector triangles, so packages can be sized finely).
fn job_with_glass(frames: usize, width: u32, height: u32, glass_segments: u32) -> Job {
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        glass_segments,
        ..CockpitConfig::default()
    });
    let reflectors = c.cover_glass_triangles();
    let frames = (0..frames)
        .map(|k| FrameSetup {
            camera: Camera {
                eye: c.camera.eye + Vec3::new(0.01, 0.005, 0.0) * k as f32,
                width,
                height,
                ..c.camera
            },
            lighting: c.lighting.clone(),
            trace: TraceSettings::default(),
            vertex: VertexSettings {
                quality: Quality::Full,
                ..VertexSettings::default()
            },
        })
        .collect();
    Job {
        scene: c.scene,
        reflectors,
        frames,
    }
}

/// The single-process images of a job.
fn reference(job: &Job) -> Vec<Vec<Vec3>> {
    reference_frames(job)
        .into_iter()
        .map(|f| f.color.pixels)
        .collect()
}

/// The single-process frames of a job with all their components.
fn reference_frames(job: &Job) -> Vec<vtfarm_vertex::FrameImage> {
    let renderer = Renderer::new(Arc::new(job.scene.clone()), job.reflectors.clone());
    job.frames
        .iter()
        .map(|f| {
            renderer
                .render(f, &Default::default(), &mut |_, _| {})
                .image
        })
        .collect()
}

/// A master listening on 127.0.0.1 with its cluster file.
struct Cluster {
    dir: tempfile::TempDir,
    options: ClientOptions,
    file: PathBuf,
    master: MasterHandle,
    _server: JoinHandle<()>,
}

impl Cluster {
    fn start(config: FarmRules) -> Cluster {
        let dir = tempfile::tempdir().unwrap();
        let identity = server::identity(dir.path(), &["127.0.0.1".into()]).unwrap();
        let endpoint = server::bind("127.0.0.1:0".parse().unwrap(), &identity).unwrap();
        let address = endpoint.local_addr().unwrap();
        let cluster = ClusterConfig::generate(&address.to_string(), &identity).unwrap();
        let file = dir.path().join("cluster.toml");
        cluster.save(&file).unwrap();
        let (master, _) = spawn_master(config);
        let policy = HandshakePolicy::new(cluster.token.clone(), "test-master");
        let server = tokio::spawn(server::serve(endpoint, policy, master.clone()));
        let options = ClientOptions {
            master: cluster.master,
            token: cluster.token,
            fingerprint: cluster.fingerprint,
        };
        Cluster {
            dir,
            options,
            file,
            master,
            _server: server,
        }
    }

    /// A worker task over QUIC with its own scene cache.
    fn worker(&self, name: &str, slowdown: f64) -> JoinHandle<()> {
        let (options, name) = (self.options.clone(), name.to_owned());
        let cache = self.dir.path().join(format!("cache-{name}"));
        tokio::spawn(async move {
            let _ = run_worker(
                options,
                name,
                1,
                Engine::new(Some(cache)),
                WorkerConfig {
                    slowdown,
                    ..WorkerConfig::default()
                },
                DrainSignal::never(),
            )
            .await;
        })
    }

    /// A worker as a child process of the `vtfarm` binary.
    fn worker_process(&self, name: &str, slowdown: f64) -> Child {
        (self.worker_command(name, slowdown).spawn()).expect("the vtfarm binary starts")
    }

    /// A worker child process that reports when it starts its first package
    /// (its own debug log line: the master counts a package as running once
    /// it is sent, before the worker has it). Its log goes on to stderr.
    fn worker_process_reporting_start(
        &self,
        name: &str,
        slowdown: f64,
    ) -> (Child, tokio::sync::oneshot::Receiver<()>) {
        let mut child = (self.worker_command(name, slowdown))
            .env("RUST_LOG", "warn,vtfarm_worker::serve=debug")
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("the vtfarm binary starts");
        let stderr = child.stderr.take().expect("stderr is piped");
        let (started, start) = tokio::sync::oneshot::channel();
        std::thread::spawn(move || {
            let mut started = Some(started);
            for line in std::io::BufRead::lines(std::io::BufReader::new(stderr)) {
                let Ok(line) = line else { break };
                eprintln!("{line}");
                if let Some(started) = started.take_if(|_| line.contains("package started")) {
                    let _ = started.send(());
                }
            }
        });
        (child, start)
    }

    fn worker_command(&self, name: &str, slowdown: f64) -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_vtfarm"));
        command
            .args([
                "worker",
                "--cluster",
                self.file.to_str().unwrap(),
                "--name",
                name,
                "--threads",
                "1",
            ])
            .args([
                "--slowdown",
                &slowdown.to_string(),
                "--cache",
                self.dir.path().join(name).to_str().unwrap(),
            ]);
        command
    }

    async fn submit(&self, job: &Job) -> Result<Vec<FinishedFrame>, JobError> {
        let mut conn = connect(&self.options, Role::Submitter).await.unwrap();
        let data = SceneData::from_scene(&job.scene);
        let run = run_job(
            &mut conn.link,
            // Components too: the glare study measures them.
            wire_job(
                "test",
                &data,
                &job.frames,
                &job.reflectors,
                JobOptions {
                    method: MethodKind::VertexTracing,
                    aux: true,
                },
            ),
            &data,
            |_| {},
        );
        (tokio::time::timeout(BOUND, run).await).expect("the job finishes within the bound")
    }

    /// What `vtfarm status` gets: a `StatusRequest` over QUIC.
    async fn status(&self) -> StatusReply {
        let mut conn = connect(&self.options, Role::Submitter).await.unwrap();
        let reply = tokio::time::timeout(BOUND, conn.link.status()).await;
        (reply.expect("a status reply within the bound")).expect("the master closed the connection")
    }

    /// Waits (bounded) until the master's status satisfies `done`, woken by
    /// its change notifications; `what` names the state for the failure.
    async fn wait_until(&self, what: &str, done: impl Fn(&StatusReply) -> bool) {
        let reached = tokio::time::timeout(BOUND, self.master.wait_for_status(done)).await;
        let reached = reached.unwrap_or_else(|_| panic!("{what} within the bound"));
        reached.expect("the master runs");
    }

    /// Waits until `count` workers are connected and asking for work.
    async fn wait_for_workers(&self, count: usize) {
        let message = format!("{count} workers connected");
        self.wait_until(&message, |s| s.workers.len() >= count)
            .await;
    }
}

fn assert_same_images(frames: &[FinishedFrame], reference: &[Vec<Vec3>]) {
    assert_eq!(frames.len(), reference.len());
    for (f, r) in frames.iter().zip(reference) {
        let pixels = &f.image.linear().expect("a linear frame").pixels;
        let differing = pixels.iter().zip(r).filter(|(a, b)| a != b).count();
        assert_eq!(
            differing, 0,
            "frame {}: pixels differ from the single-process render",
            f.frame
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_workers_render_the_cockpit_exactly_like_one_process() {
    let _serial = SERIAL.lock().await;
    let job = job(1, 240, 135);
    let reference = reference(&job);
    let cluster = Cluster::start(FarmRules::default());
    let _w1 = cluster.worker("w1", 1.0);
    let _w2 = cluster.worker("w2", 1.0);
    cluster.wait_for_workers(2).await;
    let frames = cluster.submit(&job).await.unwrap();
    assert_same_images(&frames, &reference);
    let components = frames[0]
        .components
        .as_ref()
        .expect("the job asked for components");
    assert!(
        components == &reference_frames(&job)[0],
        "reflected, transmitted and object maps equal too"
    );
    // Which worker traced how much depends on timing (a loaded machine may
    // let one do it all); the split is checked deterministically in
    // master/tests/faults.rs. Every package is counted once, whoever ran it.
    let workers = &frames[0].stats.workers;
    assert!(
        workers.iter().all(|w| w.packages > 0 && w.triangles > 0),
        "{workers:?}"
    );
    assert_eq!(
        workers.iter().map(|w| w.triangles as usize).sum::<usize>(),
        job.reflectors.len()
    );

    // The embedded master of `vtfarm render` gives the same image too.
    let farm = LocalFarm::start(3, FarmRules::default());
    let mut link = farm.submitter();
    let data = SceneData::from_scene(&job.scene);
    let embedded = run_job(
        &mut link,
        wire_job(
            "embedded",
            &data,
            &job.frames,
            &job.reflectors,
            JobOptions {
                method: MethodKind::VertexTracing,
                aux: false,
            },
        ),
        &data,
        |_| {},
    );
    let embedded = (tokio::time::timeout(BOUND, embedded).await)
        .expect("the embedded job finishes within the bound")
        .unwrap();
    assert_same_images(&embedded, &reference);
    let shut_down = tokio::time::timeout(Duration::from_secs(60), farm.shutdown());
    assert_eq!(
        shut_down.await.expect("the embedded farm shuts down"),
        0,
        "no task of the embedded farm panicked"
    );
}

/// Batch work over real QUIC: a job of more frames than workers runs its
/// first frames whole (each rendered, composited and encoded on one worker)
/// and its tail split (composited on the master); every frame, colour and
/// components, equals the single-process render on 1, 2 and 3 workers.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn whole_and_split_frames_over_quic_equal_the_single_process_render() {
    let _serial = SERIAL.lock().await;
    let job = job(4, 96, 54);
    let reference = reference(&job);
    let components = reference_frames(&job);
    for workers in 1..=3 {
        let cluster = Cluster::start(FarmRules::default());
        let _workers: Vec<JoinHandle<()>> = (0..workers)
            .map(|w| cluster.worker(&format!("w{w}"), 1.0))
            .collect();
        cluster.wait_for_workers(workers).await;
        let frames = cluster.submit(&job).await.unwrap();
        assert_same_images(&frames, &reference);
        for (frame, reference) in frames.iter().zip(&components) {
            let got = frame.components.as_ref().expect("the job asked for them");
            assert!(
                got == reference,
                "{workers} worker(s), frame {}: components differ",
                frame.frame
            );
            // Frame k starts with 4 − k frames left: whole (one package)
            // while that is more than the workers.
            if 4 - frame.frame as usize > workers {
                assert_eq!(frame.stats.packages, 1, "{:?}", frame.stats);
            }
        }
    }
}

/// The single-process frame of a per-reflector method: each reflector
/// object rendered on its own and composited over the rasterized frame.
fn method_reference(job: &Job, frame: &FrameSetup, kind: MethodKind) -> Vec<Vec3> {
    let (base, ids) = vtfarm_raster::rasterize(&job.scene, &frame.camera, &frame.lighting);
    let bvh = vtfarm_trace::SceneBvh::new(Arc::new(job.scene.clone()));
    let method = vtfarm_render::method(kind, frame.vertex);
    let full = vtfarm_vertex::PixelRect::full(base.width, base.height);
    let mut image = vtfarm_vertex::FrameImage::new(base, full);
    let reflectors = vtfarm_render::morton_order(&job.scene, job.reflectors.clone());
    for group in vtfarm_method::reflector_groups(&job.scene, &reflectors) {
        let output = method.render(&vtfarm_method::MethodFrame {
            tracer: vtfarm_trace::Tracer {
                bvh: &bvh,
                lighting: &frame.lighting,
                settings: frame.trace,
                cone: vtfarm_trace::PixelCone::of(&frame.camera),
            },
            camera: frame.camera,
            ids: &ids,
            reflector: &group,
            stop: None,
        });
        image.composite(&output.bitmap);
    }
    image.color.pixels
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_farm_runs_per_reflector_methods_reflector_by_reflector() {
    let _serial = SERIAL.lock().await;
    let mut job = job(2, 192, 108);
    // Three reflector objects: the cover glass, the steering wheel and the
    // centre console, so that the reflectors spread over the workers.
    for name in ["steering_wheel", "center_console"] {
        let object = job.scene.object_id(name).unwrap();
        job.reflectors.extend(job.scene.triangles_of(object));
    }
    let cluster = Cluster::start(FarmRules::default());
    let _w1 = cluster.worker("w1", 1.0);
    let _w2 = cluster.worker("w2", 1.0);
    cluster.wait_for_workers(2).await;
    for kind in [MethodKind::EnvironmentMap, MethodKind::Pvrr] {
        let mut conn = connect(&cluster.options, Role::Submitter).await.unwrap();
        let data = SceneData::from_scene(&job.scene);
        let options = JobOptions {
            method: kind,
            aux: false,
        };
        let wire = wire_job("methods", &data, &job.frames, &job.reflectors, options);
        let frames = run_job(&mut conn.link, wire, &data, |_| {}).await.unwrap();
        assert_eq!(frames.len(), 2);
        for (f, setup) in frames.iter().zip(&job.frames) {
            assert!(
                f.image.linear().expect("a linear frame").pixels
                    == method_reference(&job, setup, kind),
                "{}: frame {} equals the single-process render",
                kind.name(),
                f.frame
            );
            // The work items of a per-reflector method are whole reflectors.
            let workers = &f.stats.workers;
            let items: u32 = workers.iter().map(|w| w.triangles).sum();
            assert_eq!(items, 3, "{workers:?}");
        }
    }
    // Which worker took which reflector depends on timing; the images above
    // must not (the split itself is tested deterministically in master/tests/faults.rs).
}

/// Every file under `dir`, by relative path, with its bytes.
fn files_under(dir: &std::path::Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                files.insert(path.strip_prefix(dir).unwrap().to_owned(), bytes);
            }
        }
    }
    files
}

/// Runs the `vtfarm` binary off the async runtime and asserts success.
async fn vtfarm_cli(args: Vec<String>) {
    let (status, stderr) = run_vtfarm(&args, BOUND).await;
    assert!(status.success(), "{stderr}");
}

/// Runs the `vtfarm` binary, bounded; returns its exit status and stderr.
async fn run_vtfarm(args: &[String], bound: Duration) -> (std::process::ExitStatus, String) {
    use std::io::{Read, Seek};
    // A file, not a pipe: a chatty child cannot fill it and block.
    let mut stderr = tempfile::tempfile().unwrap();
    let mut child = ChildGuard(
        Command::new(env!("CARGO_BIN_EXE_vtfarm"))
            .args(args)
            .stderr(stderr.try_clone().unwrap())
            .spawn()
            .expect("the vtfarm binary runs"),
    );
    let status = child.exit_status(bound).await;
    let mut text = String::new();
    stderr.rewind().unwrap();
    stderr.read_to_string(&mut text).unwrap();
    (status, text)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_study_on_a_two_worker_cluster_writes_the_same_files_as_on_one_machine() {
    let files = study_on_one_machine_and_a_cluster(
        "[eyes]\npoints = [[-0.55, 1.40, 0.10], [-0.60, 1.45, 0.12]]\n\
         [[variants]]\nname = \"flat\"\nglass = \"flat\"\n\
         [[variants]]\nname = \"ellipsoidal\"\nglass = \"ellipsoidal\"\n",
    )
    .await;
    for expected in [
        "summary.csv",
        "summary.json",
        "report.html",
        "flat/eye_01/heat.png",
    ] {
        assert!(
            files.contains_key(std::path::Path::new(expected)),
            "{expected} in {:?}",
            files.keys()
        );
    }
    assert_eq!(
        files.len(),
        3 + 2 * 2 * 8,
        "three PNG images, the OpenEXR image and four arrays per frame"
    );
}

/// Runs `vtfarm submit FILE -o OUTPUT` on a fresh localhost cluster of two
/// workers.
async fn submit_on_a_two_worker_cluster(file: &std::path::Path, output: &std::path::Path) {
    let cluster = Cluster::start(FarmRules::default());
    let _w1 = cluster.worker("w1", 1.0);
    let _w2 = cluster.worker("w2", 1.0);
    cluster.wait_for_workers(2).await;
    let path = |p: &std::path::Path| p.to_str().unwrap().to_owned();
    vtfarm_cli(vec![
        "submit".into(),
        path(file),
        "--cluster".into(),
        path(&cluster.file),
        "-o".into(),
        path(output),
    ])
    .await;
}

/// `vtfarm submit` asks for 8-bit sRGB frames (all it writes is PNGs) and
/// `vtfarm render` gets linear ones: both write the same PNG file, byte for
/// byte.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn vtfarm_submit_on_a_two_worker_cluster_writes_the_png_of_vtfarm_render() {
    let _serial = SERIAL.lock().await;
    let dir = tempfile::tempdir().unwrap();
    let job = dir.path().join("job.toml");
    std::fs::write(
        &job,
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n[camera]\nwidth = 192\nheight = 108\n",
    )
    .unwrap();
    let path = |p: &std::path::Path| p.to_str().unwrap().to_owned();
    let rendered = dir.path().join("render.png");
    vtfarm_cli(vec![
        "render".into(),
        path(&job),
        "-o".into(),
        path(&rendered),
        "--local-workers".into(),
        "1".into(),
    ])
    .await;
    let submitted = dir.path().join("submit");
    submit_on_a_two_worker_cluster(&job, &submitted).await;
    let (a, b) = (
        std::fs::read(&rendered).unwrap(),
        std::fs::read(submitted.join("frame_0000.png")).unwrap(),
    );
    assert!(
        a == b,
        "the PNGs differ ({} and {} bytes)",
        a.len(),
        b.len()
    );
    let decoded = image::load_from_memory(&b).unwrap().to_rgb8();
    assert_eq!((decoded.width(), decoded.height()), (192, 108));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_sun_sweep_on_a_two_worker_cluster_writes_the_same_files_as_on_one_machine() {
    let files = study_on_one_machine_and_a_cluster(
        "[eyes]\npoints = [[-0.55, 1.40, 0.10], [-0.60, 1.45, 0.12]]\n\
         [[variants]]\nname = \"current\"\nglass = \"current\"\n\
         [[variants]]\nname = \"flat\"\nglass = \"flat\"\n\
         [sun]\nazimuths = [90, 200]\nelevations = [20]\n",
    )
    .await;
    assert!(files.contains_key(std::path::Path::new("current/sun_001/eye_01/heat.png")));
    assert_eq!(
        files.len(),
        3 + 2 * 2 * 2 * 8,
        "three PNG images, the OpenEXR image and four arrays per frame: 2 variants x 2 suns x 2 eyes"
    );
    let csv = String::from_utf8(files[std::path::Path::new("summary.csv")].clone()).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(
        header.contains("sun_azimuth_deg") && header.contains("sun_elevation_deg"),
        "{header}"
    );
    // The two suns light the same design differently.
    let column = header
        .split(',')
        .position(|c| c == "mean_reflected_luminance_cd_m2")
        .unwrap();
    let mean_lr: Vec<&str> = csv
        .lines()
        .filter(|l| l.starts_with("current,0,"))
        .map(|l| l.split(',').nth(column).unwrap())
        .collect();
    assert_eq!(mean_lr.len(), 2, "{csv}");
    assert_ne!(mean_lr[0], mean_lr[1]);
}

/// Runs the study (`eyes`, `variants` and `[sun]` tables after a 192x108
/// header on the small cockpit) with `vtfarm study` on one machine and with
/// `vtfarm submit` on a two-worker localhost cluster; asserts that both
/// wrote the same files, byte for byte, and returns them.
async fn study_on_one_machine_and_a_cluster(
    tables: &str,
) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let _serial = SERIAL.lock().await;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("job.toml"),
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n",
    )
    .unwrap();
    let study = dir.path().join("study.toml");
    std::fs::write(
        &study,
        format!("[study]\njob = \"job.toml\"\nwidth = 192\nheight = 108\n{tables}"),
    )
    .unwrap();
    let path = |p: &std::path::Path| p.to_str().unwrap().to_owned();
    let one = dir.path().join("one-machine");
    vtfarm_cli(vec![
        "study".into(),
        path(&study),
        "-o".into(),
        path(&one),
        "--local-workers".into(),
        "1".into(),
    ])
    .await;
    let two = dir.path().join("cluster");
    submit_on_a_two_worker_cluster(&study, &two).await;
    // How the work splits between the two workers depends on timing (a worker
    // still fetching the scene gets none); the files below must not.

    let (a, b) = (files_under(&one), files_under(&two));
    let names: Vec<&PathBuf> = a.keys().collect();
    assert_eq!(names, b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        let (x, y) = (
            without_provenance(name, bytes),
            without_provenance(name, &b[name]),
        );
        assert!(x == y, "{} differs", name.display());
    }
    a
}

/// A study output without how it was made (date, workers, command differ
/// between the runs; every figure must not): `summary.json` without its
/// `provenance`, `report.html` without its provenance section.
fn without_provenance(name: &std::path::Path, bytes: &[u8]) -> Vec<u8> {
    match name.to_str() {
        Some("summary.json") => {
            let mut json: serde_json::Value = serde_json::from_slice(bytes).unwrap();
            let provenance = json.as_object_mut().unwrap().remove("provenance");
            assert!(provenance.is_some(), "summary.json says how it was made");
            serde_json::to_vec(&json).unwrap()
        }
        Some("report.html") => {
            let text = std::str::from_utf8(bytes).unwrap();
            let start = text
                .find("<section id=\"provenance\">")
                .expect("a provenance section");
            let end = start + text[start..].find("</section>").unwrap();
            format!("{}{}", &text[..start], &text[end..]).into_bytes()
        }
        _ => bytes.to_vec(),
    }
}

/// A child process, killed when dropped (a failing test leaves no orphans).
struct ChildGuard(Child);

impl Drop for ChildGuard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl ChildGuard {
    /// Waits (bounded) for the process to exit.
    async fn exit_status(&mut self, bound: Duration) -> std::process::ExitStatus {
        let deadline = tokio::time::Instant::now() + bound;
        loop {
            if let Some(status) = self.0.try_wait().unwrap() {
                return status;
            }
            assert!(
                tokio::time::Instant::now() < deadline,
                "the child did not exit within {bound:?}"
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
}

/// A bound for waits on the farm: generous for a loaded machine, but a
/// failing test ends.
const BOUND: Duration = Duration::from_secs(120);

impl Cluster {
    /// Waits (bounded) until the named worker holds a package.
    async fn wait_until_running(&self, name: &str) {
        let message = format!("{name} holding a package");
        let running =
            |s: &StatusReply| (s.workers.iter()).any(|w| w.name == name && w.packages_running > 0);
        self.wait_until(&message, running).await;
    }

    /// Waits (bounded) until the master lists `count` workers.
    async fn wait_for_worker_count(&self, count: usize) {
        let message = format!("the master listing {count} workers");
        self.wait_until(&message, |s| s.workers.len() == count)
            .await;
    }
}

type Submission = JoinHandle<Result<Vec<FinishedFrame>, JobError>>;

/// Submits `job` in a task (so that the test can act while it runs).
fn submit_in_background(cluster: &Arc<Cluster>, job: &Job) -> Submission {
    let cluster = cluster.clone();
    let job = Job {
        scene: job.scene.clone(),
        reflectors: job.reflectors.clone(),
        frames: job.frames.clone(),
    };
    tokio::spawn(async move { cluster.submit(&job).await })
}

// The load balance under a slowed worker and a kill at every moment of a
// frame are checked deterministically in master/tests/faults.rs; these two
// check the real processes, triggered by protocol events, every wait bounded.

/// A cluster whose only worker, a slowed child process named `name`, holds a
/// package of `job` (the trigger is `vtfarm status`, not a delay). Straggler
/// copies are off: the package must come back through the worker's loss.
async fn a_lone_worker_holding_a_package(
    job: &Job,
    heartbeat_timeout: Duration,
    name: &str,
    slowdown: f64,
) -> (Arc<Cluster>, ChildGuard, Submission) {
    let config = FarmRules {
        heartbeat_timeout,
        straggler: None,
        ..FarmRules::default()
    };
    let cluster = Arc::new(Cluster::start(config));
    let worker = ChildGuard(cluster.worker_process(name, slowdown));
    cluster.wait_for_workers(1).await;
    let submit = submit_in_background(&cluster, job);
    cluster.wait_until_running(name).await;
    (cluster, worker, submit)
}

/// The frames of a submission, bounded.
async fn finished(submit: Submission) -> Vec<FinishedFrame> {
    (tokio::time::timeout(BOUND, submit).await)
        .expect("the job finishes")
        .unwrap()
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_killed_worker_process_loses_its_package_to_a_newcomer() {
    let _serial = SERIAL.lock().await;
    let job = job(1, 160, 90);
    let reference = reference(&job);
    let (cluster, mut doomed, submit) =
        a_lone_worker_holding_a_package(&job, Duration::from_millis(1500), "doomed", 50.0).await;
    doomed.0.kill().unwrap();
    doomed.exit_status(BOUND).await;
    // Only the newcomer can finish the frame, and only with the lost package.
    let _survivor = cluster.worker("survivor", 1.0);
    let frames = finished(submit).await;
    assert_same_images(&frames, &reference);
    assert!(
        frames[0].stats.requeued >= 1,
        "its package went back to the queue: {:?}",
        frames[0].stats
    );
}

#[cfg(unix)]
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_worker_stopped_with_sigterm_finishes_its_package_and_says_goodbye() {
    let _serial = SERIAL.lock().await;
    let job = job(1, 160, 90);
    let reference = reference(&job);
    // A heartbeat timeout far beyond the test's bounds: the master can only
    // drop the worker early because it said goodbye.
    let config = FarmRules {
        heartbeat_timeout: Duration::from_secs(3600),
        straggler: None,
        ..FarmRules::default()
    };
    let cluster = Arc::new(Cluster::start(config));
    // Slowed so that its first package (a few triangles) still runs when
    // SIGTERM comes; the trigger is the worker's own word that it started it
    // (a package still on its way when the worker drains is rightly handed
    // back, and the master's status cannot tell the two apart).
    let (child, started) = cluster.worker_process_reporting_start("leaving", 200.0);
    let mut leaving = ChildGuard(child);
    cluster.wait_for_workers(1).await;
    let submit = submit_in_background(&cluster, &job);
    (tokio::time::timeout(BOUND, started).await)
        .expect("the worker starts a package in time")
        .expect("the worker's log is read");
    let sent = Command::new("kill")
        .args(["-TERM", &leaving.0.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = leaving.exit_status(BOUND).await;
    assert!(status.success(), "a drained worker exits cleanly: {status}");
    cluster.wait_for_worker_count(0).await;
    let _newcomer = cluster.worker("newcomer", 1.0);
    let frames = finished(submit).await;
    assert_same_images(&frames, &reference);
    let stats = &frames[0].stats;
    let leaving_packages: u32 = (stats.workers.iter())
        .filter(|w| w.name.starts_with("leaving"))
        .map(|w| w.packages)
        .sum();
    // The package it ran was finished and counted; at most the one it had
    // asked for ahead (queued behind it) went back to the queue.
    assert!(
        leaving_packages >= 1 && stats.requeued <= 1,
        "the running package was finished and counted: {stats:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn status_without_a_master_fails_fast_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let identity = server::identity(dir.path(), &["127.0.0.1".into()]).unwrap();
    // A port nobody listens on (bound, then closed).
    let free = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let address = free.local_addr().unwrap();
    drop(free);
    let cluster = ClusterConfig::generate(&address.to_string(), &identity).unwrap();
    let file = dir.path().join("cluster.toml");
    cluster.save(&file).unwrap();
    let args = ["status", "--cluster", file.to_str().unwrap()].map(String::from);
    // Before: the QUIC idle timeout (30 s) passed first.
    let (status, stderr) = run_vtfarm(&args, Duration::from_secs(20)).await;
    assert!(!status.success());
    assert!(
        stderr.contains(&address.to_string()) && stderr.contains("timed out"),
        "{stderr}"
    );
}

/// Opens a raw QUIC connection with the right certificate pin, writes `bytes`
/// on the first stream and returns the refusal code the master closes with.
async fn raw_client(options: &ClientOptions, bytes: &[u8]) -> Option<RefuseCode> {
    let mut endpoint = quinn::Endpoint::client("127.0.0.1:0".parse().unwrap()).unwrap();
    endpoint.set_default_client_config(client_config(&options.fingerprint).unwrap());
    let conn = endpoint
        .connect(options.master.parse().unwrap(), SERVER_NAME)
        .unwrap()
        .await
        .unwrap();
    let (mut send, mut recv) = conn.open_bi().await.unwrap();
    let _ = send.write_all(bytes).await;
    let _ = send.finish();
    let _ = recv.read_to_end(1 << 20).await;
    match tokio::time::timeout(Duration::from_secs(15), conn.closed()).await {
        Ok(quinn::ConnectionError::ApplicationClosed(close)) => {
            RefuseCode::from_close_code(close.error_code.into_inner())
        }
        _ => None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn bad_clients_are_refused_and_the_master_keeps_serving() {
    let _serial = SERIAL.lock().await;
    let job = job(1, 160, 90);
    let reference = reference(&job);
    let cluster = Cluster::start(FarmRules::default());
    let _w = cluster.worker("w", 1.0);
    cluster.wait_for_workers(1).await;

    let wrong_token = ClientOptions {
        token: "0".repeat(64),
        ..cluster.options.clone()
    };
    match connect(&wrong_token, Role::Submitter).await {
        Err(e) => assert!(
            matches!(
                &e,
                vtfarm_transport::client::ConnectError::Connect {
                    source: ProtoError::Refused {
                        code: RefuseCode::BadToken,
                        ..
                    },
                    ..
                }
            ),
            "{e}"
        ),
        Ok(_) => panic!("a wrong token was accepted"),
    }
    let newer = Hello {
        version: PROTOCOL_VERSION + 1,
        ..Hello::new(cluster.options.token.clone(), Role::Submitter)
    };
    let newer = encode_message(&Message::Hello(newer)).unwrap();
    assert_eq!(
        raw_client(&cluster.options, &newer).await,
        Some(RefuseCode::BadVersion)
    );
    let mut garbage = 12u32.to_le_bytes().to_vec();
    garbage.extend_from_slice(b"\xff\xfe garbage!");
    assert_eq!(
        raw_client(&cluster.options, &garbage).await,
        Some(RefuseCode::BadMessage)
    );
    assert_eq!(
        raw_client(&cluster.options, &u32::MAX.to_le_bytes()).await,
        Some(RefuseCode::TooLarge)
    );

    let frames = cluster.submit(&job).await.unwrap();
    assert_same_images(&frames, &reference);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_second_job_on_the_same_scene_transfers_no_scene_bytes() {
    let _serial = SERIAL.lock().await;
    let job = job(1, 160, 90);
    let cluster = Cluster::start(FarmRules::default());
    let _w = cluster.worker("w", 1.0);
    cluster.wait_for_workers(1).await;
    cluster.submit(&job).await.unwrap();
    let after_first = cluster.status().await.scene_bytes_sent;
    assert!(after_first > 0, "the first job sends the scene");
    cluster.submit(&job).await.unwrap();
    assert_eq!(
        cluster.status().await.scene_bytes_sent,
        after_first,
        "the second job sends no scene bytes"
    );
}

/// A master as a child process of the `vtfarm` binary on `listen`.
fn master_process(cluster_file: &std::path::Path, listen: std::net::SocketAddr) -> ChildGuard {
    ChildGuard(
        Command::new(env!("CARGO_BIN_EXE_vtfarm"))
            .args(["master", "--cluster", cluster_file.to_str().unwrap()])
            .args(["--listen", &listen.to_string()])
            // Any free port: a fixed dashboard port fails the master wherever
            // another one (another test run) already holds it.
            .args(["--http", "127.0.0.1:0"])
            .spawn()
            .expect("the vtfarm binary starts"),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_killed_master_resumes_its_job_after_a_restart_and_the_submitter_follows() {
    let _serial = SERIAL.lock().await;
    let job = job(4, 160, 90);
    let reference = reference(&job);
    let dir = tempfile::tempdir().unwrap();
    let identity = server::identity(dir.path(), &["127.0.0.1".into()]).unwrap();
    let free = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let address = free.local_addr().unwrap();
    drop(free);
    let config = ClusterConfig::generate(&address.to_string(), &identity).unwrap();
    let file = dir.path().join("cluster.toml");
    config.save(&file).unwrap();
    let options = ClientOptions {
        master: config.master.clone(),
        token: config.token.clone(),
        fingerprint: config.fingerprint.clone(),
    };
    let mut master = master_process(&file, address);
    let workers: Vec<JoinHandle<_>> = ["w1", "w2"]
        .into_iter()
        .map(|name| {
            let (options, cache) = (options.clone(), dir.path().join(name));
            tokio::spawn(run_worker(
                options,
                name.into(),
                1,
                Engine::new(Some(cache)),
                WorkerConfig {
                    slowdown: 4.0,
                    ..WorkerConfig::default()
                },
                DrainSignal::never(),
            ))
        })
        .collect();
    let (frame_tx, mut frame_rx) = tokio::sync::mpsc::unbounded_channel();
    let submit = {
        let data = SceneData::from_scene(&job.scene);
        let job_options = JobOptions {
            method: MethodKind::VertexTracing,
            aux: false,
        };
        let wire = wire_job("restart", &data, &job.frames, &job.reflectors, job_options);
        tokio::spawn(async move {
            // The master may still be starting: try until it answers.
            loop {
                let start = RemoteJob::Submit {
                    job: wire.clone(),
                    scene: &data,
                };
                let outcome = run_remote_job(&options, start, |event| {
                    if let vtfarm_submit::JobEvent::FrameDone(f) = event {
                        let _ = frame_tx.send(f.frame);
                    }
                })
                .await;
                match outcome {
                    Err(JobError::Connect(_)) => {
                        tokio::time::sleep(Duration::from_millis(100)).await
                    }
                    other => return other,
                }
            }
        })
    };
    // The trigger: the first finished frame (three remain).
    let first = tokio::time::timeout(BOUND, frame_rx.recv()).await;
    assert_eq!(first.expect("a first frame"), Some(0));
    master.0.kill().unwrap();
    master.exit_status(BOUND).await;
    let _restarted = master_process(&file, address);
    let frames = (tokio::time::timeout(BOUND, submit).await)
        .expect("the job finishes after the restart")
        .unwrap()
        .unwrap();
    assert_same_images(&frames, &reference);
    let journal = std::fs::read_dir(dir.path().join("jobs")).unwrap().count();
    assert_eq!(
        journal, 3,
        "the completed job stays journaled a while (with the scenes and the format)"
    );
    for w in workers {
        w.abort();
    }
}
