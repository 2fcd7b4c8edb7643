#!/usr/bin/env bash
# Lab mode: the farm on emulated hosts inside this machine. As root, the
# master and each worker run in their own network namespace; every host's
# veth joins one bridge (in a switch namespace) and is rate limited with a
# `tc` token bucket (tbf) both ways, so the master's link is the one link all
# results share. Optional cgroup v2 CPU quotas make workers slower machines.
# Runs a job, prints the measured mean frame time and bytes next to the
# simulator's prediction (`vtfarm bench simulate` with the same workers,
# link and job), and removes everything it created. Without the privileges
# it prints why and exits 0. Addresses are 10.77.x.y inside its own
# namespaces only; nothing leaves this machine.
#
# Usage: sudo scripts/lab.sh [--workers 4] [--mbit 100] [--frames 16]
#   [--width 1920] [--height 1080] [--detail 2.1] [--cpu-percent P]
#   [--bin target/release/vtfarm]
# --cpu-percent P: each worker gets P% of one core (cgroup v2 cpu.max).
set -euo pipefail

workers=4; mbit=100; frames=16; width=1920; height=1080; detail=2.1; cpu=""
bin=target/release/vtfarm
while [ $# -gt 0 ]; do
  case "$1" in
    --workers) workers="$2"; shift 2;;
    --mbit) mbit="$2"; shift 2;;
    --frames) frames="$2"; shift 2;;
    --width) width="$2"; shift 2;;
    --height) height="$2"; shift 2;;
    --detail) detail="$2"; shift 2;;
    --cpu-percent) cpu="$2"; shift 2;;
    --bin) bin="$2"; shift 2;;
    *) echo "unknown option $1" >&2; exit 2;;
  esac
done
skip() { echo "lab skipped: $*"; exit 0; }
[ "$(id -u)" = 0 ] || skip "needs root (network namespaces, tc)"
command -v ip >/dev/null && command -v tc >/dev/null || skip "needs ip and tc (iproute2)"
[ -x "$bin" ] || { echo "no $bin: run cargo build --release first" >&2; exit 1; }
bin=$(realpath "$bin")
# shellcheck source=scripts/farm-common.sh
source "$(dirname "$0")/farm-common.sh"
tag="vtlab$$"
ip netns add "$tag-sw" 2>/dev/null || skip "cannot create network namespaces here"

work=$(mktemp -d /tmp/vtfarm-lab.XXXXXX)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  for ns in $(ip netns list | awk '{print $1}' | grep "^$tag-" || true); do ip netns del "$ns"; done
  for g in /sys/fs/cgroup/"$tag"-*; do [ -d "$g" ] && rmdir "$g" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

# One host: namespace $1 with address $2, its veth on the bridge, both ends
# limited to $mbit.
limit() { ip netns exec "$1" tc qdisc add dev "$2" root tbf rate "${mbit}mbit" burst 64kb latency 100ms; }
ip netns exec "$tag-sw" ip link add br0 type bridge
ip netns exec "$tag-sw" ip link set br0 up
host() {
  local ns="$tag-$1" addr="$2" k="$3"
  ip netns add "$ns"
  ip link add "v$tag$k" type veth peer name "s$tag$k"
  ip link set "v$tag$k" netns "$ns" name eth0
  ip link set "s$tag$k" netns "$tag-sw"
  ip netns exec "$tag-sw" ip link set "s$tag$k" master br0 up
  ip netns exec "$ns" ip addr add "$addr/16" dev eth0
  ip netns exec "$ns" ip link set eth0 up
  ip netns exec "$ns" ip link set lo up
  limit "$ns" eth0
  limit "$tag-sw" "s$tag$k"
}
host m 10.77.0.1 0
for ((i = 1; i <= workers; i++)); do host "w$i" "10.77.1.$i" "$i"; done

write_job "$work/job.toml" "$frames" "$width" "$height" "$detail"
port=7878
"$bin" cluster init -o "$work/cluster" --master "10.77.0.1:$port" >/dev/null
cluster="$work/cluster/cluster.toml"
ip netns exec "$tag-m" env RUST_LOG=warn "$bin" master --cluster "$cluster" >"$work/master.log" 2>&1 &
pids+=($!)
for ((i = 1; i <= workers; i++)); do
  cmd=("$bin" worker --cluster "$cluster" --threads 1 --name "w$i" --cache "$work/cache-$i")
  if [ -n "$cpu" ] && [ -w /sys/fs/cgroup/cgroup.subtree_control ]; then
    g="/sys/fs/cgroup/$tag-w$i"; mkdir -p "$g"
    echo "$((cpu * 1000)) 100000" > "$g/cpu.max"
    ip netns exec "$tag-w$i" env RUST_LOG=warn sh -c 'echo $$ > "$0/cgroup.procs"; exec "$@"' "$g" "${cmd[@]}" >"$work/w$i.log" 2>&1 &
  else
    ip netns exec "$tag-w$i" env RUST_LOG=warn "${cmd[@]}" >"$work/w$i.log" 2>&1 &
  fi
  pids+=($!)
done
# Wait (bounded) for every worker to join.
for _ in $(seq 1 100); do
  n=$(ip netns exec "$tag-m" "$bin" status --cluster "$cluster" 2>/dev/null | grep -c '^w[0-9]' || true)
  [ "$n" -ge "$workers" ] && break
  sleep 0.2
done
[ "$n" -ge "$workers" ] || { echo "workers did not join" >&2; cat "$work"/w1.log >&2; exit 1; }
measured_submit "$work/out" "$work/submit.log" "$frames" "${pids[@]}" -- \
  ip netns exec "$tag-m" "$bin" submit "$work/job.toml" --cluster "$cluster" -o "$work/out"

# The prediction: the simulator (the master core and worker sessions on a
# virtual clock) with the same job, workers and links. The emulated hosts
# share this machine's cores (`--shared-cores`) with the other work the run
# met on it (`--background-cores`, from /proc/stat); a CPU quota makes the
# workers' work (and, roughly, the rest) 100/P times slower.
cores=$(nproc)
others=$job_others; [ "$others" = nan ] && others=0
scale=$(awk -v p="${cpu:-100}" 'BEGIN { printf "%.3f", 100 / p }')
"$bin" bench simulate --workers "$workers" --link-mbit "$mbit" --latency-ms 0.05 --frames "$frames" --width "$width" \
  --height "$height" --detail "$detail" --repeats 1 --threads 1 --shared-cores "$cores" --background-cores "$others" --cost-scale "$scale" \
  --fixed-cost-scale "$scale" --json "$work/sim.json" >"$work/sim.log" 2>&1 || { cat "$work/sim.log" >&2; exit 1; }
read -r measured _ sent _ <<<"$(frame_figures "$work/out/stats.json" "$job_from")"
read -r predicted predicted_idle modelled_cpu < <(python3 -c 'import json, sys; r = [r for r in json.load(open(sys.argv[1])) if not r["heterogeneous"]][-1]; print(r["frame_seconds"], r["frame_seconds_idle"], ",".join(f"{x:.3f}" for x in r["cpu_per_frame"]))' "$work/sim.json")
echo "lab: $workers workers, $mbit Mbit/s tbf links through one bridge, all on this machine's $cores cores (CPU x$scale); other processes used $others cores meanwhile"
awk -v m="$measured" -v p="$predicted" -v q="$predicted_idle" 'BEGIN { printf "  mean frame (from frame '"$job_from"', the steady state): measured %.3f s, predicted %.3f s, ratio %.2f (predicted on the idle machine %.3f s)\n", m, p, m / p, q }'
awk -v b="$sent" -v r="$mbit" 'BEGIN { printf "  results per frame: %.3f MB (%.3f s of the master link)\n", b, b * 8 / r }'
python3 - "$job_cpu" "$modelled_cpu" <<'PY'
import sys
c, m = [list(map(float, a.split(","))) for a in sys.argv[1:3]]
print(f"  CPU per frame: master {c[0]:.3f} s, submitter {c[1]:.3f} s, workers {' + '.join(f'{w:.3f}' for w in c[2:])} s")
print(f"     simulated:  master {m[0]:.3f} s, submitter {m[-1]:.3f} s, workers {' + '.join(f'{w:.3f}' for w in m[1:-1])} s")
PY
