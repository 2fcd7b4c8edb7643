#!/usr/bin/env bash
# Measures what a second machine buys: a real master with one, then two
# `vtfarm worker --threads 1`, each worker pinned to its own core (taskset),
# running the same job (default: the cockpit at detail 2.1, 1920x1080, `full`,
# 8 frames). Both runs happen in this one invocation, so the printed ratio
# compares like with like even on a machine shared with other work (the
# absolute figures are noisy there: quote ratios).
#
# Usage: scripts/scaling.sh [--workers "1 2"] [--frames 8] [--width 1920]
#        [--height 1080] [--detail 2.1] [--bin target/release/vtfarm]
#        [--keep DIR]   (keeps each run's frames, stats.json and timelines)
# Prints one line per worker count: the mean frame time (the interval between
# frame arrivals at the submitter, first frame left out: it includes the scene
# transfer and BVH builds), its ratio to the first count's, and the
# simulator's prediction for the same job and workers (`vtfarm bench simulate
# --shared-cores`: the master core and worker sessions with costs recorded on
# this machine, all sharing its cores) with measured/predicted.
set -euo pipefail

workers_list="1 2"; frames=8; width=1920; height=1080; detail=2.1
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

declare -A mean
for n in $workers_list; do
  pids=()
  RUST_LOG=warn "$bin" master --cluster "$work/cluster/cluster.toml" --listen "127.0.0.1:$port" \
    >"$work/master-$n.log" 2>&1 &
  pids+=($!)
  for ((w = 0; w < n; w++)); do
    core=$((w % cores))
    RUST_LOG=warn taskset -c "$core" "$bin" worker --cluster "$work/cluster/cluster.toml" \
      --threads 1 --name "w$w" --cache "$work/cache-$w" >"$work/worker-$n-$w.log" 2>&1 &
    pids+=($!)
  done
  wait_for_workers "$n"
  out="$work/out-$n"
  timeout 600 "$bin" submit "$work/job.toml" --cluster "$work/cluster/cluster.toml" -o "$out" \
    >"$work/submit-$n.log" 2>&1 || { cat "$work/submit-$n.log" >&2; exit 1; }
  mean[$n]=$(frame_figures "$out/stats.json")
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  pids=()
  [ -n "$keep" ] && mkdir -p "$keep" && cp -r "$out" "$keep/workers-$n"
done

# The simulator's prediction for each count: the master core and worker
# sessions on a virtual clock, everything sharing this machine's cores
# (`--shared-cores`), localhost links. Twice: with the fixed costs (base
# frame, set-up) timed by the simulator itself, and with those measured in
# the first count's run (its stats.json phases).
first=${workers_list%% *}
declare -A predicted predicted_phases
for n in $workers_list; do
  for source in recorded phases; do
    extra=()
    [ "$source" = phases ] && extra=(--fixed-costs "$work/out-$first/stats.json")
    "$bin" bench simulate --workers "$n" --link-mbit 10000 --latency-ms 0.05 --frames "$frames" \
      --width "$width" --height "$height" --detail "$detail" --repeats 1 --threads 1 \
      --shared-cores "$cores" "${extra[@]}" --json "$work/sim-$n-$source.json" >"$work/sim-$n-$source.log" 2>&1 \
      || { cat "$work/sim-$n-$source.log" >&2; exit 1; }
    p=$(python3 -c 'import json, sys; print([r for r in json.load(open(sys.argv[1])) if not r["heterogeneous"]][-1]["frame_seconds"])' "$work/sim-$n-$source.json")
    if [ "$source" = phases ]; then predicted_phases[$n]=$p; else predicted[$n]=$p; fi
  done
done

read -r base _ <<<"${mean[$first]}"
echo "job: cockpit detail $detail, ${width}x${height}, full, $frames frames; $cores cores; workers pinned, --threads 1"
printf "%8s %16s %13s %9s %15s %13s %10s %13s %10s\n" workers "frame interval s" "frame wall s" speed-up "result MB/frame" "predicted s" "meas/pred" "pred.phases s" "meas/pred"
for n in $workers_list; do
  read -r gap wall bytes raw <<<"${mean[$n]}"
  p=${predicted[$n]}; q=${predicted_phases[$n]}
  printf "%8s %16s %13s %9s %15s %13.4f %10s %13.4f %10s\n" "$n" "$gap" "$wall" "$(awk -v a="$base" -v b="$gap" 'BEGIN { printf "%.2fx", a / b }')" "$bytes" "$p" "$(awk -v a="$gap" -v b="$p" 'BEGIN { printf "%.2f", a / b }')" "$q" "$(awk -v a="$gap" -v b="$q" 'BEGIN { printf "%.2f", a / b }')"
done
echo "predicted: vtfarm bench simulate --shared-cores $cores (master core and worker sessions on a virtual clock), fixed costs timed by it; pred.phases: base frame and set-up from the $first-worker run's stats.json phases"
echo "result MB: results as sent (zstd byte planes, colour only)"
