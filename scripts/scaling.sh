#!/usr/bin/env bash
# Measures what a second machine buys: a real master with one, then two
# `vtfarm worker --threads 1`, each worker pinned to its own core (taskset),
# running the same job (default: the cockpit at detail 2.1, 1920x1080, `full`,
# 16 frames). Both runs happen in this one invocation, so the printed ratio
# compares like with like even on a machine shared with other work (the
# absolute figures are noisy there: quote ratios).
#
# Usage: scripts/scaling.sh [--workers "1 2"] [--frames 16] [--width 1920]
#        [--height 1080] [--detail 2.1] [--bin target/release/vtfarm]
#        [--keep DIR]   (keeps each run's frames, stats.json and timelines)
# Prints one line per worker count: the mean frame time (the interval between
# frame arrivals at the submitter in the steady state: from the first frame
# started after frame 0 arrived, see steady_frame), its ratio to the first count's, and the
# simulator's prediction for the same job and workers (`vtfarm bench simulate
# --shared-cores`: the master core and worker sessions with costs recorded on
# this machine in CPU time, all sharing its cores with the other work the run
# met, measured from /proc/stat) with measured/predicted. Then the CPU each
# process spent per frame in each run (from /proc, the same steady frames)
# beside the simulator's for it, and the floor it sets on this machine's cores: with a worker's
# set-up U and tracing T (from its CPU alone, U + T, and the workers' total
# with n, n U + T), n workers need at least max((master + submitter + n U +
# T) / cores, U + T / n) per frame, so the speed-up over one worker cannot
# exceed its measured interval over that floor.
set -euo pipefail

workers_list="1 2"; frames=16; width=1920; height=1080; detail=2.1
bin=target/release/vtfarm; keep=""
while [ $# -gt 0 ]; do
  case "$1" in
    --workers) workers_list="$2"; shift 2;;
    --frames) frames="$2"; shift 2;;
    --width) width="$2"; shift 2;;
    --height) height="$2"; shift 2;;
    --detail) detail="$2"; shift 2;;
    --bin) bin="$2"; shift 2;;
    --keep) keep="$2"; shift 2;;
    *) echo "unknown option $1" >&2; exit 2;;
  esac
done
[ -x "$bin" ] || { echo "no $bin: run cargo build --release first" >&2; exit 1; }
bin=$(realpath "$bin")
# shellcheck source=scripts/farm-common.sh
source "$(dirname "$0")/farm-common.sh"
cores=$(nproc)

work=$(mktemp -d /tmp/vtfarm-scaling.XXXXXX)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

write_job "$work/job.toml" "$frames" "$width" "$height" "$detail"

port=$((20000 + RANDOM % 20000))
"$bin" cluster init -o "$work/cluster" --master "127.0.0.1:$port" >/dev/null

# Waits (bounded) until `vtfarm status` lists $1 workers.
wait_for_workers() {
  for _ in $(seq 1 100); do
    n=$("$bin" status --cluster "$work/cluster/cluster.toml" 2>/dev/null | grep -c '^w[0-9]' || true)
    [ "$n" -ge "$1" ] && return 0
    sleep 0.2
  done
  echo "workers did not join" >&2; return 1
}

declare -A mean cpu others from predicted predicted_idle modelled_cpu
for n in $workers_list; do
  pids=()
  # The dashboard on a free port: another farm on this machine may hold the default.
  RUST_LOG=warn "$bin" master --cluster "$work/cluster/cluster.toml" --listen "127.0.0.1:$port" \
    --http 127.0.0.1:0 >"$work/master-$n.log" 2>&1 &
  pids+=($!)
  for ((w = 0; w < n; w++)); do
    core=$((w % cores))
    RUST_LOG=warn taskset -c "$core" "$bin" worker --cluster "$work/cluster/cluster.toml" \
      --threads 1 --name "w$w" --cache "$work/cache-$w" >"$work/worker-$n-$w.log" 2>&1 &
    pids+=($!)
  done
  wait_for_workers "$n"
  out="$work/out-$n"
  measured_submit "$out" "$work/submit-$n.log" "$frames" "${pids[@]}" -- \
    "$bin" submit "$work/job.toml" --cluster "$work/cluster/cluster.toml" -o "$out"
  mean[$n]=$(frame_figures "$out/stats.json" "$job_from")
  cpu[$n]=$job_cpu; others[$n]=$job_others; from[$n]=$job_from
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  pids=()
  # The simulator's prediction, recorded right after the run (the costs are
  # CPU times, but other work on the machine still slows the CPU a little,
  # and it changes from minute to minute): the master core and worker
  # sessions on a virtual clock, everything sharing this machine's cores
  # (`--shared-cores`), localhost links, and the other work this run met
  # (`--background-cores`: always-runnable threads, as many as use that much).
  background=${others[$n]}; [ "$background" = nan ] && background=0
  "$bin" bench simulate --workers "$n" --link-mbit 10000 --latency-ms 0.05 --frames "$frames" \
    --width "$width" --height "$height" --detail "$detail" --repeats 1 --threads 1 \
    --shared-cores "$cores" --background-cores "$background" --json "$work/sim-$n.json" >"$work/sim-$n.log" 2>&1 \
    || { cat "$work/sim-$n.log" >&2; exit 1; }
  read -r predicted[$n] predicted_idle[$n] modelled_cpu[$n] < <(python3 -c '
import json, sys
r = [r for r in json.load(open(sys.argv[1])) if not r["heterogeneous"]][-1]
print(r["frame_seconds"], r["frame_seconds_idle"], ",".join(f"{x:.4f}" for x in r["cpu_per_frame"]))
' "$work/sim-$n.json")
  [ -n "$keep" ] && mkdir -p "$keep" && cp -r "$out" "$keep/workers-$n" && cp "$work/sim-$n.log" "$work/sim-$n.json" "$keep/"
done

first=${workers_list%% *}
read -r base _ <<<"${mean[$first]}"
echo "job: cockpit detail $detail, ${width}x${height}, full, $frames frames (measured from the steady frame: $(for n in $workers_list; do printf "%s " "${from[$n]}"; done)); $cores cores; workers pinned, --threads 1"
printf "%8s %16s %13s %9s %15s %12s %12s %10s %13s\n" workers "frame interval s" "frame wall s" speed-up "result MB/frame" "others cores" "predicted s" "meas/pred" "pred. idle s"
for n in $workers_list; do
  read -r gap wall bytes raw <<<"${mean[$n]}"
  p=${predicted[$n]}; q=${predicted_idle[$n]}
  printf "%8s %16s %13s %9s %15s %12s %12.4f %10s %13.4f\n" "$n" "$gap" "$wall" "$(awk -v a="$base" -v b="$gap" 'BEGIN { printf "%.2fx", a / b }')" "$bytes" "${others[$n]}" "$p" "$(awk -v a="$gap" -v b="$p" 'BEGIN { printf "%.2f", a / b }')" "$q"
done
echo "others cores: CPU the machine's other processes used during the run (/proc/stat less the farm's), in cores"
echo "predicted: vtfarm bench simulate --shared-cores $cores --background-cores (master core and worker sessions on a virtual clock, costs timed by it in CPU time, that other work as always-runnable threads); pred. idle: the same without the other work"
echo "result MB: results as sent (zstd byte planes, colour only)"

# The CPU each process spent per frame (from /proc, frames after the
# first) and the floor it sets: a worker's set-up U and tracing T follow
# from its CPU with one worker (U + T) and the workers' total with n (n U + T).
cpu_args=()
for n in $workers_list; do cpu_args+=("$n" "${cpu[$n]}" "${mean[$n]%% *}" "${modelled_cpu[$n]}"); done
python3 - "$cores" "${cpu_args[@]}" <<'PY'
import sys
cores, rest = int(sys.argv[1]), sys.argv[2:]
runs, modelled = {}, {}
for i in range(0, len(rest), 4):
    n = int(rest[i])
    runs[n] = (list(map(float, rest[i + 1].split(","))), float(rest[i + 2]))
    modelled[n] = list(map(float, rest[i + 3].split(",")))
for n, (c, gap) in runs.items():
    total = sum(c)
    m = modelled[n]
    print(f"CPU per frame, {n} worker(s): master {c[0]:.3f} s, submitter {c[1]:.3f} s, "
          f"workers {' + '.join(f'{w:.3f}' for w in c[2:])} s; total {total:.3f} s = "
          f"{total / cores:.3f} s on {cores} cores (interval {gap:.3f} s)")
    print(f"  simulated:                master {m[0]:.3f} s, submitter {m[-1]:.3f} s, "
          f"workers {' + '.join(f'{w:.3f}' for w in m[1:-1])} s; total {sum(m):.3f} s")
first = min(runs)
more = [n for n in runs if n > first]
if first == 1 and more:
    (c1, t1), n = runs[1], more[0]
    setup = (sum(runs[n][0][2:]) - c1[2]) / (n - 1)
    tracing = c1[2] - setup
    m, s = c1[0], c1[1]
    print(f"one worker's set-up {setup:.3f} s and tracing {tracing:.3f} s per frame (from 1 and {n} workers' CPU)")
    floor = lambda k: max((m + s + k * setup + tracing) / cores, setup + tracing / k)
    for k in sorted(runs):
        print(f"  {k} worker(s): at least {floor(k):.3f} s per frame = max((master + submitter + {k} set-ups + tracing) / "
              f"{cores} cores, set-up + tracing / {k}); speed-up over 1 worker at most {floor(1) / floor(k):.2f}x when both "
              f"are CPU-bound ({t1 / floor(k):.2f}x over the measured {t1:.3f} s), "
              f"{(setup + tracing) / (setup + tracing / k):.2f}x with the master and submitter on other cores")
PY
