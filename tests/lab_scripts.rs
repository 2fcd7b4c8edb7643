//! The lab scripts' quota and argument handling (`scripts/lab.sh`,
//! `scripts/hosts.sh`, the functions of `scripts/farm-common.sh`), run
//! against temporary fake cgroup trees (`VTFARM_CGROUP_ROOT`) with
//! `--dry-run`: the files a quota is made of, the prediction's command, and
//! a clear error and a failing exit where no quota can be made. Nothing
//! here needs root, network namespaces or timing; every script run is
//! bounded by `timeout`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Every script run ends within this, whatever it does.
const SCRIPT_LIMIT_SECONDS: &str = "60";

fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(name)
}

/// Runs `bash SCRIPT ARGS` with the cgroup hierarchy at `cgroups`, bounded.
fn run(name: &str, cgroups: &Path, args: &[&str]) -> Output {
    Command::new("timeout")
        .arg(SCRIPT_LIMIT_SECONDS)
        .arg("bash")
        .arg(script(name))
        .args(args)
        .env("VTFARM_CGROUP_ROOT", cgroups)
        .output()
        .expect("timeout and bash run")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .trim_end()
        .to_owned()
}

/// A cgroup v1 machine's tree: the cpu controller's own hierarchy under cpu/.
fn fake_v1() -> tempfile::TempDir {
    let root = tempfile::tempdir().unwrap();
    std::fs::create_dir(root.path().join("cpu")).unwrap();
    std::fs::write(root.path().join("cpu/cpu.cfs_quota_us"), "-1\n").unwrap();
    std::fs::write(root.path().join("cpu/cpu.cfs_period_us"), "100000\n").unwrap();
    root
}

/// A cgroup v2 machine's unified tree offering the cpu controller, not yet
/// handed on to children.
fn fake_v2() -> tempfile::TempDir {
    let root = tempfile::tempdir().unwrap();
    std::fs::write(
        root.path().join("cgroup.controllers"),
        "cpuset cpu io memory pids\n",
    )
    .unwrap();
    std::fs::write(root.path().join("cgroup.subtree_control"), "").unwrap();
    root
}

/// The groups the scripts made under `dir` for worker `w` (`vtlabPID-wW`),
/// sorted by name.
fn groups_of_worker(dir: &Path, w: usize) -> Vec<PathBuf> {
    let suffix = format!("-w{w}");
    let mut groups: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("vtlab") && n.ends_with(&suffix))
        })
        .collect();
    groups.sort();
    groups
}

/// The one group worker `w` of a single lab run got.
fn group_of_worker(dir: &Path, w: usize) -> PathBuf {
    let groups = groups_of_worker(dir, w);
    assert_eq!(groups.len(), 1, "worker {w}'s groups: {groups:?}");
    groups.into_iter().next().unwrap()
}

#[test]
fn v1_quotas_hold_each_worker_to_its_share_over_a_10_ms_period() {
    let root = fake_v1();
    let out = run(
        "lab.sh",
        root.path(),
        &[
            "--dry-run",
            "--workers",
            "2",
            "--cpu-percent",
            "45,15",
            "--mbit",
            "100,10",
            "--cpus",
            "0,1",
        ],
    );
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    for (w, quota) in [(1, "4500"), (2, "1500")] {
        let group = group_of_worker(&root.path().join("cpu"), w);
        assert_eq!(read(&group.join("cpu.cfs_period_us")), "10000");
        assert_eq!(read(&group.join("cpu.cfs_quota_us")), quota);
    }
    // The hierarchy's own files are left alone.
    assert_eq!(read(&root.path().join("cpu/cpu.cfs_quota_us")), "-1");
    // The prediction slows the workers alone, each by its own quota, with
    // each worker's link; the master keeps its core.
    let prediction = stdout
        .lines()
        .find(|l| {
            l.trim_start()
                .starts_with("prediction: vtfarm bench simulate")
        })
        .unwrap_or_else(|| panic!("no prediction in {stdout}"));
    for flag in [
        "--workers 2",
        "--worker-speed 0.45,0.15",
        "--worker-mbit 100,10",
        "--link-mbit 100",
        "--master-threads 1",
    ] {
        assert!(prediction.contains(flag), "{flag} in {prediction}");
    }
    for flag in ["--cost-scale", "--fixed-cost-scale", "--shared-cores"] {
        assert!(!prediction.contains(flag), "{flag} in {prediction}");
    }
    assert!(stdout.contains("master and submitter: cores 1"), "{stdout}");
}

#[test]
fn v2_quotas_write_cpu_max_and_hand_the_cpu_controller_on() {
    let root = fake_v2();
    let out = run(
        "lab.sh",
        root.path(),
        &[
            "--dry-run",
            "--localhost",
            "--workers",
            "3",
            "--cpu-percent",
            "22",
            "--cpus",
            "2,3,5",
        ],
    );
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert_eq!(read(&root.path().join("cgroup.subtree_control")), "+cpu");
    for w in 1..=3 {
        let group = group_of_worker(root.path(), w);
        assert_eq!(read(&group.join("cpu.max")), "2200 10000");
    }
    assert!(stdout.contains("w3: 22% of core 2"), "{stdout}");
    assert!(
        stdout.contains("master and submitter: cores 3,5"),
        "{stdout}"
    );
    assert!(
        stdout.contains("--master-threads 2 --worker-speed 0.22,0.22,0.22"),
        "{stdout}"
    );
    assert!(stdout.contains("--link-mbit 10000"), "{stdout}");
}

/// Without quotas the lab's processes share the machine's cores, links as given.
#[test]
fn without_quotas_the_prediction_shares_the_machine() {
    let root = tempfile::tempdir().unwrap();
    let out = run(
        "lab.sh",
        root.path(),
        &["--dry-run", "--workers", "2", "--mbit", "100,10"],
    );
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(stdout.contains("--shared-cores"), "{stdout}");
    assert!(stdout.contains("--worker-mbit 100,10"), "{stdout}");
    assert!(!stdout.contains("--worker-speed"), "{stdout}");
    assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 0);
}

#[test]
fn where_no_quota_can_be_made_the_lab_says_why_and_fails() {
    // Neither hierarchy.
    let root = tempfile::tempdir().unwrap();
    let out = run(
        "lab.sh",
        root.path(),
        &[
            "--dry-run",
            "--workers",
            "2",
            "--cpu-percent",
            "45",
            "--cpus",
            "0,1",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("no CPU quotas here") && stderr.contains("refusing to run without quotas"),
        "{stderr}"
    );
    assert!(!text(&out.stdout).contains("prediction"));
    assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 0);

    // A v2 tree whose controller cannot be handed on (the file is a directory).
    let root = fake_v2();
    let control = root.path().join("cgroup.subtree_control");
    std::fs::remove_file(&control).unwrap();
    std::fs::create_dir(&control).unwrap();
    let out = run(
        "lab.sh",
        root.path(),
        &[
            "--dry-run",
            "--workers",
            "1",
            "--cpu-percent",
            "45",
            "--cpus",
            "0,1",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(&format!("cannot write '+cpu' to {}", control.display())),
        "{stderr}"
    );

    // The hosts benchmark stops at its first farm.
    let root = tempfile::tempdir().unwrap();
    let out = run(
        "hosts.sh",
        root.path(),
        &["--dry-run", "--cpus", "0,1", "--configs", "45 45,45"],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    assert!(text(&out.stderr).contains("refusing to run without quotas"));
}

#[test]
fn bad_arguments_are_refused_naming_the_option() {
    let root = fake_v1();
    for (args, message) in [
        (
            &["--workers", "3", "--cpu-percent", "45,15"][..],
            "--cpu-percent 45,15 gives 2 values for 3 workers (--workers)",
        ),
        (
            &["--workers", "3", "--mbit", "100,10"][..],
            "--mbit 100,10 gives 2 values for 3 workers (--workers)",
        ),
        (
            &["--workers", "2", "--cpu-percent", "60,45"][..],
            "their shares must add up to at most 100 (they add up to 105)",
        ),
        (
            &["--workers", "1", "--cpu-percent", "5"][..],
            "--cpu-percent 5: give a share of one core from 10 to 100",
        ),
        (
            &["--workers", "1", "--cpu-percent", "120"][..],
            "--cpu-percent 120: give a share of one core from 10 to 100",
        ),
        (
            &["--workers", "2", "--mbit", "100,fast"][..],
            "--mbit 100,fast: 'fast' is not a positive number",
        ),
        (
            &["--localhost", "--mbit", "100"][..],
            "--localhost has no links to limit",
        ),
        (&["--workers", "0"][..], "--workers 0: give 1 to 64"),
        (&["--frames", "2"][..], "--frames 2: give at least 4"),
        (&["--bogus", "1"][..], "unknown option --bogus"),
        (
            &["--cpus", "0,1"][..],
            "--cpus lays out the workers under --cpu-percent",
        ),
        (
            &["--cpu-percent", "20", "--cpus", "0;1"][..],
            "--cpus 0;1: not a CPU list",
        ),
        (&["--workers"][..], "--workers needs a value"),
    ] {
        let mut all = vec!["--dry-run"];
        all.extend_from_slice(args);
        let out = run("lab.sh", root.path(), &all);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(message), "{args:?}: {stderr}");
    }
    // None of them made a cgroup: arguments are checked first.
    assert_eq!(
        std::fs::read_dir(root.path().join("cpu")).unwrap().count(),
        2
    );

    // Quotas on a one-core layout cannot keep the workers off the master's core.
    let out = run(
        "lab.sh",
        root.path(),
        &[
            "--dry-run",
            "--workers",
            "1",
            "--cpu-percent",
            "45",
            "--cpus",
            "0",
        ],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("--cpu-percent needs two cores"));

    let out = run(
        "hosts.sh",
        root.path(),
        &["--dry-run", "--configs", "45 45,x"],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("'45,x' is not a comma-separated list of percents"),
        "{}",
        text(&out.stderr)
    );
    // A farm's links are checked against its workers by lab.sh.
    let out = run(
        "hosts.sh",
        root.path(),
        &["--dry-run", "--cpus", "0,1", "--configs", "45,45@100,10,5"],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--mbit 100,10,5 gives 3 values for 2 workers"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn the_hosts_benchmark_gives_every_farm_its_quotas() {
    let root = fake_v1();
    let out = run(
        "hosts.sh",
        root.path(),
        &[
            "--dry-run",
            "--cpus",
            "0,1",
            "--frames",
            "8",
            "--configs",
            "45 45,45 22,22,22,22 45,15 45,45@100,10",
        ],
    );
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert_eq!(stdout.matches("lab (dry run)").count(), 5, "{stdout}");
    assert_eq!(stdout.matches("; localhost").count(), 4, "{stdout}");
    // The farm with links: a 10 Mbit worker beside a 100 Mbit one.
    assert!(
        stdout.contains("tbf links: workers 100,10 Mbit/s, master 100 Mbit/s"),
        "{stdout}"
    );
    assert!(
        stdout.contains("--link-mbit 100 --worker-mbit 100,10"),
        "{stdout}"
    );
    for workers in ["1 worker", "2 workers", "4 workers"] {
        assert!(stdout.contains(&format!("{workers}, 8 frames")), "{stdout}");
    }
    assert!(stdout.contains("--worker-speed 0.45,0.15"), "{stdout}");
    // Each farm's own groups (one per run), with its workers' quotas.
    let cpu = root.path().join("cpu");
    let quotas = |w: usize| -> Vec<String> {
        (groups_of_worker(&cpu, w).iter())
            .map(|g| read(&g.join("cpu.cfs_quota_us")))
            .collect()
    };
    let mut first = quotas(1);
    first.sort();
    assert_eq!(first, ["2200", "4500", "4500", "4500", "4500"]);
    let mut second = quotas(2);
    second.sort();
    assert_eq!(second, ["1500", "2200", "4500", "4500"]);
    assert_eq!(quotas(3), ["2200"]);
    assert_eq!(quotas(4), ["2200"]);
}

/// `in_cgroup` writes the process's own PID into the group before it runs
/// the command (the exec keeps the PID).
#[test]
fn a_worker_joins_its_cgroup_before_it_runs() {
    let root = fake_v1();
    let group = root.path().join("cpu/w1");
    std::fs::create_dir(&group).unwrap();
    let pid_file = root.path().join("pid");
    let out = Command::new("timeout")
        .args([SCRIPT_LIMIT_SECONDS, "bash", "-c"])
        .arg(
            r#"set -eu; source "$1"; in_cgroup "$2"; "${in_cgroup_cmd[@]}" sh -c 'echo $$ >"$0"' "$3""#,
        )
        .arg("bash")
        .arg(script("farm-common.sh"))
        .arg(&group)
        .arg(&pid_file)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let pid = read(&pid_file);
    assert!(pid.parse::<u32>().is_ok(), "{pid}");
    assert_eq!(read(&group.join("cgroup.procs")), pid);
}

/// `stop_pids` ends even a process that ignores TERM (once it says it
/// does), and reaps it.
#[test]
fn stopping_the_farm_is_bounded_even_for_a_process_that_ignores_term() {
    let out = Command::new("timeout")
        .args([SCRIPT_LIMIT_SECONDS, "bash", "-c"])
        .arg(
            r#"set -eu; source "$1"; ready=$(mktemp -u)
            sh -c 'trap "" TERM; : >"$0"; while :; do sleep 1; done' "$ready" & stubborn=$!
            for _ in $(seq 1 200); do [ -e "$ready" ] && break; read -rt 0.05 -u "$sleeper" || true; done
            [ -e "$ready" ] || { echo "never ready"; exit 1; }
            rm -f "$ready"
            sleep 0.2 & quick=$!
            stop_pids "$stubborn" "$quick"
            if alive "$stubborn" || kill -0 "$stubborn" 2>/dev/null; then echo "still there"; exit 1; fi
            echo stopped"#,
        )
        .arg("bash")
        .arg(script("farm-common.sh"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    assert_eq!(text(&out.stdout).trim(), "stopped");
}

/// `quota_throttled` reads a group's cpu.stat the same way for v1 and v2
/// (v2's has usage figures beside the period counts).
#[test]
fn throttling_is_read_from_cpu_stat_in_v1_and_v2() {
    let dir = tempfile::tempdir().unwrap();
    for (name, stat) in [
        (
            "v1",
            "nr_periods 812\nnr_throttled 377\nthrottled_time 1520000000\n",
        ),
        (
            "v2",
            "usage_usec 9000\nuser_usec 8000\nsystem_usec 1000\nnr_periods 812\nnr_throttled 377\nthrottled_usec 1520000\n",
        ),
    ] {
        let group = dir.path().join(name);
        std::fs::create_dir(&group).unwrap();
        std::fs::write(group.join("cpu.stat"), stat).unwrap();
        let out = Command::new("timeout")
            .args([SCRIPT_LIMIT_SECONDS, "bash", "-c"])
            .arg(r#"set -eu; source "$1"; quota_throttled "$2""#)
            .arg("bash")
            .arg(script("farm-common.sh"))
            .arg(&group)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", text(&out.stderr));
        assert_eq!(text(&out.stdout).trim(), "377 812", "{name}");
    }
}

/// The lab lays out the cores the kernel allows it, in its list's form.
#[test]
fn cpu_lists_expand_their_ranges() {
    let out = Command::new("timeout")
        .args([SCRIPT_LIMIT_SECONDS, "bash", "-c"])
        .arg(r#"set -eu; source "$1"; cpu_list 0-2,5,7-8; cpu_list 3"#)
        .arg("bash")
        .arg(script("farm-common.sh"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "0,1,2,5,7,8\n3\n");
}

/// Frames that wait for a slow worker's reach the submitter in a bunch; the
/// steady window starts at the end of the bunch that holds its first frame,
/// so that it counts whole bunches. Evenly spaced frames keep their start.
#[test]
fn the_steady_window_starts_at_the_end_of_a_bunch() {
    let dir = tempfile::tempdir().unwrap();
    let stats = |name: &str, arrivals: &[u64]| {
        let frames: Vec<String> = (arrivals.iter())
            .map(|a| format!(r#"{{"arrival_micros": {a}}}"#))
            .collect();
        let path = dir.path().join(name);
        std::fs::write(&path, format!("[{}]", frames.join(","))).unwrap();
        path
    };
    // A slow frame every 2.5 s releases three waiting ones within 30 ms;
    // listed out of order, as frames finished out of order arrive.
    let bunched = stats(
        "bunched.json",
        &[
            2_500_000, 2_510_000, 0, 2_520_000, 5_000_000, 5_010_000, 5_020_000, 7_500_000,
        ],
    );
    let even = stats(
        "even.json",
        &[0, 1_000_000, 2_000_000, 3_000_000, 4_000_000],
    );
    let out = Command::new("timeout")
        .args([SCRIPT_LIMIT_SECONDS, "bash", "-c"])
        .arg(r#"set -eu; source "$1"; window_start "$2" 1; window_start "$2" 4; window_start "$3" 1"#)
        .arg("bash")
        .arg(script("farm-common.sh"))
        .args([&bunched, &even])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "3\n6\n1\n");
}

/// A farm of a fast and a slow worker: the fast worker's frames wait for
/// the slow one's and arrive in a bunch, but their completions at the
/// master (arrival less the held time: the wall less the workers' phases'
/// span) keep their own pace, and the steady window's rate is taken over
/// those. A frame without worker phases counts at its arrival.
#[test]
fn the_steady_rate_is_timed_by_completions_not_bunched_arrivals() {
    let dir = tempfile::tempdir().unwrap();
    let frame = |arrival: u64, wall: u64, span: (u64, u64)| {
        format!(
            r#"{{"arrival_micros": {arrival}, "wall_micros": {wall}, "phases": [
                {{"who": "master", "kind": "base", "start_micros": 0, "end_micros": 0}},
                {{"who": "w1", "kind": "setup", "start_micros": {}, "end_micros": {}}},
                {{"who": "w1", "kind": "package", "start_micros": {}, "end_micros": {}}}]}}"#,
            span.0,
            span.0 + 1000,
            span.0 + 1000,
            span.1
        )
    };
    // Frame 0 by the slow worker (3 s), frames 1 and 2 by the fast one
    // (1 s each, done at 1 s and 2 s, held until 3 s); frame 3 resumed.
    let frames = [
        frame(3_000_000, 3_000_000, (0, 3_000_000)),
        frame(3_000_100, 3_000_100, (0, 1_000_000)),
        frame(3_000_200, 2_000_200, (1_000_000, 2_000_000)),
        r#"{"arrival_micros": 4000000, "wall_micros": 0, "phases": []}"#.to_owned(),
    ];
    let stats = dir.path().join("stats.json");
    std::fs::write(&stats, format!("[{}]", frames.join(","))).unwrap();
    let out = Command::new("timeout")
        .args([SCRIPT_LIMIT_SECONDS, "python3", "-c"])
        .arg(
            "import json, sys; sys.path.insert(0, sys.argv[1]); \
             from steady_window import completions, seconds_per_frame; \
             t = completions(json.load(open(sys.argv[2]))); \
             print(' '.join(f'{x:.1f}' for x in t)); print(f'{seconds_per_frame(t, 1):.2f}')",
        )
        .arg(script(""))
        .arg(&stats)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "1.0 2.0 3.0 4.0\n1.00\n");
}
