#!/usr/bin/env bash
# Emulated separate hosts, the benchmark of docs/lab.md: what every machine
# added buys. The master and the submitter are pinned to one core, each
# one-thread worker to the other and held to a share of it by a CPU quota
# (scripts/lab.sh --localhost --cpu-percent), so no worker contends with
# another or with the master. Runs each farm of --configs in turn on the
# same job (default: 24 frames of the cockpit at detail 2.1, 1920x1080,
# `full`) and prints, per farm, frames per second over the second half of
# the frames, the speed-up over one worker at the first worker's quota, the
# efficiency (frames per second over the sum of its workers' rates alone,
# where each quota ran alone too), each process's CPU per frame, and the
# simulator's prediction of each figure beside it (measured/predicted). The
# ratios compare runs of this one invocation: quote them, with the load.
#
# Usage: sudo scripts/hosts.sh [--configs "45 45,45 22 22,22,22,22 15 45,15"]
#   [--frames 24] [--width 1920] [--height 1080] [--detail 2.1] [--cpus LIST]
#   [--bin target/release/vtfarm] [--json FILE] [--keep DIR] [--dry-run]
# --configs: one farm per word, its workers' quotas in % of one core,
#   comma-separated ("45,15": two workers, 45% and 15%); "@" and Mbit/s
#   per worker put the farm behind rate-limited links instead of localhost
#   ("45,45@100,10": a 10 Mbit worker beside a 100 Mbit one; lab.sh --mbit).
# --json FILE: every farm's figures (default hosts.json in --keep DIR, if given).
# --keep DIR: keeps each farm's lab output and JSON.
# --dry-run: each farm's scripts/lab.sh --dry-run (arguments and quotas), nothing run.
set -euo pipefail
here=$(dirname "$0")
# shellcheck source=scripts/farm-common.sh
source "$here/farm-common.sh"

configs="45 45,45 22 22,22,22,22 15 45,15"; frames=24; width=1920; height=1080; detail=2.1
cpus=""; bin=target/release/vtfarm; json=""; keep=""; dry_run=false
while [ $# -gt 0 ]; do
  if [ "$1" = --dry-run ]; then dry_run=true; shift; continue; fi
  [ $# -ge 2 ] || die 2 "$1 needs a value"
  case "$1" in
    --configs) configs="$2";;
    --frames) frames="$2";;
    --width) width="$2";;
    --height) height="$2";;
    --detail) detail="$2";;
    --cpus) cpus="$2";;
    --bin) bin="$2";;
    --json) json="$2";;
    --keep) keep="$2";;
    *) die 2 "unknown option $1";;
  esac
  shift 2
done
read -ra farms <<<"$configs"
[ ${#farms[@]} -gt 0 ] || die 2 "--configs names no farm"
for farm in "${farms[@]}"; do
  [[ $farm =~ ^[0-9.]+(,[0-9.]+)*(@[0-9.]+(,[0-9.]+)*)?$ ]] ||
    die 2 "--configs: '$farm' is not a comma-separated list of percents (and optionally @ and one Mbit/s value per worker)"
done
[ -z "$keep" ] || mkdir -p "$keep"
[ -n "$json" ] || [ -z "$keep" ] || json="$keep/hosts.json"

work=$(mktemp -d /tmp/vtfarm-hosts.XXXXXX)
trap 'rm -rf "$work"' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

common=(--frames "$frames" --width "$width" --height "$height" --detail "$detail" --bin "$bin")
[ -z "$cpus" ] || common+=(--cpus "$cpus")
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
runs=()
for k in "${!farms[@]}"; do
  farm=${farms[k]}
  IFS=, read -ra quotas <<<"${farm%@*}"
  args=("${common[@]}" --workers "${#quotas[@]}" --cpu-percent "${farm%@*}" --json "$work/farm-$k.json")
  if [[ $farm == *@* ]]; then args+=(--mbit "${farm#*@}"); else args+=(--localhost); fi
  if $dry_run; then
    "$here/lab.sh" "${args[@]}" --dry-run
    continue
  fi
  echo "farm $((k + 1))/${#farms[@]}: ${#quotas[@]} worker(s) at $farm % ..." >&2
  "$here/lab.sh" "${args[@]}" >"$work/farm-$k.log" 2>&1 || { cat "$work/farm-$k.log" >&2; die 1 "the farm $farm failed"; }
  [ -s "$work/farm-$k.json" ] || { cat "$work/farm-$k.log" >&2; die 1 "the farm $farm wrote no figures (was the lab skipped?)"; }
  [ -z "$keep" ] || cp "$work/farm-$k.log" "$work/farm-$k.json" "$keep/"
  runs+=("$work/farm-$k.json")
done
$dry_run && exit 0

python3 - "$json" "$load_before" "$(cut -d' ' -f1-3 /proc/loadavg)" "$(date -u +%FT%TZ)" "${runs[@]}" <<'PY'
import json, sys
out, load_before, load_after, date, *paths = sys.argv[1:]
runs = [json.load(open(p)) for p in paths]
def label(r):
    quotas = (f"{r['workers']} x {r['cpu_percent'][0]:g}%" if len(set(r["cpu_percent"])) == 1
              else " + ".join(f"{p:g}%" for p in r["cpu_percent"]))
    return quotas + ("" if r["links"] == "localhost" else " @" + ",".join(f"{m:g}" for m in r["worker_mbit"]))
# One worker alone at each quota (on localhost): the rate each farm's workers add up to.
alone = {r["cpu_percent"][0]: r for r in runs if r["workers"] == 1 and r["links"] == "localhost"}
for r in runs:
    one = alone.get(r["cpu_percent"][0])
    parts = [alone.get(p) for p in r["cpu_percent"]]
    for key, rate in (("", "frames_per_second"), ("predicted_", "predicted_frames_per_second")):
        r[key + "speedup"] = r[rate] / one[rate] if one else None
        r[key + "efficiency"] = r[rate] / sum(p[rate] for p in parts) if all(parts) else None
job = runs[0]["job"]
print(f"emulated separate hosts: cockpit detail {job['detail']:g}, {job['width']}x{job['height']}, full, "
      f"{job['frames']} frames, frames per second from completion {job['frames'] // 2 - 1} at the master to the last (lab.sh); "
      f"{runs[0]['cores']} cores; load average {load_before} before, {load_after} after ({date})")
print("workers on one core under CPU quotas (10 ms period), the master and the submitter pinned to the other(s); "
      "predicted: vtfarm bench simulate --worker-speed (quota / 100) --master-threads (their cores)")
head = ("farm", "frames/s", "predicted", "meas/pred", "speed-up", "pred.", "effic.", "pred.", "CPU/frame: master", "submitter", "workers (s)")
print(f"{head[0]:<22} {head[1]:>9} {head[2]:>9} {head[3]:>9} {head[4]:>9} {head[5]:>6} {head[6]:>7} {head[7]:>6}  {head[8]} {head[9]} {head[10]}")
fmt = lambda x, f: "-" if x is None else format(x, f)
for r in runs:
    c, p = r["cpu_per_frame"], r["predicted_cpu_per_frame"]
    workers = " + ".join(f"{m:.3f} ({s:.3f})" for m, s in zip(c["workers"], p["workers"]))
    eff = lambda x: None if x is None else 100 * x
    print(f"{label(r):<22} {r['frames_per_second']:>9.3f} {r['predicted_frames_per_second']:>9.3f} "
          f"{r['measured_over_predicted']:>9.2f} {fmt(r['speedup'], '>8.2f')}x {fmt(r['predicted_speedup'], '>5.2f')}x "
          f"{fmt(eff(r['efficiency']), '>6.0f')}% {fmt(eff(r['predicted_efficiency']), '>5.0f')}%  "
          f"{c['master']:.3f} ({p['master']:.3f}) {c['submitter']:.3f} ({p['submitter']:.3f}) {workers}")
print("speed-up: over one worker at the farm's first quota; effic.: frames/s over the sum of its workers' rates alone; "
      "CPU per frame from /proc (the simulator's in brackets); others on the machine meanwhile: "
      + ", ".join(f"{r['others_cores']:.2f}" for r in runs) + " cores")
if out:
    with open(out, "w") as f:
        json.dump({"date": date, "load_average_before": load_before, "load_average_after": load_after, "farms": runs}, f, indent=1)
    print(f"wrote {out}")
PY
