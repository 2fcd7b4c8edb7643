//! The master's HTTP side over real sockets on 127.0.0.1: a master, two
//! worker tasks over QUIC and the HTTP server; `/metrics` parses as
//! Prometheus text and moves when a job runs, `/api/status` and the event
//! stream agree with `vtfarm status`, finished frames are served as the
//! submitter received them, and a non-loopback peer needs the token.

#[path = "support/frame.rs"]
mod frame;

use frame::small_frame;
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use vtfarm_proto::JobId;

use axum::body::Body;
use axum::extract::connect_info::MockConnectInfo;
use axum::http::{Request, StatusCode};
use glam::Vec3;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::task::JoinHandle;
use tower::ServiceExt;
use vtfarm_browser::{Browser, Graphics, Options};
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::FarmRules;
use vtfarm_master::stream::StageMessage;
use vtfarm_master::view::ViewOutcome;
use vtfarm_master::{MasterHandle, http, server, spawn_master};
use vtfarm_method::MethodKind;
use vtfarm_proto::{HandshakePolicy, Role, SceneData, StatusReply};
use vtfarm_proto::{JobSummary, WireJobState};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_submit::{FinishedFrame, JobError, JobOptions, run_job, wire_job};
use vtfarm_transport::ClusterConfig;
use vtfarm_transport::client::{ClientOptions, connect};
use vtfarm_vertex::Quality;
use vtfarm_worker::{DrainSignal, Engine, WorkerConfig, run_worker};

/// Every wait on the network is bounded by this.
const WAIT: Duration = Duration::from_secs(60);

/// A master with its QUIC and HTTP servers on 127.0.0.1 and two workers.
struct Farm {
    dir: tempfile::TempDir,
    options: ClientOptions,
    master: MasterHandle,
    http: SocketAddr,
    _tasks: Vec<JoinHandle<()>>,
}

impl Farm {
    async fn start() -> Farm {
        Farm::with_workers(2).await
    }

    /// A farm of `workers` workers (none: a job runs and never progresses).
    async fn with_workers(workers: usize) -> Farm {
        let dir = tempfile::tempdir().unwrap();
        let identity = server::identity(dir.path(), &["127.0.0.1".into()]).unwrap();
        let endpoint = server::bind("127.0.0.1:0".parse().unwrap(), &identity).unwrap();
        let address = endpoint.local_addr().unwrap();
        let cluster = ClusterConfig::generate(&address.to_string(), &identity).unwrap();
        let (master, _) = spawn_master(FarmRules::default());
        let policy = HandshakePolicy::new(cluster.token.clone(), "test-master");
        let listener = http::bind("127.0.0.1:0".parse().unwrap()).await.unwrap();
        let http = listener.local_addr().unwrap();
        let tasks = vec![
            tokio::spawn(server::serve(endpoint, policy, master.clone())),
            tokio::spawn(http::serve(
                listener,
                master.clone(),
                http::HttpAccess::new(cluster.token.clone()),
                http::HttpLimits::default(),
            )),
        ];
        let options = ClientOptions {
            master: cluster.master,
            token: cluster.token,
            fingerprint: cluster.fingerprint,
        };
        let mut farm = Farm {
            dir,
            options,
            master,
            http,
            _tasks: tasks,
        };
        for name in ["w1", "w2"].into_iter().take(workers) {
            let (options, name) = (farm.options.clone(), name.to_owned());
            let engine = Engine::new(Some(farm.dir.path().join(format!("cache-{name}"))));
            farm._tasks.push(tokio::spawn(async move {
                let _ = run_worker(
                    options,
                    name,
                    1,
                    engine,
                    WorkerConfig::default(),
                    DrainSignal::never(),
                )
                .await;
            }));
        }
        farm.wait_until(|s| s.workers.len() == workers).await;
        farm
    }

    /// Submits a one-frame job from a task of its own that follows it
    /// until it ends (bounded); waits until the master lists it running.
    async fn submit_in_background(
        &self,
    ) -> (JobId, JoinHandle<Result<Vec<FinishedFrame>, JobError>>) {
        let c = cockpit(&CockpitConfig {
            detail: 0.3,
            ..CockpitConfig::default()
        });
        let setups = [small_frame(&c, Vec3::ZERO)];
        let reflectors = c.cover_glass_triangles();
        let data = SceneData::from_scene(&c.scene);
        let options = JobOptions {
            method: MethodKind::VertexTracing,
            aux: false,
        };
        let job = wire_job("background", &data, &setups, &reflectors, options);
        let mut conn = connect(&self.options, Role::Submitter).await.unwrap();
        let submitter = tokio::spawn(async move {
            let run = run_job(&mut conn.link, job, &data, |_| {});
            (tokio::time::timeout(WAIT, run).await).expect("the job ended in time")
        });
        self.wait_until(|s| !s.queue.running.is_empty()).await;
        let id = (self.master.inspect(|c| c.status().queue.running[0].job))
            .await
            .unwrap();
        (id, submitter)
    }

    /// Waits (bounded) for the master's state to satisfy `done`, woken by
    /// its change notifications.
    async fn wait_until(&self, done: impl Fn(&StatusReply) -> bool) {
        let reached = tokio::time::timeout(WAIT, self.master.wait_for_status(done)).await;
        (reached.expect("the farm reached the awaited state")).expect("the master runs");
    }

    /// What `vtfarm status` gets: a `StatusRequest` over QUIC.
    async fn quic_status(&self) -> StatusReply {
        let mut conn = connect(&self.options, Role::Submitter).await.unwrap();
        let reply = tokio::time::timeout(WAIT, conn.link.status()).await;
        (reply.expect("status reply")).expect("the master closed the connection")
    }

    async fn submit(&self, frames: usize) -> Vec<FinishedFrame> {
        let c = cockpit(&CockpitConfig {
            detail: 0.3,
            ..CockpitConfig::default()
        });
        let setups: Vec<FrameSetup> = (0..frames)
            .map(|k| small_frame(&c, Vec3::new(0.01, 0.0, 0.0) * k as f32))
            .collect();
        let reflectors = c.cover_glass_triangles();
        let data = SceneData::from_scene(&c.scene);
        let mut conn = connect(&self.options, Role::Submitter).await.unwrap();
        let job = wire_job(
            "http-test",
            &data,
            &setups,
            &reflectors,
            JobOptions {
                method: MethodKind::VertexTracing,
                aux: false,
            },
        );
        let run = run_job(&mut conn.link, job, &data, |_| {});
        (tokio::time::timeout(WAIT, run).await)
            .expect("the job finished in time")
            .expect("the job succeeded")
    }

    async fn get(&self, path: &str) -> Response {
        tokio::time::timeout(WAIT, get(self.http, path))
            .await
            .expect("HTTP answer in time")
    }

    async fn post(&self, path: &str, json: serde_json::Value) -> Response {
        tokio::time::timeout(WAIT, request(self.http, "POST", path, Some(json)))
            .await
            .expect("HTTP answer in time")
    }

    /// Waits (bounded) until `done` holds of the master's core, woken by
    /// its change notifications.
    async fn wait_for_core(
        &self,
        done: impl Fn(&vtfarm_master::MasterCore) -> bool + Clone + Send + 'static,
    ) {
        let mut changes = self.master.changes();
        let check = async {
            loop {
                changes.mark_unchanged();
                if self.master.inspect(done.clone()).await.unwrap() {
                    return;
                }
                changes.changed().await.unwrap();
            }
        };
        tokio::time::timeout(WAIT, check)
            .await
            .expect("the master reached the awaited state");
    }
}

struct Response {
    status: u16,
    headers: BTreeMap<String, String>,
    body: Vec<u8>,
}

impl Response {
    fn text(&self) -> &str {
        std::str::from_utf8(&self.body).expect("UTF-8 body")
    }
}

/// A plain HTTP/1.1 GET over a fresh connection.
async fn get(address: SocketAddr, path: &str) -> Response {
    request(address, "GET", path, None).await
}

/// A plain HTTP/1.1 request over a fresh connection, with an optional JSON
/// body.
async fn request(
    address: SocketAddr,
    method: &str,
    path: &str,
    json: Option<serde_json::Value>,
) -> Response {
    let body = json.map(|j| j.to_string()).unwrap_or_default();
    let request = format!(
        "{method} {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    exchange(address, &request).await
}

/// Sends `request` (head and body as given) over a fresh connection; reads
/// the headers, then exactly `Content-Length` bytes (servers need not
/// close the connection).
async fn exchange(address: SocketAddr, request: &str) -> Response {
    let stream = TcpStream::connect(address).await.unwrap();
    let mut stream = BufReader::new(stream);
    stream
        .get_mut()
        .write_all(request.as_bytes())
        .await
        .unwrap();
    let mut status_line = String::new();
    stream.read_line(&mut status_line).await.unwrap();
    let status = status_line.split(' ').nth(1).unwrap().parse().unwrap();
    let mut headers = BTreeMap::new();
    loop {
        let mut line = String::new();
        stream.read_line(&mut line).await.unwrap();
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        let (key, value) = line.split_once(':').expect("header line");
        headers.insert(key.to_ascii_lowercase(), value.trim().to_owned());
    }
    let length: usize = headers
        .get("content-length")
        .map_or(0, |l| l.parse().unwrap());
    let mut body = vec![0; length];
    stream.read_exact(&mut body).await.unwrap();
    Response {
        status,
        headers,
        body,
    }
}

/// The first `farm` event of the event stream, as JSON.
async fn first_event(address: SocketAddr) -> serde_json::Value {
    let read = async {
        let mut stream = TcpStream::connect(address).await.unwrap();
        let request = format!("GET /api/events HTTP/1.1\r\nHost: {address}\r\n\r\n");
        stream.write_all(request.as_bytes()).await.unwrap();
        let mut lines = BufReader::new(stream).lines();
        let mut in_farm_event = false;
        while let Some(line) = lines.next_line().await.unwrap() {
            if line == "event: farm" {
                in_farm_event = true;
            } else if let (true, Some(data)) = (in_farm_event, line.strip_prefix("data: ")) {
                return serde_json::from_str(data).expect("event data is JSON");
            }
        }
        panic!("the event stream ended");
    };
    tokio::time::timeout(WAIT, read)
        .await
        .expect("an event in time")
}

/// Parses Prometheus/OpenMetrics text into `name{labels}` -> value, checking
/// every line's form: `# HELP|TYPE|UNIT`, samples, and `# EOF` last.
fn parse_metrics(text: &str) -> BTreeMap<String, f64> {
    let mut samples = BTreeMap::new();
    let mut lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines.pop(),
        Some("# EOF"),
        "OpenMetrics text ends with # EOF"
    );
    for line in lines {
        if let Some(comment) = line.strip_prefix("# ") {
            let kind = comment.split(' ').next().unwrap();
            assert!(
                ["HELP", "TYPE", "UNIT"].contains(&kind),
                "comment line: {line}"
            );
            continue;
        }
        let (series, value) = line.rsplit_once(' ').expect("sample line: NAME VALUE");
        let name_end = series.find('{').unwrap_or(series.len());
        let name = &series[..name_end];
        assert!(
            !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'),
            "metric name in {line}"
        );
        if name_end < series.len() {
            assert!(series.ends_with('}'), "label set closes: {line}");
        }
        let value: f64 = match value {
            "+Inf" => f64::INFINITY,
            v => v
                .parse()
                .unwrap_or_else(|_| panic!("sample value in {line}")),
        };
        assert!(
            samples.insert(series.to_owned(), value).is_none(),
            "duplicate {series}"
        );
    }
    samples
}

fn sum_of(samples: &BTreeMap<String, f64>, name: &str) -> f64 {
    (samples.iter())
        .filter(|(series, _)| series.split('{').next() == Some(name))
        .map(|(_, v)| v)
        .sum()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn metrics_move_when_a_job_runs_and_every_view_matches_vtfarm_status() {
    let farm = Farm::start().await;
    let before = farm.get("/metrics").await;
    assert_eq!(before.status, 200);
    assert!(before.headers["content-type"].starts_with("application/openmetrics-text"));
    let before = parse_metrics(before.text());
    assert_eq!(before["vtfarm_frames_total"], 0.0);
    assert_eq!(before["vtfarm_jobs_total{state=\"completed\"}"], 0.0);
    assert_eq!(before["vtfarm_frame_duration_seconds_count"], 0.0);
    assert_eq!(sum_of(&before, "vtfarm_workers"), 2.0);

    let frames = farm.submit(2).await;
    assert_eq!(frames.len(), 2);
    // The job's end reaches the master before the submitter hears of it,
    // but wait for the workers to be idle again so the figures hold still.
    farm.wait_until(|s| {
        s.queue.running.is_empty() && s.workers.iter().all(|w| w.packages_running == 0)
    })
    .await;

    let after = parse_metrics(farm.get("/metrics").await.text());
    assert_eq!(after["vtfarm_frames_total"], 2.0);
    assert_eq!(after["vtfarm_jobs_total{state=\"submitted\"}"], 1.0);
    assert_eq!(after["vtfarm_jobs_total{state=\"completed\"}"], 1.0);
    assert_eq!(after["vtfarm_frame_duration_seconds_count"], 2.0);
    assert_eq!(
        after["vtfarm_frame_duration_seconds_bucket{le=\"+Inf\"}"],
        2.0
    );
    let packages: u32 = frames.iter().map(|f| f.stats.packages).sum();
    assert_eq!(
        after["vtfarm_packages_total{state=\"done\"}"],
        f64::from(packages)
    );
    let samples: u64 = (frames.iter())
        .flat_map(|f| &f.stats.workers)
        .map(|w| w.rays)
        .sum();
    assert_eq!(
        sum_of(&after, "vtfarm_worker_samples_total"),
        samples as f64
    );
    assert!(sum_of(&after, "vtfarm_worker_bytes_total") > 0.0);
    assert!(sum_of(&after, "vtfarm_worker_busy_seconds") > 0.0);

    // One source: the status API, the event stream and `vtfarm status`.
    let quic = farm.quic_status().await;
    assert_eq!(quic.workers.len(), 2);
    let api: StatusReply = serde_json::from_slice(&farm.get("/api/status").await.body).unwrap();
    assert_eq!(api, quic);
    let event = first_event(farm.http).await;
    let streamed: StatusReply = serde_json::from_value(event["status"].clone()).unwrap();
    assert_eq!(streamed, quic);
    assert_eq!(event["counters"]["frames_completed"], 2);
    assert_eq!(event["frames"].as_array().unwrap().len(), 2);

    // Finished frames come back as the submitter received them.
    for (seq, frame) in (1..).zip(&frames) {
        let png = farm.get(&format!("/frames/{seq}.png")).await;
        assert_eq!(png.headers["content-type"], "image/png");
        let decoded = image::load_from_memory(&png.body).unwrap().to_rgb8();
        assert_eq!(decoded.as_raw(), &frame.image.to_srgb8(), "frame {seq}");
    }
    assert_eq!(farm.get("/frames/99.png").await.status, 404);
    assert_eq!(
        farm.get("/frames/live.png").await.status,
        404,
        "nothing running"
    );
    let page = farm.get("/").await;
    assert!(page.text().contains("EventSource(\"/api/events\")"));
    let timeline = farm.get("/frames/2.svg").await;
    assert_eq!(timeline.headers["content-type"], "image/svg+xml");
    assert!(timeline.text().starts_with("<svg") && timeline.text().contains(">master<"));

    // The interactive view over HTTP: a refused move, then one that renders
    // to `full`; its image is served as the core holds it.
    assert_eq!(farm.get("/view/image.png").await.status, 404, "no view yet");
    let refused = farm
        .post(
            "/api/view",
            serde_json::json!({ "job": 99, "offset": [0, 0, 0] }),
        )
        .await;
    assert_eq!(refused.status, 400);
    assert!(refused.text().contains("job 99"), "{}", refused.text());
    let moved = farm
        .post(
            "/api/view",
            serde_json::json!({ "job": 1, "offset": [0.01, 0, 0] }),
        )
        .await;
    assert_eq!(moved.status, 200, "{}", moved.text());
    let view_job: serde_json::Value = serde_json::from_slice(&moved.body).unwrap();
    farm.wait_for_core(|c| {
        c.views()
            .latest()
            .is_some_and(|l| l.quality == Quality::Full)
    })
    .await;
    let core_view = (farm.master)
        .inspect(|c| c.views().latest().unwrap().image().clone())
        .await
        .unwrap();
    assert_eq!(
        view_job["job"],
        farm.master
            .inspect(|c| c.views().current().unwrap().job.0)
            .await
            .unwrap()
    );
    let png = farm.get("/view/image.png").await;
    let decoded = image::load_from_memory(&png.body).unwrap().to_rgb8();
    assert_eq!(decoded.as_raw(), &core_view.to_srgb8());
    // At a display's width: reduced by the whole factor that fits it (96
    // pixels into 40: 3), again the same bytes the second time (kept); a
    // display at least as wide gets the stage's own pixels.
    for _ in 0..2 {
        let small = farm.get("/view/image.png?width=40&stage=x").await;
        assert_eq!(small.status, 200, "{}", small.text());
        let decoded = image::load_from_memory(&small.body).unwrap().to_rgb8();
        assert_eq!((decoded.width(), decoded.height()), (32, 18));
        assert_eq!(decoded.as_raw(), &core_view.reduced(3).to_srgb8());
    }
    assert_eq!(farm.get("/view/image.png?width=96").await.body, png.body);
    for bad in ["width=0", "width=-3", "width=wide"] {
        let refused = farm.get(&format!("/view/image.png?{bad}")).await;
        assert_eq!(refused.status, 400, "{bad}: {}", refused.text());
    }
    // The figures come after the stage went on view, and the object map with them.
    farm.wait_for_core(|c| c.views().latest().is_some_and(|l| l.figures.is_some()))
        .await;
    assert_eq!(farm.get("/view/objects.png").await.status, 200);
}

/// `GET /api/jobs`, `GET /api/jobs/{id}` and `POST /api/jobs/{id}/…`
/// over real sockets: the listing, pause, resume, priority and cancel of a running job (whose
/// submitter hears of it), the refusals, and `/metrics`' per-state gauges
/// agreeing with the listing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_jobs_api_lists_and_changes_jobs_and_the_metrics_agree() {
    // No worker: the job runs and makes no progress.
    let farm = Farm::with_workers(0).await;
    let (id, submitter) = farm.submit_in_background().await;
    let jobs = |r: &Response| -> Vec<JobSummary> { serde_json::from_slice(&r.body).unwrap() };
    let listed = jobs(&farm.get("/api/jobs").await);
    assert_eq!(listed.len(), 1);
    assert_eq!((listed[0].id, listed[0].state), (id, WireJobState::Running));
    assert_eq!(listed[0].name, "background");
    assert_eq!(listed[0].frames_total, 1);
    assert!(
        listed[0].host.starts_with("127.0.0.1:"),
        "{}",
        listed[0].host
    );
    // One job by its id, as listed.
    let one = farm.get(&format!("/api/jobs/{id}")).await;
    assert_eq!(one.status, 200, "{}", one.text());
    assert_eq!(
        serde_json::from_slice::<JobSummary>(&one.body).unwrap(),
        listed[0]
    );
    assert_eq!(farm.get("/api/jobs/99").await.status, 404);

    let farm = &farm;
    let post = |action: &'static str, body: serde_json::Value| {
        let path = format!("/api/jobs/{id}/{action}");
        async move { farm.post(&path, body).await }
    };
    let state_of = |r: &Response| -> WireJobState {
        assert_eq!(r.status, 200, "{}", r.text());
        serde_json::from_slice::<JobSummary>(&r.body).unwrap().state
    };
    assert_eq!(
        state_of(&post("pause", serde_json::json!({})).await),
        WireJobState::Paused
    );
    let again = post("pause", serde_json::json!({})).await;
    assert_eq!(again.status, 409);
    assert!(again.text().contains("is paused"), "{}", again.text());
    assert_eq!(
        state_of(&post("resume", serde_json::json!({})).await),
        WireJobState::Running
    );
    let raised = post("priority", serde_json::json!({ "priority": 7 })).await;
    assert_eq!(raised.status, 200, "{}", raised.text());
    assert_eq!(
        serde_json::from_slice::<JobSummary>(&raised.body)
            .unwrap()
            .priority,
        7
    );
    assert_eq!(post("priority", serde_json::json!({})).await.status, 400);
    assert_eq!(post("explode", serde_json::json!({})).await.status, 400);
    assert_eq!(
        farm.post("/api/jobs/99/cancel", serde_json::json!({}))
            .await
            .status,
        404
    );

    let cancelled = post("cancel", serde_json::json!({})).await;
    assert_eq!(state_of(&cancelled), WireJobState::Cancelled);
    let ended = (tokio::time::timeout(WAIT, submitter).await)
        .expect("the submitter ended")
        .unwrap();
    match ended {
        Err(JobError::Cancelled { job, reason }) => {
            assert_eq!(job, id);
            assert!(
                reason.contains(&format!(
                    "job {id} was cancelled by the dashboard (127.0.0.1:"
                )),
                "{reason}"
            );
        }
        other => panic!("the submitter got {other:?}"),
    }
    assert_eq!(post("cancel", serde_json::json!({})).await.status, 409);
    // A finished job's state allows a requeue only.
    for (action, body) in [
        ("priority", serde_json::json!({ "priority": 3 })),
        ("pause", serde_json::json!({})),
        ("resume", serde_json::json!({})),
    ] {
        let refused = post(action, body).await;
        assert_eq!(refused.status, 409, "{action}: {}", refused.text());
        assert!(
            refused.text().contains("is cancelled"),
            "{}",
            refused.text()
        );
    }
    let listed = jobs(&farm.get("/api/jobs").await);
    assert_eq!(
        listed[0].priority, 7,
        "the finished job's priority is as it was"
    );

    // The gauges count the listing's states.
    let listed = jobs(&farm.get("/api/jobs").await);
    let metrics = parse_metrics(farm.get("/metrics").await.text());
    for state in [
        "queued",
        "running",
        "paused",
        "completed",
        "failed",
        "cancelled",
    ] {
        let n = listed
            .iter()
            .filter(|j| serde_json::to_value(j.state).unwrap() == state)
            .count();
        assert_eq!(
            metrics[&format!("vtfarm_jobs_now{{state=\"{state}\"}}")],
            n as f64,
            "{state}"
        );
    }
    assert_eq!(metrics["vtfarm_jobs_now{state=\"cancelled\"}"], 1.0);
    assert_eq!(metrics["vtfarm_jobs_total{state=\"submitted\"}"], 1.0);
    assert_eq!(metrics["vtfarm_jobs_total{state=\"cancelled\"}"], 1.0);
}

/// What a page of another site can send with `fetch(url, {method: "POST",
/// mode: "no-cors"})` or a form, and what a sibling site (same site,
/// another origin) can: every one refused over real sockets while the
/// job keeps running; preflights (Private Network Access ones included)
/// are refused; the dashboard's own requests (its origin, JSON) work.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_from_other_sites_are_refused_and_the_job_keeps_running() {
    let farm = Farm::with_workers(0).await;
    let (id, submitter) = farm.submit_in_background().await;
    let address = farm.http;
    let port = address.port();
    let post = |path: String, headers: &str, body: &str| {
        format!(
            "POST {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n{headers}\
             Content-Length: {}\r\n\r\n{body}",
            body.len()
        )
    };
    let evil = "Origin: https://evil.example\r\nSec-Fetch-Site: cross-site\r\n";
    let sibling = format!("Origin: http://other.localhost:{port}\r\nSec-Fetch-Site: same-site\r\n");
    let plain = "Content-Type: text/plain;charset=UTF-8\r\n";
    let json = "Content-Type: application/json\r\n";
    let priority = r#"{"priority": 9}"#;
    let refused = [
        // fetch(…, {method: "POST", mode: "no-cors"}): no body.
        (post(format!("/api/jobs/{id}/cancel"), evil, ""), 403),
        (post(format!("/api/jobs/{id}/pause"), evil, ""), 403),
        (
            post(
                format!("/api/jobs/{id}/priority"),
                &format!("{evil}{plain}"),
                priority,
            ),
            403,
        ),
        // A sibling site, marked same-site by the browser.
        (
            post(
                format!("/api/jobs/{id}/cancel"),
                &format!("{sibling}{json}"),
                "",
            ),
            403,
        ),
        // Another origin named without Sec-Fetch-Site (an older browser).
        (
            post(
                format!("/api/jobs/{id}/cancel"),
                &format!("Origin: http://127.0.0.1:{}\r\n{json}", port + 1),
                "",
            ),
            403,
        ),
        (
            post(
                format!("/api/jobs/{id}/cancel"),
                &format!("Origin: null\r\n{json}"),
                "",
            ),
            403,
        ),
        // No browser header at all, and not JSON: what a form or
        // no-cors fetch of a browser that sends neither would make.
        (post(format!("/api/jobs/{id}/cancel"), plain, ""), 415),
        (
            post(format!("/api/jobs/{id}/priority"), plain, priority),
            415,
        ),
        (
            post(
                "/api/view".into(),
                &format!("{evil}{json}"),
                r#"{"job": 1, "offset": [0, 0, 0]}"#,
            ),
            403,
        ),
        (
            post(
                "/login".into(),
                &format!("{evil}Content-Type: application/x-www-form-urlencoded\r\n"),
                "token=x",
            ),
            403,
        ),
    ];
    for (request, code) in &refused {
        let answer = exchange(address, request).await;
        assert_eq!(answer.status, *code, "{request}\n{}", answer.text());
    }
    // Preflights, a Private Network Access one included: no CORS header
    // lets the page go on.
    for headers in [
        "Access-Control-Request-Method: POST\r\nAccess-Control-Request-Headers: content-type\r\n",
        "Access-Control-Request-Method: GET\r\nAccess-Control-Request-Private-Network: true\r\n",
    ] {
        let request = format!(
            "OPTIONS /api/jobs/{id}/cancel HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\
             Origin: https://evil.example\r\nSec-Fetch-Site: cross-site\r\nSec-Fetch-Mode: cors\r\n{headers}\r\n"
        );
        let answer = exchange(address, &request).await;
        assert_eq!(answer.status, 403, "{headers}");
        for header in [
            "access-control-allow-origin",
            "access-control-allow-private-network",
        ] {
            assert!(
                !answer.headers.contains_key(header),
                "{header} in {:?}",
                answer.headers
            );
        }
    }
    let listed: Vec<JobSummary> =
        serde_json::from_slice(&farm.get("/api/jobs").await.body).unwrap();
    assert_eq!(
        (listed[0].state, listed[0].priority),
        (WireJobState::Running, 0)
    );
    // No other site may frame the dashboard or load its images.
    let page = farm.get("/").await;
    assert_eq!(page.headers["x-frame-options"], "DENY");
    assert_eq!(page.headers["cross-origin-resource-policy"], "same-origin");

    // The dashboard's own request: its origin, JSON.
    let own = format!("Origin: http://{address}\r\nSec-Fetch-Site: same-origin\r\n{json}");
    let answer = exchange(
        address,
        &post(format!("/api/jobs/{id}/priority"), &own, priority),
    )
    .await;
    assert_eq!(answer.status, 200, "{}", answer.text());
    let answer = exchange(address, &post(format!("/api/jobs/{id}/cancel"), &own, "")).await;
    assert_eq!(answer.status, 200, "{}", answer.text());
    let ended = (tokio::time::timeout(WAIT, submitter).await)
        .expect("the submitter ended")
        .unwrap();
    assert!(
        matches!(ended, Err(JobError::Cancelled { job, .. }) if job == id),
        "{ended:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_peer_off_loopback_needs_the_cluster_token() {
    let (master, _task) = spawn_master(FarmRules::default());
    let token = "c0ffee".to_owned();
    // `request` from `peer`, with that authorization header if any.
    let send = |mut request: axum::http::request::Builder,
                peer: SocketAddr,
                authorization: Option<&str>| {
        let app = http::router(master.clone(), http::HttpAccess::new(token.clone()))
            .layer(MockConnectInfo(peer));
        if let Some(value) = authorization {
            request = request.header("authorization", value);
        }
        app.oneshot(request.body(Body::empty()).unwrap())
    };
    // Reading and changing jobs follow the same rule.
    let cancel = |peer, authorization| {
        let request =
            Request::post("/api/jobs/5/cancel").header("content-type", "application/json");
        send(request, peer, authorization)
    };
    let outsider: SocketAddr = "192.0.2.7:40000".parse().unwrap();
    let code = |r: axum::response::Response| r.status();
    assert_eq!(
        code(cancel(outsider, None).await.unwrap()),
        StatusCode::UNAUTHORIZED
    );
    // Let through, it finds no job 5.
    let allowed = cancel(outsider, Some("Bearer c0ffee")).await.unwrap();
    assert_eq!(code(allowed), StatusCode::NOT_FOUND);
    let ask = |peer, authorization| send(Request::get("/api/status"), peer, authorization);
    let remote: SocketAddr = "192.0.2.7:40000".parse().unwrap();
    let local: SocketAddr = "127.0.0.1:40000".parse().unwrap();
    let mapped_local: SocketAddr = "[::ffff:127.0.0.1]:40000".parse().unwrap();
    let status = |r: axum::response::Response| r.status();
    assert_eq!(
        status(ask(remote, None).await.unwrap()),
        StatusCode::UNAUTHORIZED
    );
    assert_eq!(
        status(ask(remote, Some("Bearer wrong")).await.unwrap()),
        StatusCode::UNAUTHORIZED
    );
    assert_eq!(
        status(ask(remote, Some("c0ffee")).await.unwrap()),
        StatusCode::UNAUTHORIZED
    );
    assert_eq!(
        status(ask(remote, Some("Bearer c0ffee")).await.unwrap()),
        StatusCode::OK
    );
    assert_eq!(status(ask(local, None).await.unwrap()), StatusCode::OK);
    assert_eq!(
        status(ask(mapped_local, None).await.unwrap()),
        StatusCode::OK
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_browser_off_loopback_logs_in_once_and_keeps_a_cookie() {
    let (master, _task) = spawn_master(FarmRules::default());
    let remote: SocketAddr = "192.0.2.7:40000".parse().unwrap();
    let app = http::router(master.clone(), http::HttpAccess::new("c0ffee"))
        .layer(MockConnectInfo(remote));
    let send = |request: Request<Body>| app.clone().oneshot(request);
    let get_with = |path: &str, header: Option<(&str, &str)>| {
        let mut request = Request::get(path);
        if let Some((name, value)) = header {
            request = request.header(name, value);
        }
        request.body(Body::empty()).unwrap()
    };
    let login = |token: &str| {
        Request::post("/login")
            .header("content-type", "application/x-www-form-urlencoded")
            .body(Body::from(format!("token={token}")))
            .unwrap()
    };
    // A browser without the cookie is sent to the login page, which it may see.
    let page = send(get_with("/", Some(("accept", "text/html"))))
        .await
        .unwrap();
    assert_eq!(page.status(), StatusCode::SEE_OTHER);
    assert_eq!(page.headers()["location"], "/login");
    let form = send(get_with("/login", None)).await.unwrap();
    assert_eq!(form.status(), StatusCode::OK);
    let body = axum::body::to_bytes(form.into_body(), 1 << 20)
        .await
        .unwrap();
    assert!(
        std::str::from_utf8(&body)
            .unwrap()
            .contains("name=\"token\"")
    );

    let wrong = send(login("tea")).await.unwrap();
    assert_eq!(wrong.status(), StatusCode::UNAUTHORIZED);
    assert!(wrong.headers().get("set-cookie").is_none());

    let right = send(login("c0ffee")).await.unwrap();
    assert_eq!(right.status(), StatusCode::SEE_OTHER);
    assert_eq!(right.headers()["location"], "/");
    let set_cookie = right.headers()["set-cookie"].to_str().unwrap().to_owned();
    assert!(set_cookie.contains("HttpOnly") && set_cookie.contains("SameSite=Strict"));
    let cookie = set_cookie.split(';').next().unwrap().to_owned();
    assert!(cookie.starts_with(http::SESSION_COOKIE));
    assert!(
        !cookie.contains("c0ffee"),
        "the cookie does not carry the token"
    );

    let among_others = format!("theme=dark; {cookie}");
    let ok = send(get_with("/api/status", Some(("cookie", &among_others))))
        .await
        .unwrap();
    assert_eq!(ok.status(), StatusCode::OK);
    let forged = format!("{}=c0ffee", http::SESSION_COOKIE);
    let forged = send(get_with("/api/status", Some(("cookie", &forged))))
        .await
        .unwrap();
    assert_eq!(forged.status(), StatusCode::UNAUTHORIZED);
    let none = send(get_with("/api/status", None)).await.unwrap();
    assert_eq!(none.status(), StatusCode::UNAUTHORIZED);
    // Bearer tokens keep working beside the cookie.
    let bearer = send(get_with(
        "/api/status",
        Some(("authorization", "Bearer c0ffee")),
    ))
    .await
    .unwrap();
    assert_eq!(bearer.status(), StatusCode::OK);
}

/// The page's canvas, read back: its width, height and RGB rows from the
/// top, as the CPU's images hold them.
async fn canvas_pixels(browser: &mut Browser) -> (usize, usize, Vec<[u8; 3]>) {
    let pixels = browser
        .eval(
            r#"(() => {
            const canvas = document.getElementById("view-gl");
            const gl = canvas.getContext("webgl2");
            const out = new Uint8Array(canvas.width * canvas.height * 4);
            gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, out);
            return [canvas.width, canvas.height, Array.from(out)];
        })()"#,
        )
        .await
        .unwrap();
    let (width, height) = (
        pixels[0].as_u64().unwrap() as usize,
        pixels[1].as_u64().unwrap() as usize,
    );
    let rgba: Vec<u8> = (pixels[2].as_array().unwrap().iter())
        .map(|v| v.as_u64().unwrap() as u8)
        .collect();
    // Read back bottom row first: the frame's row y is the canvas's height - 1 - y.
    let rows = (0..height).rev().flat_map(|y| {
        let rgba = &rgba;
        (0..width).map(move |x| {
            let at = (y * width + x) * 4;
            [rgba[at], rgba[at + 1], rgba[at + 2]]
        })
    });
    (width, height, rows.collect())
}

/// How a canvas agrees with the CPU's frame of the same eye: on the glass
/// with the render, off it with the base frame.
#[derive(Debug)]
struct StillEye {
    glass: usize,
    /// Within 8/255 in every channel.
    glass_close: usize,
    glass_same: usize,
    /// The largest difference on the glass.
    worst: u8,
    off_glass: usize,
    off_glass_close: usize,
}

fn still_eye(
    (width, height, shown): &(usize, usize, Vec<[u8; 3]>),
    render: &vtfarm_vertex::FrameImage,
    base_srgb: &[u8],
) -> StillEye {
    assert_eq!(*width as u32, render.color.width);
    assert_eq!(*height as u32, render.color.height);
    let render_srgb = render.color.to_srgb8();
    let rgb = |bytes: &[u8], i: usize| [bytes[i * 3], bytes[i * 3 + 1], bytes[i * 3 + 2]];
    let close = |a: [u8; 3], b: [u8; 3]| (0..3).all(|k| a[k].abs_diff(b[k]) <= 8);
    let mut out = StillEye {
        glass: 0,
        glass_close: 0,
        glass_same: 0,
        worst: 0,
        off_glass: 0,
        off_glass_close: 0,
    };
    for (i, &page) in shown.iter().enumerate() {
        if render.is_glass(i) {
            let cpu = rgb(&render_srgb, i);
            out.glass += 1;
            out.glass_close += usize::from(close(page, cpu));
            out.glass_same += usize::from(page == cpu);
            out.worst = (0..3)
                .map(|k| page[k].abs_diff(cpu[k]))
                .fold(out.worst, u8::max);
        } else {
            out.off_glass += 1;
            out.off_glass_close += usize::from(close(page, rgb(base_srgb, i)));
        }
    }
    out
}

/// Headless Chromium (a 1100×900 window) without WebGL: the view falls
/// back to the master's images. Without Chromium the test fails, unless
/// the run is not CI's and `VTFARM_ALLOW_NO_BROWSER=1` asks for a run
/// without the browser (`None`, said aloud).
async fn start_browser() -> Option<Browser> {
    start_browser_with(Graphics::NoWebGl).await
}

/// [`start_browser`] with WebGL2 on SwiftShader.
async fn start_browser_with_webgl() -> Option<Browser> {
    start_browser_with(Graphics::SwiftShader).await
}

async fn start_browser_with(graphics: Graphics) -> Option<Browser> {
    let Ok(path) = vtfarm_browser::which_chromium() else {
        no_browser();
        return None;
    };
    let options = Options {
        graphics,
        window: [1100, 900],
        timeout: WAIT,
        end_with_this_thread: false,
    };
    Some(
        Browser::start(&path, &options)
            .await
            .expect("chromium starts"),
    )
}

/// The opt-out of a machine without Chromium: never under CI (`CI` set to
/// anything but `false` or `0`), elsewhere only when asked for by name.
const ALLOW_NO_BROWSER: &str = "VTFARM_ALLOW_NO_BROWSER";

/// Fails the test for want of Chromium, or (outside CI, with
/// `VTFARM_ALLOW_NO_BROWSER=1`) says aloud that it did not run.
fn no_browser() {
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0");
    let allowed = std::env::var(ALLOW_NO_BROWSER).is_ok_and(|v| v == "1");
    assert!(
        !ci,
        "no `chromium` on PATH, and CI always runs the browser test (apt-get install chromium)"
    );
    assert!(
        allowed,
        "no `chromium` on PATH: install it (apt-get install chromium), or set \
         {ALLOW_NO_BROWSER}=1 to run the other tests without the browser test"
    );
    eprintln!("SKIPPED: no `chromium` on this machine and {ALLOW_NO_BROWSER}=1");
}

/// FNV-1a over the RGB bytes, as the dashboard hashes what it drew.
fn fnv1a(bytes: &[u8]) -> String {
    let hash = bytes.iter().fold(0x811c_9dc5_u32, |h, &b| {
        (h ^ u32::from(b)).wrapping_mul(0x0100_0193)
    });
    format!("{hash:08x}")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_dashboard_in_chromium_shows_both_workers_the_finished_frame_and_the_moved_eye() {
    let Some(mut browser) = start_browser().await else {
        return;
    };
    let farm = Farm::start().await;
    let url = format!("http://{}/", farm.http);
    browser
        .call("Page.enable", serde_json::json!({}))
        .await
        .unwrap();
    browser
        .call("Page.navigate", serde_json::json!({ "url": url }))
        .await
        .unwrap();
    browser.event("Page.loadEventFired").await.unwrap();
    // Armed before the job starts: resolves when the page has drawn
    // finished frame #1 (the page's own event), whatever the timing.
    let arm = r#"window.shownFrame = new Promise((resolve) => {
        const done = () => document.getElementById("frame").dataset.seq === "1"
            && document.getElementById("frame").dataset.state === "shown";
        if (done()) resolve();
        document.addEventListener("vtfarm-frame-shown", () => { if (done()) resolve(); });
    }); true"#;
    assert_eq!(browser.eval(arm).await.unwrap(), true);
    let frames = farm.submit(1).await;
    let shown = browser
        .eval(
            r##"window.shownFrame.then(() => ({
                hash: document.getElementById("frame").dataset.hash,
                workers: [...document.querySelectorAll("#workers tr td:first-child")].map((td) => td.textContent),
            }))"##,
        )
        .await.unwrap();
    assert_eq!(
        shown["hash"],
        fnv1a(&frames[0].image.to_srgb8()),
        "pixels equal the submitted image"
    );
    let mut workers: Vec<&str> = (shown["workers"].as_array().unwrap().iter())
        .map(|w| w.as_str().unwrap())
        .collect();
    workers.sort_unstable();
    assert_eq!(workers, ["w1", "w2"]);

    // The interactive view: pick the job's scene, then three quick moves
    // with the keys. Armed first: resolves when the page shows the newest
    // move's `full` stage with its figures (the page's own events, whatever
    // the timing).
    let pick = r#"new Promise((resolve) => {
        const select = document.getElementById("view-source");
        const pick = () => {
            if (![...select.options].some((o) => o.value === "1")) return false;
            select.value = "1";
            select.dispatchEvent(new Event("change"));
            return true;
        };
        if (pick()) return resolve(true);
        const retry = () => { if (pick()) { document.removeEventListener("vtfarm-update", retry); resolve(true); } };
        document.addEventListener("vtfarm-update", retry);
    })"#;
    assert_eq!(browser.eval(pick).await.unwrap(), true);
    let arm = r#"window.viewDone = new Promise((resolve) => {
        const done = () => {
            const v = window.lastView.view, img = document.getElementById("view");
            return v.current && v.latest && v.current.offset[0] > 0.029
                && v.latest.generation === v.current.generation && v.latest.quality === "full"
                && v.latest.glare && img.dataset.shown === v.latest.generation + "/full";
        };
        const check = () => { if (done()) resolve(); };
        document.addEventListener("vtfarm-view-shown", check);
        document.addEventListener("vtfarm-update", check);
        check();
    }); true"#;
    assert_eq!(browser.eval(arm).await.unwrap(), true);
    for _ in 0..3 {
        browser.press("ArrowRight", 39).await.unwrap();
    }
    let view = browser
        .eval(
            r##"window.viewDone.then(() => ({
                hash: document.getElementById("view").dataset.hash,
                glare: document.querySelectorAll("#glare tr").length,
                unshown: [...document.querySelectorAll("#glare td")].filter((td) => td.textContent.includes("–")).length,
                objects: document.getElementById("view-objects").src,
                legend: [...document.querySelectorAll("#view-legend li")].map((li) => ({
                    text: li.textContent,
                    color: getComputedStyle(li.querySelector(".swatch")).backgroundColor,
                    px: parseFloat(getComputedStyle(li).fontSize),
                })),
                objectCount: window.lastView.view.latest.glare.objects.length,
                mode: document.getElementById("view-mode").textContent,
                current: window.lastView.view.current,
                outcomes: window.lastView.view.outcomes,
            }))"##,
        )
        .await.unwrap();
    // The view is the single-process render of the moved eye at `full`.
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..CockpitConfig::default()
    });
    let moved = small_frame(&c, Vec3::new(0.03, 0.0, 0.0));
    let renderer = Renderer::new(Arc::new(c.scene.clone()), c.cover_glass_triangles());
    let reference = renderer.render(&moved, &Default::default(), &mut |_, _| {});
    assert_eq!(
        view["hash"],
        fnv1a(&reference.image.color.to_srgb8()),
        "{view} {:?}",
        moved.camera.eye
    );
    assert!(view["glare"].as_u64().unwrap() >= 7, "{view}");
    assert!(
        view["mode"].as_str().unwrap().contains("no WebGL2"),
        "the page says it shows the master's images: {view}"
    );
    assert_eq!(view["unshown"], 0, "every glare figure is shown: {view}");
    assert!(
        view["objects"]
            .as_str()
            .unwrap()
            .contains("/view/objects.png")
    );
    // The object map's legend: one readable entry per object, in the
    // map's colours.
    let legend = view["legend"].as_array().unwrap();
    assert!(!legend.is_empty(), "{view}");
    assert_eq!(legend.len() as u64, view["objectCount"].as_u64().unwrap());
    let [r, g, b] = vtfarm_glare::object_color_srgb(0);
    assert_eq!(legend[0]["color"], format!("rgb({r}, {g}, {b})"), "{view}");
    assert!(legend[0]["px"].as_f64().unwrap() >= 12.0, "{view}");
    // Only the newest move was rendered to `full`.
    let fulls = farm
        .master
        .inspect(|c| {
            (c.views().outcomes())
                .filter(|o| {
                    matches!(
                        o,
                        ViewOutcome::Rendered {
                            quality: Quality::Full,
                            ..
                        }
                    )
                })
                .count()
        })
        .await
        .unwrap();
    assert_eq!(fulls, 1);

    // The whole page, view and timeline included.
    let metrics = browser
        .call("Page.getLayoutMetrics", serde_json::json!({}))
        .await
        .unwrap();
    let size = &metrics["cssContentSize"];
    let clip = serde_json::json!({
        "x": 0, "y": 0, "width": size["width"], "height": size["height"], "scale": 1
    });
    let shot = browser
        .call(
            "Page.captureScreenshot",
            serde_json::json!({ "format": "png", "clip": clip, "captureBeyondViewport": true }),
        )
        .await
        .unwrap();
    let png = base64::Engine::decode(
        &base64::engine::general_purpose::STANDARD,
        shot["data"].as_str().unwrap(),
    )
    .unwrap();
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("dashboard.png");
    std::fs::write(&path, png).unwrap();
    eprintln!("dashboard screenshot: {}", path.display());
}

/// The dashboard's jobs table in chromium: the cancel button of a running
/// job cancels it (its submitter hears of it), and the row shows it.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_dashboards_cancel_button_cancels_a_running_job() {
    let Some(mut browser) = start_browser().await else {
        return;
    };
    let farm = Farm::with_workers(0).await;
    let (id, submitter) = farm.submit_in_background().await;
    let url = format!("http://{}/", farm.http);
    browser
        .call("Page.enable", serde_json::json!({}))
        .await
        .unwrap();
    browser
        .call("Page.navigate", serde_json::json!({ "url": url }))
        .await
        .unwrap();
    browser.event("Page.loadEventFired").await.unwrap();
    // Click the row's cancel button once the page lists the job running,
    // then wait for the row to say cancelled (the page's own events).
    let click = format!(
        r#"new Promise((resolve) => {{
            const row = () => document.querySelector('#jobs tr[data-job="{id}"]');
            let clicked = false, confirmed = false, armedWhileRunning = null;
            const step = () => {{
                const r = row();
                if (!r) return;
                if (!clicked && r.dataset.state === "running") {{
                    clicked = true;
                    r.querySelector('button[data-action="cancel"]').click();
                }}
                // The first press only asks to confirm: nothing is sent yet.
                const confirm = row().querySelector('button[data-action="confirm-cancel"]');
                if (clicked && !confirmed && confirm) {{
                    armedWhileRunning = row().dataset.state === "running"
                        && document.getElementById("job-answer").textContent === "";
                    confirmed = true;
                    confirm.click();
                }}
                const answered = document.getElementById("job-answer").textContent !== "";
                if (confirmed && answered && r.dataset.state === "cancelled") {{
                    resolve({{ state: r.dataset.state, armedWhileRunning,
                      answer: document.getElementById("job-answer").textContent,
                      buttons: [...r.querySelectorAll("button")].map((b) => b.dataset.action) }});
                }}
            }};
            document.addEventListener("vtfarm-update", step);
            document.addEventListener("vtfarm-job-answer", step);
            step();
        }})"#
    );
    let row = browser.eval(&click).await.unwrap();
    assert_eq!(row["state"], "cancelled", "{row}");
    assert_eq!(row["answer"], format!("job {id}: cancelled"), "{row}");
    assert_eq!(
        row["armedWhileRunning"], true,
        "a single press cancels nothing: {row}"
    );
    // A finished job offers requeue (all or its unfinished frames) and
    // nothing else: its priority changes once it is requeued.
    assert_eq!(
        row["buttons"],
        serde_json::json!(["requeue", "requeue-failed"]),
        "{row}"
    );
    let ended = (tokio::time::timeout(WAIT, submitter).await)
        .expect("the submitter ended")
        .unwrap();
    assert!(
        matches!(ended, Err(JobError::Cancelled { job, .. }) if job == id),
        "{ended:?}"
    );
    let state = (farm
        .master
        .inspect(move |c| c.jobs().get(id).map(|e| e.state)))
    .await
    .unwrap();
    assert_eq!(state, Some(vtfarm_master_core::JobState::Cancelled));
}

/// [`view_reaches`] with a 30 s bound, after which it resolves to what
/// the page has, for the failure's message.
fn view_reaches(condition: &str, value: &str) -> String {
    let state = r#"{ timings: window.vtfarm.viewTimings, mode: document.getElementById("view-mode").textContent }"#;
    vtfarm_master::view_reaches(condition, value, state, 30_000)
}

/// Resolves to `true` once move `index` (0-based, in the page's order) has
/// drawn its `full` stage (the page's own timings).
fn full_drawn(index: usize) -> String {
    let t = format!("window.vtfarm.viewTimings && window.vtfarm.viewTimings[{index}]");
    view_reaches(&format!("{t} && {t}.full !== null"), "true")
}

/// Fails with what the page logged when `result` is not `true`.
fn page_reached(browser: &Browser, result: serde_json::Value, what: &str) {
    if result == true {
        return;
    }
    let logged = browser.page_log();
    panic!("{what}: {result}; the page logged {logged:#?}");
}

/// The page draws the view itself (WebGL2 on SwiftShader): it draws the
/// cockpit, takes three moves and a drag, records one timing per move with
/// every stage of the moves it waited for, and at the still eye its canvas
/// is the CPU's: the base scene within 8/255 on at least 95% of the pixels
/// off the glass, and on the glass the `full` render's pixels. While the
/// eye is dragged it draws previews only, and the stages it held when the
/// drag ends.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_page_draws_the_cockpit_and_the_streamed_stages_and_matches_the_render_at_a_still_eye()
{
    let Some(mut browser) = start_browser_with_webgl().await else {
        return;
    };
    let farm = Farm::start().await;
    farm.submit(1).await;
    let url = format!("http://{}/", farm.http);
    browser
        .call("Page.enable", serde_json::json!({}))
        .await
        .unwrap();
    browser
        .call("Runtime.enable", serde_json::json!({}))
        .await
        .unwrap();
    browser
        .call("Page.navigate", serde_json::json!({ "url": url }))
        .await
        .unwrap();
    browser.event("Page.loadEventFired").await.unwrap();
    let pick = r#"new Promise((resolve) => {
        const select = document.getElementById("view-source");
        const ready = () => resolve(true);
        document.addEventListener("vtfarm-gl-ready", ready);
        setTimeout(() => resolve(document.getElementById("view-mode").textContent), 30000);
        const pick = () => {
            if (![...select.options].some((o) => o.value === "1")) return false;
            select.value = "1";
            select.dispatchEvent(new Event("change"));
            return true;
        };
        if (pick()) return;
        const retry = () => { if (pick()) document.removeEventListener("vtfarm-update", retry); };
        document.addEventListener("vtfarm-update", retry);
    })"#;
    let picked = browser.eval(pick).await.unwrap();
    page_reached(&browser, picked, "the scene drawn");
    // The move to the job's eye that loading the scene sends.
    let drawn = browser.eval(&full_drawn(0)).await.unwrap();
    page_reached(&browser, drawn, "the first move's full stage");
    for k in 1..=3 {
        browser.press("ArrowRight", 39).await.unwrap();
        let drawn = browser.eval(&full_drawn(k)).await.unwrap();
        page_reached(&browser, drawn, &format!("move {k}'s full stage"));
    }
    // A drag: 10 pixels left, a millimetre each.
    let bounds = browser
        .eval(
            r#"(() => {
            const canvas = document.getElementById("view-gl");
            canvas.scrollIntoView();
            const r = canvas.getBoundingClientRect();
            return [r.x + 20, r.y + 20];
        })()"#,
        )
        .await
        .unwrap();
    let (x, y) = (bounds[0].as_f64().unwrap(), bounds[1].as_f64().unwrap());
    let mouse = |kind: &str, x: f64| vtfarm_browser::left_button(kind, x, y);
    browser
        .call("Input.dispatchMouseEvent", mouse("mousePressed", x))
        .await
        .unwrap();
    for step in 1..=10 {
        let at = x - step as f64;
        browser
            .call("Input.dispatchMouseEvent", mouse("mouseMoved", at))
            .await
            .unwrap();
    }
    browser
        .call("Input.dispatchMouseEvent", mouse("mouseReleased", x - 10.0))
        .await
        .unwrap();
    let settled = view_reaches(
        r#"(() => {
            const t = window.vtfarm.viewTimings;
            const offset = document.getElementById("eye-offset").textContent;
            return offset === "20, 0, 0" && t.length > 4 && t[t.length - 1].full !== null;
        })()"#,
        "window.vtfarm.viewTimings.length",
    );
    let moves = browser.eval(&settled).await.unwrap();
    let Some(moves) = moves.as_u64() else {
        return page_reached(&browser, moves, "the drag's last move's full stage");
    };
    let moves = moves as usize;
    let current = (farm.master)
        .inspect(|c| c.views().current().map(|v| (v.generation, v.offset)))
        .await
        .unwrap()
        .expect("a move");
    assert_eq!(
        current.0 as usize, moves,
        "one timing per move the page sent"
    );
    let timings = browser.eval("window.vtfarm.viewTimings").await.unwrap();
    let timings = timings.as_array().unwrap();
    assert_eq!(timings.len(), moves);
    eprintln!("the page's view timings (ms, performance.now()): {timings:?}");
    for (k, t) in timings.iter().enumerate() {
        for stage in ["sent", "preview", "refine", "full", "draw"] {
            assert!(t.get(stage).is_some(), "move {k} has {stage}: {t}");
        }
        let awaited = k <= 3 || k + 1 == moves;
        if awaited {
            for stage in ["preview", "refine", "full", "draw"] {
                assert!(t[stage].is_number(), "move {k} drew {stage}: {t}");
            }
            let (sent, preview, full) = (
                t["sent"].as_f64().unwrap(),
                t["preview"].as_f64().unwrap(),
                t["full"].as_f64().unwrap(),
            );
            assert!(sent <= preview && preview <= full, "{t}");
        }
    }

    // The page's decoder reads the stages the master sent bit for bit.
    let decoded = browser
        .eval(
            r#"(() => {
            const s = window.vtfarm.stages;
            const bits = (a) => Array.from(new Uint32Array(a.buffer, a.byteOffset, a.length));
            return ["preview", "refine", "full"].map((q) => ({
                generation: s[q].generation,
                positions: s[q].positions ? bits(s[q].positions) : [],
                colors: bits(s[q].colors),
                behind: s[q].behind ? bits(s[q].behind) : [],
                reflectionScale: s[q].reflectionScale ? bits(s[q].reflectionScale) : [],
                faces: s[q].faces ? Array.from(s[q].faces) : [],
            }));
        })()"#,
        )
        .await
        .unwrap();
    let sent = (farm.master)
        .inspect(|c| {
            let stream = c.views().stream();
            (stream.messages.iter())
                .map(|m| vtfarm_master::stream::decode(&m.bytes).unwrap())
                .collect::<Vec<_>>()
        })
        .await
        .unwrap();
    assert_eq!(sent.len(), 3);
    let bits = |v: &[Vec3]| -> Vec<u64> {
        v.iter()
            .flat_map(|c| c.to_array())
            .map(|f| u64::from(f.to_bits()))
            .collect()
    };
    let json = |v: &serde_json::Value| -> Vec<u64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .collect()
    };
    for (message, page) in sent.iter().zip(decoded.as_array().unwrap()) {
        assert_eq!(page["generation"].as_u64().unwrap(), current.0);
        match message {
            StageMessage::Mesh { meshes, .. } => {
                let m = &meshes[0];
                let colors: Vec<Vec3> = m.samples.iter().map(|s| s.color).collect();
                assert_eq!(json(&page["colors"]), bits(&colors));
                assert_eq!(json(&page["positions"]), bits(&m.positions));
                let behind: Vec<Vec3> = m.slabs.iter().map(|s| s.behind).collect();
                assert_eq!(json(&page["behind"]), bits(&behind));
                let scales: Vec<u64> = (m.slabs.iter())
                    .map(|s| u64::from(s.reflection_scale.to_bits()))
                    .collect();
                assert_eq!(json(&page["reflectionScale"]), scales);
                let faces: Vec<u64> = m.faces.iter().flatten().map(|&v| u64::from(v)).collect();
                assert_eq!(json(&page["faces"]), faces);
            }
            StageMessage::Overlay { overlay, .. } => {
                assert_eq!(json(&page["colors"]), bits(&overlay.colors));
            }
        }
    }

    // The page's sRGB table gives its formula's bytes: at 2^18 inputs
    // spread over [0, 1] (the overlay's pixels below check the formula
    // against the CPU's).
    let differ = browser
        .eval(
            r#"import("/assets/view/stream.js").then(({ srgb8, srgb8Formula }) => {
            const bits = new Uint32Array(1), float = new Float32Array(bits.buffer);
            const differ = [];
            for (let b = 0; b <= 0x3f800000; b += 4057) {
                bits[0] = b;
                if (srgb8(float[0]) !== srgb8Formula(float[0])) differ.push(float[0]);
            }
            return differ.slice(0, 8);
        })"#,
        )
        .await
        .unwrap();
    assert_eq!(
        differ,
        serde_json::json!([]),
        "sRGB table and formula differ"
    );

    // The still eye: each stage as the page shows it against the CPU's
    // frames of that eye.
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..CockpitConfig::default()
    });
    assert_eq!(current.1, [0.02, 0.0, 0.0]);
    let setup = small_frame(&c, Vec3::from(current.1));
    let renderer = Renderer::new(Arc::new(c.scene.clone()), c.cover_glass_triangles());
    let (base, _) = renderer.base_frame(&setup);
    let base_srgb = base.to_srgb8();
    for quality in [Quality::Preview, Quality::Refine, Quality::Full] {
        let show = format!("window.vtfarm.showStage({:?})", quality.name());
        assert_eq!(browser.eval(&show).await.unwrap(), true, "{quality:?}");
        let shown = canvas_pixels(&mut browser).await;
        let cpu = FrameSetup {
            vertex: vtfarm_vertex::VertexSettings {
                quality,
                ..setup.vertex
            },
            ..setup.clone()
        };
        let cpu = renderer.render(&cpu, &Default::default(), &mut |_, _| {});
        let agreement = still_eye(&shown, &cpu.image, &base_srgb);
        eprintln!("the page's {quality:?} against the CPU's: {agreement:?}");
        let StillEye {
            glass,
            glass_close,
            glass_same,
            worst,
            off_glass,
            off_glass_close,
        } = agreement;
        assert!(glass > 0 && off_glass > 0);
        assert!(
            off_glass_close * 100 >= off_glass * 95,
            "{quality:?}: base scene: {off_glass_close} of {off_glass} pixels within 8/255"
        );
        if quality == Quality::Full {
            assert_eq!(
                glass_same, glass,
                "the glass shows the full render's pixels (off by up to {worst})"
            );
        } else {
            assert!(
                glass_close * 100 >= glass * 95,
                "{quality:?}: {glass_close} of {glass} glass pixels within 8/255 (worst {worst})"
            );
        }
    }

    // While the eye is dragged the page asks for previews only: the master
    // ends the dragged move at its preview, which the page draws; when the
    // mouse is let go, the page sends the eye again and draws it to `full`.
    browser
        .call("Input.dispatchMouseEvent", mouse("mousePressed", x))
        .await
        .unwrap();
    browser
        .call("Input.dispatchMouseEvent", mouse("mouseMoved", x + 1.0))
        .await
        .unwrap();
    let last = "window.vtfarm.viewTimings[window.vtfarm.viewTimings.length - 1]";
    let previewed = view_reaches(
        &format!(
            "window.vtfarm.viewTimings.length === {} && {last}.preview !== null",
            moves + 1
        ),
        "true",
    );
    let previewed = browser.eval(&previewed).await.unwrap();
    page_reached(&browser, previewed, "the dragged move's preview");
    let dragged = moves as u64 + 1;
    let ended = (farm.master)
        .inspect(move |c| {
            c.views().outcomes().any(|o| {
                matches!(*o, ViewOutcome::Cancelled { generation, .. } if generation == dragged)
            })
        })
        .await
        .unwrap();
    assert!(ended, "the master ended the dragged move at its preview");
    browser
        .call("Input.dispatchMouseEvent", mouse("mouseReleased", x + 1.0))
        .await
        .unwrap();
    let drawn = browser.eval(&full_drawn(moves + 1)).await.unwrap();
    page_reached(
        &browser,
        drawn,
        "the eye where the drag ended, sent again and drawn to full",
    );
    let dragged = browser
        .eval(&format!(
            "JSON.stringify(window.vtfarm.viewTimings[{moves}])"
        ))
        .await
        .unwrap();
    let dragged: serde_json::Value = serde_json::from_str(dragged.as_str().unwrap()).unwrap();
    assert!(
        dragged["refine"].is_null() && dragged["full"].is_null(),
        "the dragged move drew its preview only: {dragged}"
    );
}
