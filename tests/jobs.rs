//! Managing jobs with the real `vtfarm` binary on 127.0.0.1: a master and
//! workers as child processes, `vtfarm submit`, `jobs`, `cancel`, `pause`
//! from the command line. Every wait is bounded and triggered by what the
//! processes say (their log lines, `--json` events), never by a delay.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use serde_json::Value;

/// A bound for every wait: generous for a loaded machine, but a failing
/// test ends.
const BOUND: Duration = Duration::from_secs(180);

/// A small job file: the built-in cockpit at `width` × `height`.
fn job_file(dir: &Path, name: &str, width: u32, height: u32) -> PathBuf {
    let path = dir.join(name);
    let text = format!(
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n[camera]\nwidth = {width}\nheight = {height}\n"
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// A `vtfarm` child process, killed when dropped; its stderr (and stdout)
/// lines come through channels as it writes them.
struct Process {
    child: Child,
    stderr: Receiver<String>,
    stdout: Receiver<String>,
    /// Every stderr line read so far.
    log: Vec<String>,
}

impl Process {
    fn spawn(args: &[&str]) -> Process {
        let mut child = Command::new(env!("CARGO_BIN_EXE_vtfarm"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the vtfarm binary starts");
        let lines = |stream: Box<dyn std::io::Read + Send>| {
            let (send, receive) = channel();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    if send.send(line).is_err() {
                        break;
                    }
                }
            });
            receive
        };
        let stderr = lines(Box::new(child.stderr.take().unwrap()));
        let stdout = lines(Box::new(child.stdout.take().unwrap()));
        Process {
            child,
            stderr,
            stdout,
            log: Vec::new(),
        }
    }

    /// The first stderr line (from now) containing `needle`, bounded.
    fn wait_for(&mut self, needle: &str) -> String {
        let deadline = Instant::now() + BOUND;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = (self.stderr.recv_timeout(left))
                .unwrap_or_else(|e| panic!("no line with {needle:?} ({e}); got {:?}", self.log));
            self.log.push(line.clone());
            if line.contains(needle) {
                return line;
            }
        }
    }

    /// The first stdout line containing `needle`, bounded.
    fn wait_for_stdout(&mut self, needle: &str) -> String {
        let deadline = Instant::now() + BOUND;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = (self.stdout.recv_timeout(left))
                .unwrap_or_else(|e| panic!("no stdout line with {needle:?} ({e})"));
            if line.contains(needle) {
                return line;
            }
        }
    }

    /// The job id of `submit --json`'s accepted event (on stdout, which
    /// holds JSON lines alone).
    fn accepted_job(&mut self) -> u64 {
        let line = self.wait_for_stdout("\"accepted\"");
        let event: Value = serde_json::from_str(&line).expect("a JSON line");
        event["job"].as_u64().expect("the job's id")
    }

    /// Waits (bounded) for the exit; the rest of stderr joins the log.
    fn exit(&mut self) -> std::process::ExitStatus {
        let deadline = Instant::now() + BOUND;
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            assert!(Instant::now() < deadline, "no exit within {BOUND:?}");
            // Reading its stderr meanwhile keeps a chatty child going.
            if let Ok(line) = self.stderr.recv_timeout(Duration::from_millis(50)) {
                self.log.push(line);
            }
        };
        // The pipes close at the exit: what is left comes at once.
        while let Ok(line) = self.stderr.recv_timeout(BOUND) {
            self.log.push(line);
        }
        status
    }

    /// The rest of stdout, once the process has exited.
    fn rest_of_stdout(&self) -> String {
        let mut lines = Vec::new();
        while let Ok(line) = self.stdout.recv_timeout(BOUND) {
            lines.push(line);
        }
        lines.join("\n")
    }

    fn log_text(&self) -> String {
        self.log.join("\n")
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `vtfarm ARGS` to its end (bounded): exit status, stdout, stderr.
fn vtfarm(args: &[&str]) -> (std::process::ExitStatus, String, String) {
    let mut process = Process::spawn(args);
    let status = process.exit();
    let stdout = process.rest_of_stdout();
    (status, stdout, process.log_text())
}

/// A cluster directory and a master process on a free localhost port.
struct Master {
    dir: tempfile::TempDir,
    cluster: String,
    process: Process,
}

impl Master {
    fn start() -> Master {
        let dir = tempfile::tempdir().unwrap();
        let free = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let address = free.local_addr().unwrap().to_string();
        drop(free);
        let out = dir.path().to_str().unwrap().to_owned();
        let (status, _, stderr) = vtfarm(&["cluster", "init", "-o", &out, "--master", &address]);
        assert!(status.success(), "{stderr}");
        let cluster = dir.path().join("cluster.toml").to_str().unwrap().to_owned();
        let process = Master::process(&cluster);
        Master {
            dir,
            cluster,
            process,
        }
    }

    /// `vtfarm master` on the cluster file; returns once it serves.
    fn process(cluster: &str) -> Process {
        let mut process =
            Process::spawn(&["master", "--cluster", cluster, "--http", "127.0.0.1:0"]);
        process.wait_for_stdout("dashboard on");
        process
    }

    /// Kills the master (no goodbye) and starts it again on its state.
    fn restart(&mut self) {
        self.process.child.kill().unwrap();
        self.process.exit();
        self.process = Master::process(&self.cluster);
    }

    fn worker(&self, name: &str) -> Process {
        let cache = self.dir.path().join(name);
        Process::spawn(&[
            "worker",
            "--cluster",
            &self.cluster,
            "--name",
            name,
            "--threads",
            "1",
            "--cache",
            cache.to_str().unwrap(),
        ])
    }

    /// `vtfarm submit FILE` with `extra` options, in the background.
    fn submit(&self, file: &Path, output: &str, extra: &[&str]) -> Process {
        let output = self.dir.path().join(output);
        let mut args = vec![
            "submit",
            file.to_str().unwrap(),
            "--cluster",
            &self.cluster,
            "-o",
            output.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        Process::spawn(&args)
    }

    /// `vtfarm jobs --all --json`.
    fn jobs(&self) -> Vec<Value> {
        let (status, stdout, stderr) =
            vtfarm(&["jobs", "--all", "--json", "--cluster", &self.cluster]);
        assert!(status.success(), "{stderr}");
        serde_json::from_str(&stdout).expect("a JSON array of jobs")
    }

    /// `vtfarm ACTION ARGS --cluster …`.
    fn control(&self, args: &[&str]) -> (std::process::ExitStatus, String, String) {
        let mut all = args.to_vec();
        all.extend(["--cluster", &self.cluster]);
        vtfarm(&all)
    }
}

fn job_of(jobs: &[Value], id: u64) -> &Value {
    (jobs.iter().find(|j| j["id"] == id)).unwrap_or_else(|| panic!("job {id} in {jobs:?}"))
}

#[test]
fn the_higher_priority_job_gets_the_workers_first_and_both_images_equal_vtfarm_render() {
    let mut master = Master::start();
    let dir = master.dir.path().to_owned();
    let (low_file, high_file) = (
        job_file(&dir, "low.toml", 96, 54),
        job_file(&dir, "high.toml", 120, 68),
    );
    // No worker yet: the low job starts (none runs); the high one, submitted
    // after it, starts when a worker asks and gets the workers first.
    let mut low = master.submit(&low_file, "low", &["--json", "--name", "low"]);
    let low_id = low.accepted_job();
    let mut high = master.submit(&high_file, "high", &["--json", "--priority", "5"]);
    let high_id = high.accepted_job();
    let listed = master.jobs();
    assert_eq!(job_of(&listed, low_id)["name"], "low");
    assert_eq!(job_of(&listed, high_id)["priority"], 5);
    let mut workers = [master.worker("w1"), master.worker("w2")];
    for w in &mut workers {
        w.wait_for("connected to the master");
    }
    // Each worker's first package is the high job's: it sets that frame up
    // first. (Which job ends first is not the rule: the workers the high
    // job has nothing for near its end take the low one's.)
    let high_frame = format!("frame ready job={high_id} frame=0");
    for w in &mut workers {
        let first = w.wait_for("frame ready");
        assert!(first.ends_with(&high_frame), "{first}");
    }
    assert!(low.exit().success(), "{}", low.log_text());
    assert!(high.exit().success(), "{}", high.log_text());
    let listed = master.jobs();
    let (l, h) = (job_of(&listed, low_id), job_of(&listed, high_id));
    assert_eq!(
        (l["state"].as_str(), h["state"].as_str()),
        (Some("completed"), Some("completed"))
    );
    assert!(
        l["started_ms"].as_u64() <= h["started_ms"].as_u64(),
        "{listed:?}"
    );
    // Both images byte for byte as `vtfarm render` writes them.
    for (file, output) in [(&low_file, "low"), (&high_file, "high")] {
        assert_equals_vtfarm_render(&dir, file, output);
    }
    // The master said who joined; its redirected log has no colour codes.
    master.process.wait_for("worker joined");
    master.process.wait_for("worker joined");
    let log = master.process.log_text();
    assert!(
        !log.contains('\u{1b}'),
        "escape codes in a redirected log: {log}"
    );
}

/// Renders `file` with `vtfarm render` and checks that the farm's
/// `output/frame_0000.png` is the same bytes.
fn assert_equals_vtfarm_render(dir: &Path, file: &Path, output: &str) {
    let rendered = dir.join(format!("{output}.png"));
    let (status, _, stderr) = vtfarm(&[
        "render",
        file.to_str().unwrap(),
        "-o",
        rendered.to_str().unwrap(),
        "--local-workers",
        "1",
    ]);
    assert!(status.success(), "{stderr}");
    let farm = std::fs::read(dir.join(output).join("frame_0000.png")).unwrap();
    assert!(
        farm == std::fs::read(&rendered).unwrap(),
        "{output}: the PNGs differ"
    );
}

/// The index of the master's first log line that says `what` of `job`.
fn log_index(log: &[String], what: &str, job: u64) -> Option<usize> {
    let tag = format!("job={job}");
    (log.iter()).position(|l| l.contains(what) && l.split_whitespace().any(|w| w == tag))
}

#[test]
fn two_jobs_run_at_once_on_two_workers_and_both_images_equal_vtfarm_render() {
    let mut master = Master::start();
    let dir = master.dir.path().to_owned();
    let (first_file, second_file) = (
        job_file(&dir, "first.toml", 96, 54),
        job_file(&dir, "second.toml", 120, 68),
    );
    // Both queued before a worker comes: the first starts (none runs), and
    // the second once a worker asks and the first has nothing for it (its
    // last package runs: a worker asks one package ahead).
    let mut first = master.submit(&first_file, "first", &["--json"]);
    let first_id = first.accepted_job();
    let mut second = master.submit(&second_file, "second", &["--json"]);
    let second_id = second.accepted_job();
    let mut workers = [master.worker("w1"), master.worker("w2")];
    for w in &mut workers {
        w.wait_for("connected to the master");
    }
    assert!(first.exit().success(), "{}", first.log_text());
    assert!(second.exit().success(), "{}", second.log_text());
    master.process.wait_for("job complete");
    master.process.wait_for("job complete");
    let log = &master.process.log;
    let started = log_index(log, "job started", second_id).expect("the second started");
    let first_done = log_index(log, "job complete", first_id).expect("the first completed");
    assert!(
        started < first_done,
        "the second job started only after the first ended: {log:?}"
    );
    for (file, output) in [(&first_file, "first"), (&second_file, "second")] {
        assert_equals_vtfarm_render(&dir, file, output);
    }
}

#[test]
fn a_cancel_ends_its_submit_with_an_error_naming_it_and_ctrl_c_says_how_to_come_back() {
    let master = Master::start();
    let file = job_file(master.dir.path(), "job.toml", 96, 54);
    // No worker: the job runs and never finishes on its own.
    let mut submit = master.submit(&file, "a", &["--json"]);
    let id = submit.accepted_job();
    let (status, stdout, stderr) = master.control(&["cancel", &id.to_string()]);
    assert!(status.success(), "{stderr}");
    assert_eq!(
        stdout,
        format!("job {id}: cancelled (priority 0, 0/1 frames done)")
    );
    assert!(!submit.exit().success());
    let log = submit.log_text();
    assert!(
        log.contains(&format!(
            "error: job {id} was cancelled by `vtfarm cancel` on 127.0.0.1"
        )),
        "{log}"
    );
    for line in submit.rest_of_stdout().lines() {
        let parsed: Result<Value, _> = serde_json::from_str(line);
        assert!(parsed.is_ok(), "a plain line in --json's stdout: {line}");
    }
    let (status, _, stderr) = master.control(&["cancel", &id.to_string()]);
    assert!(!status.success());
    assert!(
        stderr.contains(&format!("job {id} is cancelled")),
        "{stderr}"
    );

    // Ctrl-C: the job stays on the farm, and the submitter says how to
    // follow it again or stop it. Without --json the id is on stderr too.
    let mut submit = master.submit(&file, "b", &[]);
    let line = submit.wait_for("accepted");
    let id: u64 = (line.split_whitespace().nth(1).and_then(|w| w.parse().ok()))
        .unwrap_or_else(|| panic!("{line}"));
    let sent = Command::new("kill")
        .args(["-INT", &submit.child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = submit.exit();
    assert_eq!(status.code(), Some(130), "{}", submit.log_text());
    let log = submit.log_text();
    assert!(
        log.contains(&format!("job {id} keeps running on the farm")),
        "{log}"
    );
    assert!(log.contains(&format!("--attach {id}")), "{log}");
    assert!(log.contains(&format!("vtfarm cancel {id}")), "{log}");
    assert_eq!(job_of(&master.jobs(), id)["state"], "running");
    // Cancelling it and an unknown job: the one is cancelled, the other named.
    let (status, _, stderr) = master.control(&["cancel", &id.to_string(), "99"]);
    assert!(!status.success());
    assert!(stderr.contains("no job 99"), "{stderr}");
    assert_eq!(job_of(&master.jobs(), id)["state"], "cancelled");
}

#[test]
fn after_a_master_restart_jobs_all_lists_the_same_jobs_and_states() {
    let mut master = Master::start();
    let file = job_file(master.dir.path(), "job.toml", 96, 54);
    let mut cancelled = master.submit(&file, "a", &["--json"]);
    let cancelled_id = cancelled.accepted_job();
    assert!(
        master
            .control(&["cancel", &cancelled_id.to_string()])
            .0
            .success()
    );
    assert!(!cancelled.exit().success());
    let mut running = master.submit(&file, "b", &["--json", "--name", "running"]);
    let running_id = running.accepted_job();
    let mut paused = master.submit(&file, "c", &["--json", "--priority", "-1"]);
    let paused_id = paused.accepted_job();
    let (status, stdout, stderr) = master.control(&["pause", &paused_id.to_string()]);
    assert!(status.success(), "{stderr}");
    assert!(stdout.contains("paused"), "{stdout}");
    let (status, _, _) = master.control(&["priority", &paused_id.to_string(), "-2"]);
    assert!(status.success());
    let before = master.jobs();
    let states: Vec<&str> = before
        .iter()
        .map(|j| j["state"].as_str().unwrap())
        .collect();
    assert_eq!(states, ["cancelled", "running", "paused"]);

    master.restart();
    let after = master.jobs();
    assert_eq!(after, before);
    assert_eq!(job_of(&after, paused_id)["priority"], -2);
    assert_eq!(job_of(&after, running_id)["name"], "running");
    // The table in text names every job and state too.
    let (status, table, _) = master.control(&["jobs", "--all"]);
    assert!(status.success());
    for (id, state) in [
        (cancelled_id, "cancelled"),
        (running_id, "running"),
        (paused_id, "paused"),
    ] {
        let row = (table.lines()).find(|l| l.split_whitespace().next() == Some(&id.to_string()));
        assert!(row.is_some_and(|r| r.contains(state)), "{table}");
    }
    drop((running, paused));
}

/// A small study: two designs of the built-in cockpit seen from two eye
/// points (four frames of 96 × 54), and its base job beside it.
fn study_file(dir: &Path) -> PathBuf {
    std::fs::write(
        dir.join("base.toml"),
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n",
    )
    .unwrap();
    let path = dir.join("study.toml");
    let text = "[study]\nname = \"small study\"\njob = \"base.toml\"\nwidth = 96\nheight = 54\n\
        [eyes]\npoints = [[-0.55, 1.4, 0.1], [-0.5, 1.42, 0.12]]\n\
        [[variants]]\nname = \"current\"\nglass = \"current\"\n\
        [[variants]]\nname = \"flat\"\nglass = \"flat\"\n";
    std::fs::write(&path, text).unwrap();
    path
}

/// `summary.json` under `dir` without how it was made (its date, workers
/// and command differ between runs; every figure must not).
fn summary_figures(dir: &Path) -> Value {
    let bytes = std::fs::read(dir.join("summary.json")).unwrap();
    let mut json: Value = serde_json::from_slice(&bytes).unwrap();
    let provenance = json.as_object_mut().unwrap().remove("provenance");
    assert!(provenance.is_some(), "summary.json says how it was made");
    json
}

/// The study's figures as `vtfarm study` writes them on this machine.
fn local_study_figures(dir: &Path, study: &Path) -> Value {
    let out = dir.join("local-study");
    let (status, _, stderr) = vtfarm(&[
        "study",
        study.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--local-workers",
        "1",
    ]);
    assert!(status.success(), "{stderr}");
    summary_figures(&out)
}

/// `submit --attach STUDY --json` to its end: it succeeds.
fn attach_to_the_end(master: &Master, study: &Path, output: &str, id: u64) {
    let id = id.to_string();
    let mut attach = master.submit(study, output, &["--json", "--attach", &id]);
    assert!(attach.exit().success(), "{}", attach.log_text());
}

#[test]
fn a_study_is_one_job_through_submit_pause_resume_cancel_requeue_and_attach() {
    let master = Master::start();
    let dir = master.dir.path().to_owned();
    let study = study_file(&dir);
    // No worker yet: the study waits, one row of kind study.
    let mut submit = master.submit(&study, "study", &["--json"]);
    let id = submit.accepted_job();
    let jobs = master.jobs();
    assert_eq!(jobs.len(), 1, "one row: {jobs:?}");
    let row = job_of(&jobs, id);
    assert_eq!(row["kind"], "study");
    assert_eq!(row["frames_total"], 4);
    let variants = row["variants"].as_array().expect("its variants");
    let names: Vec<&str> = variants
        .iter()
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["small study / current", "small study / flat"]);
    assert!(variants.iter().all(|v| v["kind"] == "variant"), "{row}");
    // A variant is controlled through its study.
    let variant = variants[1]["id"].as_u64().unwrap().to_string();
    let (status, _, stderr) = master.control(&["pause", &variant]);
    assert!(!status.success());
    assert!(
        stderr.contains(&format!("a variant of study {id}")),
        "{stderr}"
    );

    // Paused, every variant is; the submitter killed, the study stays.
    let pause = |master: &Master| {
        let (status, stdout, stderr) = master.control(&["pause", &id.to_string()]);
        assert!(status.success(), "{stderr}");
        assert!(stdout.contains("paused"), "{stdout}");
    };
    pause(&master);
    submit.child.kill().unwrap();
    submit.exit();
    let states = |master: &Master| -> (String, Vec<String>) {
        let jobs = master.jobs();
        let row = job_of(&jobs, id);
        let variants = (row["variants"].as_array().unwrap().iter())
            .map(|v| v["state"].as_str().unwrap().to_owned())
            .collect();
        (row["state"].as_str().unwrap().to_owned(), variants)
    };
    assert_eq!(states(&master), ("paused".into(), vec!["paused".into(); 2]));

    // Cancelled as one, by whom; its unfinished variants queued again.
    let (status, stdout, stderr) = master.control(&["cancel", &id.to_string()]);
    assert!(status.success(), "{stderr}");
    assert!(stdout.contains("cancelled"), "{stdout}");
    assert_eq!(
        states(&master),
        ("cancelled".into(), vec!["cancelled".into(); 2])
    );
    let row = job_of(&master.jobs(), id).clone();
    let reason = row["reason"].as_str().unwrap();
    assert!(
        reason.starts_with(&format!("study {id} was cancelled by `vtfarm cancel`")),
        "{reason}"
    );
    let (status, _, stderr) = master.control(&["requeue", "--failed", &id.to_string()]);
    assert!(status.success(), "{stderr}");
    let (_, variants) = states(&master);
    assert!(
        (variants.iter()).all(|s| s == "queued" || s == "running"),
        "{variants:?}"
    );

    // Paused, it holds: a worker joins and gets none of its work.
    pause(&master);
    let mut worker = master.worker("w1");
    worker.wait_for("connected to the master");
    assert_eq!(states(&master), ("paused".into(), vec!["paused".into(); 2]));
    assert_eq!(job_of(&master.jobs(), id)["frames_done"], 0);

    // Resumed and followed again: the report is `vtfarm study`'s.
    let (status, _, stderr) = master.control(&["resume", &id.to_string()]);
    assert!(status.success(), "{stderr}");
    attach_to_the_end(&master, &study, "attached", id);
    let local = local_study_figures(&dir, &study);
    assert_eq!(summary_figures(&dir.join("attached")), local);
    let row = job_of(&master.jobs(), id).clone();
    assert_eq!(
        (row["state"].as_str(), row["frames_done"].as_u64()),
        (Some("completed"), Some(4))
    );

    // Queued again whole: the same report again.
    let (status, _, stderr) = master.control(&["requeue", &id.to_string()]);
    assert!(status.success(), "{stderr}");
    attach_to_the_end(&master, &study, "requeued", id);
    assert_eq!(summary_figures(&dir.join("requeued")), local);
    let (status, _, stderr) = master.control(&["priority", &id.to_string(), "3"]);
    assert!(
        !status.success(),
        "a completed study has no priority to set"
    );
    assert!(
        stderr.contains(&format!("job {id} is completed")),
        "{stderr}"
    );
    drop(worker);
}

#[test]
fn a_master_killed_mid_study_resumes_it_and_attach_writes_the_same_report() {
    let mut master = Master::start();
    let dir = master.dir.path().to_owned();
    let study = study_file(&dir);
    let mut worker = master.worker("w1");
    worker.wait_for("connected to the master");
    let mut submit = master.submit(&study, "study", &["--json"]);
    let id = submit.accepted_job();
    // A frame done (and journaled): the master is killed, and the submitter.
    master.process.wait_for("frame complete");
    submit.child.kill().unwrap();
    submit.exit();
    let before = master.jobs();
    master.restart();
    let after = master.jobs();
    assert_eq!(after.len(), 1, "one row: {after:?}");
    let (b, a) = (job_of(&before, id), job_of(&after, id));
    assert_eq!(
        (a["kind"].as_str(), a["name"].as_str()),
        (Some("study"), b["name"].as_str())
    );
    let ids = |row: &Value| -> Vec<u64> {
        (row["variants"].as_array().unwrap().iter())
            .map(|v| v["id"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(ids(a), ids(b));
    attach_to_the_end(&master, &study, "attached", id);
    assert_eq!(
        summary_figures(&dir.join("attached")),
        local_study_figures(&dir, &study)
    );
    assert_eq!(job_of(&master.jobs(), id)["state"], "completed");
    drop(worker);
}

#[test]
fn ctrl_c_on_a_study_submit_writes_a_partial_report_and_says_how_to_follow_or_cancel_it() {
    let master = Master::start();
    let study = study_file(master.dir.path());
    // No worker: the study never finishes on its own.
    let mut submit = master.submit(&study, "study", &[]);
    let line = submit.wait_for("accepted");
    let id: u64 = (line.split_whitespace().nth(1).and_then(|w| w.parse().ok()))
        .unwrap_or_else(|| panic!("{line}"));
    assert!(line.starts_with(&format!("study {id} accepted")), "{line}");
    let sent = Command::new("kill")
        .args(["-INT", &submit.child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    assert_eq!(submit.exit().code(), Some(130), "{}", submit.log_text());
    let log = submit.log_text();
    assert!(
        log.contains(&format!("study {id} keeps running on the farm")),
        "{log}"
    );
    assert!(log.contains(&format!("--attach {id}")), "{log}");
    assert!(log.contains(&format!("vtfarm cancel {id}")), "{log}");
    assert!(log.contains("partial report of 0 of 4 frames"), "{log}");
    assert!(master.dir.path().join("study/report.html").exists());
    assert_eq!(job_of(&master.jobs(), id)["state"], "running");
}
