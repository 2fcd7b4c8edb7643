#!/usr/bin/env bash
# Lab mode: the farm on emulated hosts inside this machine (docs/lab.md).
# As root, the master and each worker run in their own network namespace;
# every host's veth joins one bridge (in a switch namespace) and is rate
# limited with a `tc` token bucket (tbf) both ways: each worker's link at
# its --mbit, the master's at --master-mbit (the one link all results
# share). With --localhost everything talks over 127.0.0.1 instead (no
# namespaces, no links to limit).
#
# --cpu-percent makes each one-thread worker a slower machine: a CPU quota
# (cgroup v2 cpu.max, or v1 cpu.cfs_quota_us; a 10 ms period) holds it to
# that share of one core. The workers are then pinned to the first allowed
# core (taskset) and the master and the submitter to the others, so no
# worker contends with the master: the layout of separate hosts. Where no
# quota can be made, the lab says why and exits 1; it never runs without.
#
# Runs one job, prints the frames per second over the second half of the
# frames (the first half holds the start-up and a burst of pipelined
# frames), timed by their completion at the master, result bytes and each process's CPU per frame next to the
# simulator's prediction (`vtfarm bench simulate` with the same workers,
# speeds, links and job), and removes everything it created. Without root
# (namespaces) it prints why and exits 0. Addresses are 10.77.x.y inside
# its own namespaces only; nothing leaves this machine.
#
# Usage: sudo scripts/lab.sh [--workers 4] [--mbit 100[,10,...]] [--master-mbit M]
#   [--frames 16] [--width 1920] [--height 1080] [--detail 2.1]
#   [--cpu-percent P[,P,...]] [--cpus LIST] [--localhost]
#   [--bin target/release/vtfarm] [--json FILE] [--dry-run]
# --mbit, --cpu-percent: one value for every worker, or one each.
# --master-mbit: the master's link (default: the fastest worker link).
# --cpus: the cores to lay out, a CPU list such as 0-3 (default: this process's allowed ones); the
#   first holds the workers, the rest the master and the submitter.
# --dry-run: checks the arguments, makes the quotas' cgroups (and removes
#   them), prints the plan and the prediction's command, runs nothing.
# Environment: VTFARM_CGROUP_ROOT (default /sys/fs/cgroup).
set -euo pipefail
# shellcheck source=scripts/farm-common.sh
source "$(dirname "$0")/farm-common.sh"

workers=4; mbit=""; master_mbit=""; frames=16; width=1920; height=1080; detail=2.1
cpu=""; cpus=""; localhost=false; dry_run=false; json=""
bin=target/release/vtfarm
while [ $# -gt 0 ]; do
  case "$1" in
    --localhost) localhost=true; shift; continue;;
    --dry-run) dry_run=true; shift; continue;;
  esac
  [ $# -ge 2 ] || die 2 "$1 needs a value"
  case "$1" in
    --workers) workers="$2";;
    --mbit) mbit="$2";;
    --master-mbit) master_mbit="$2";;
    --frames) frames="$2";;
    --width) width="$2";;
    --height) height="$2";;
    --detail) detail="$2";;
    --cpu-percent) cpu="$2";;
    --cpus) cpus="$2";;
    --bin) bin="$2";;
    --json) json="$2";;
    *) die 2 "unknown option $1";;
  esac
  shift 2
done

[[ $workers =~ ^[1-9][0-9]*$ ]] && [ "$workers" -le 64 ] || die 2 "--workers $workers: give 1 to 64"
[[ $frames =~ ^[0-9]+$ ]] && [ "$frames" -ge 4 ] || die 2 "--frames $frames: give at least 4 (the figures take the second half)"
if $localhost; then
  [ -z "$mbit$master_mbit" ] || die 2 "--localhost has no links to limit: leave out --mbit and --master-mbit"
  mbits=()
else
  per_worker_list mbits --mbit "${mbit:-100}" "$workers"
  master_mbit=${master_mbit:-$(printf '%s\n' "${mbits[@]}" | sort -g | tail -n 1)}
  is_positive "$master_mbit" || die 2 "--master-mbit $master_mbit: not a positive number"
fi
percents=()
[ -n "$cpu" ] || [ -z "$cpus" ] || die 2 "--cpus lays out the workers under --cpu-percent: give both"
if [ -n "$cpu" ]; then
  per_worker_list percents --cpu-percent "$cpu" "$workers"
  for p in "${percents[@]}"; do
    cpu_quota_us "$p" >/dev/null ||
      die 2 "--cpu-percent $p: give a share of one core from 10 to 100 (the quota is at least 1 ms of each $((cpu_period_us / 1000)) ms period)"
  done
  # The workers share one core: together they must fit in it.
  total=$(printf '%s\n' "${percents[@]}" | awk '{ s += $1 } END { print s }')
  awk -v t="$total" 'BEGIN { exit !(t <= 100) }' ||
    die 2 "--cpu-percent $cpu: the workers share one core, so their shares must add up to at most 100 (they add up to $total)"
  [ -z "$cpus" ] || [[ $cpus =~ ^[0-9]+(-[0-9]+)?(,[0-9]+(-[0-9]+)?)*$ ]] || die 2 "--cpus $cpus: not a CPU list (e.g. 0,1 or 0-3)"
  IFS=, read -ra cores_list <<<"$(if [ -n "$cpus" ]; then cpu_list "$cpus"; else allowed_cpus; fi)"
  [ "${#cores_list[@]}" -ge 2 ] ||
    die 1 "--cpu-percent needs two cores (the workers on one, the master and the submitter on the others); allowed: ${cores_list[*]}"
  worker_cpu=${cores_list[0]}
  master_cpus=$(IFS=,; echo "${cores_list[*]:1}")
  master_threads=$((${#cores_list[@]} - 1))
fi

tag="vtlab$$"
work=$(mktemp -d /tmp/vtfarm-lab.XXXXXX)
pids=()
cleanup() {
  stop_pids "${pids[@]}" ${submit_pid:+"$submit_pid"}
  if ! $localhost && command -v ip >/dev/null; then
    for ns in $(ip netns list 2>/dev/null | awk '{print $1}' | grep "^$tag-" || true); do ip netns del "$ns"; done
  fi
  quota_remove_all
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# The quotas first: where none can be made, nothing else starts.
groups=()
for ((i = 1; i <= workers; i++)); do
  [ ${#percents[@]} -gt 0 ] || break
  quota_create "$tag-w$i" "${percents[i - 1]}"
  groups+=("$quota_dir")
done

join() { (IFS=,; echo "$*"); }
speeds=()
for p in "${percents[@]}"; do speeds+=("$(awk -v p="$p" 'BEGIN { printf "%g", p / 100 }')"); done

# The prediction: the simulator (the master core and worker sessions on a
# virtual clock) with the same job, workers and links. With quotas the
# hosts are separate: each worker on a machine of its own at its quota's
# speed, the master and the submitter on their cores at full speed (only
# what the quota holds is slower). Without, everything shares this
# machine's cores (`--shared-cores`) with the other work the run met there
# (`--background-cores`, from /proc/stat, added after the run).
cores=$(nproc)
sim=(bench simulate --workers "$workers" --latency-ms 0.05 --frames "$frames" --width "$width"
  --height "$height" --detail "$detail" --repeats 1 --threads 1 --json "$work/sim.json")
if $localhost; then
  sim+=(--link-mbit 10000)
else
  sim+=(--link-mbit "$master_mbit" --worker-mbit "$(join "${mbits[@]}")")
fi
if [ ${#percents[@]} -gt 0 ]; then
  sim+=(--master-threads "$master_threads" --worker-speed "$(join "${speeds[@]}")")
else
  sim+=(--shared-cores "$cores")
fi

links_text() {
  if $localhost; then echo "localhost"; else echo "tbf links: workers $(join "${mbits[@]}") Mbit/s, master $master_mbit Mbit/s, through one bridge"; fi
}
if $dry_run; then
  echo "lab (dry run): $workers worker$([ "$workers" = 1 ] || echo s), $frames frames of the cockpit at detail $detail, ${width}x${height}, full; $(links_text)"
  for ((i = 1; i <= workers; i++)); do
    if [ ${#percents[@]} -gt 0 ]; then
      g=${groups[i - 1]}
      if [ "$quota_version" = v2 ]; then
        echo "  w$i: ${percents[i - 1]}% of core $worker_cpu: $g/cpu.max = $(cat "$g/cpu.max")"
      else
        echo "  w$i: ${percents[i - 1]}% of core $worker_cpu: $g/cpu.cfs_quota_us = $(cat "$g/cpu.cfs_quota_us"), cpu.cfs_period_us = $(cat "$g/cpu.cfs_period_us")"
      fi
    else
      echo "  w$i: no quota, not pinned"
    fi
  done
  [ ${#percents[@]} -eq 0 ] || echo "  master and submitter: cores $master_cpus (taskset); quotas through cgroup $quota_version under $cgroup_root"
  extra=""; [ ${#percents[@]} -gt 0 ] || extra=" --background-cores MEASURED"
  echo "  prediction: vtfarm ${sim[*]}$extra"
  exit 0
fi

if ! $localhost; then
  skip() { echo "lab skipped: $*"; exit 0; }
  [ "$(id -u)" = 0 ] || skip "needs root (network namespaces, tc)"
  command -v ip >/dev/null && command -v tc >/dev/null || skip "needs ip and tc (iproute2)"
fi
[ -x "$bin" ] || die 1 "no $bin: run cargo build --release -p vtfarm first"
bin=$(realpath "$bin")
export RUST_LOG=warn

# Command prefixes: where the master (and the submitter) and each worker run.
in_master=(); pin_master=(); pin_worker=()
if [ ${#percents[@]} -gt 0 ]; then
  pin_master=(taskset -c "$master_cpus")
  pin_worker=(taskset -c "$worker_cpu")
fi
if $localhost; then
  port=$((20000 + RANDOM % 20000))
  master_addr=127.0.0.1
  master_flags=(--listen "127.0.0.1:$port" --http 127.0.0.1:0)
else
  ip netns add "$tag-sw" 2>/dev/null || skip "cannot create network namespaces here"
  port=7878
  master_addr=10.77.0.1
  master_flags=()
  in_master=(ip netns exec "$tag-m")
  # One host: namespace $1 with address $2, its veth on the bridge, both
  # ends limited to $4 Mbit/s.
  limit() { ip netns exec "$1" tc qdisc add dev "$2" root tbf rate "${3}mbit" burst 64kb latency 100ms; }
  ip netns exec "$tag-sw" ip link add br0 type bridge
  ip netns exec "$tag-sw" ip link set br0 up
  host() {
    local ns="$tag-$1" addr="$2" k="$3" rate="$4"
    ip netns add "$ns"
    ip link add "v$tag$k" type veth peer name "s$tag$k"
    ip link set "v$tag$k" netns "$ns" name eth0
    ip link set "s$tag$k" netns "$tag-sw"
    ip netns exec "$tag-sw" ip link set "s$tag$k" master br0 up
    ip netns exec "$ns" ip addr add "$addr/16" dev eth0
    ip netns exec "$ns" ip link set eth0 up
    ip netns exec "$ns" ip link set lo up
    limit "$ns" eth0 "$rate"
    limit "$tag-sw" "s$tag$k" "$rate"
  }
  host m 10.77.0.1 0 "$master_mbit"
  for ((i = 1; i <= workers; i++)); do host "w$i" "10.77.1.$i" "$i" "${mbits[i - 1]}"; done
fi

write_job "$work/job.toml" "$frames" "$width" "$height" "$detail"
"$bin" cluster init -o "$work/cluster" --master "$master_addr:$port" >/dev/null
cluster="$work/cluster/cluster.toml"
"${pin_master[@]}" "${in_master[@]}" "$bin" master --cluster "$cluster" "${master_flags[@]}" >"$work/master.log" 2>&1 &
pids+=($!)
for ((i = 1; i <= workers; i++)); do
  in_worker=(); in_cgroup_cmd=()
  $localhost || in_worker=(ip netns exec "$tag-w$i")
  [ ${#groups[@]} -eq 0 ] || in_cgroup "${groups[i - 1]}"
  # The cgroup first: `ip netns exec` mounts a sysfs of its own, without
  # the cgroup hierarchies; the namespaced process inherits its cgroup.
  "${in_cgroup_cmd[@]}" "${in_worker[@]}" "${pin_worker[@]}" "$bin" worker --cluster "$cluster" --threads 1 \
    --name "w$i" --cache "$work/cache-$i" >"$work/w$i.log" 2>&1 &
  pids+=($!)
done
# Wait (bounded) for every worker to join.
n=0
for _ in $(seq 1 100); do
  n=$(timeout 5 "${in_master[@]}" "$bin" status --cluster "$cluster" 2>/dev/null | grep -c '^w[0-9]' || true)
  [ "$n" -ge "$workers" ] && break
  read -rt 0.2 -u "$sleeper" || true
done
[ "$n" -ge "$workers" ] || { echo "workers did not join" >&2; cat "$work"/w1.log "$work/master.log" >&2; exit 1; }
# The figures: the second half of the frames, over the time from the
# completion at the master that ends the first half to the last
# (steady_window.py: arrivals bunch behind a slow worker's frames, the
# completions do not); CPU over the arrivals from the end of the bunch that
# holds the same arrival.
measure_from=$((frames / 2 - 1))
measured_submit "$work/out" "$work/submit.log" "$frames" "${pids[@]}" -- \
  "${pin_master[@]}" "${in_master[@]}" "$bin" submit "$work/job.toml" --cluster "$cluster" -o "$work/out"
throttled=()
for g in "${groups[@]}"; do throttled+=("$(quota_throttled "$g" | tr ' ' /)"); done
stop_pids "${pids[@]}"
pids=()

others=$job_others; [ "$others" = nan ] && others=0
[ ${#percents[@]} -gt 0 ] || sim+=(--background-cores "$others")
timeout 1800 "$bin" "${sim[@]}" >"$work/sim.log" 2>&1 || { cat "$work/sim.log" >&2; die 1 "the prediction (vtfarm ${sim[*]}) failed"; }
read -r _ _ sent _ <<<"$(frame_figures "$work/out/stats.json" "$job_from")"

if [ ${#percents[@]} -gt 0 ]; then
  layout="each worker a one-thread process held to its share of core $worker_cpu by a CPU quota (cgroup $quota_version, ${cpu_period_us} us period): $(join "${percents[@]}") %; the master and the submitter on core(s) $master_cpus"
else
  layout="all on this machine's $cores cores, not pinned"
fi
python3 - "$work/sim.json" "$job_from" "$frames" "$measure_from" "$work/out/stats.json" "$sent" "$job_cpu" "$others" \
  "$(join "${percents[@]}")" "$(join "${mbits[@]}")" "${master_mbit:-}" "$($localhost && echo localhost || echo tbf)" \
  "$cores" "$(cut -d' ' -f1-3 /proc/loadavg)" "$json" "$workers" "$width" "$height" "$detail" "$(join "${throttled[@]}")" \
  "lab: $workers workers, $(links_text); $layout; other processes used $others cores meanwhile" \
  "$farm_scripts" <<'PY'
import json, math, sys
(sim_path, start, frames, measure_from, stats_path, sent, cpu, others, percents, mbits, master_mbit, links,
 cores, load, out, workers, width, height, detail, throttled, headline, scripts) = sys.argv[1:]
sys.path.insert(0, scripts)
from steady_window import bunch_end, completions, seconds_per_frame
start, frames, measure_from, sent = int(start), int(frames), int(measure_from), float(sent)
row = [r for r in json.load(open(sim_path)) if not r["heterogeneous"]][-1]
completed = completions(json.load(open(stats_path)))
if len(completed) != frames:
    sys.exit(f"lab: {stats_path} holds {len(completed)} frames of {frames}")
measured = seconds_per_frame(completed, measure_from)
predicted = seconds_per_frame(sorted(row["completed_seconds_per_frame"]), measure_from)
# The frames in the order they were delivered, as the measured ones.
order = sorted(range(len(row["done_seconds_per_frame"])), key=lambda i: row["done_seconds_per_frame"][i])
done = [row["done_seconds_per_frame"][i] for i in order]
# The predicted frames bunch in their own way: their CPU window starts at
# the end of the bunch that holds the measured one's start.
pstart = bunch_end(done, start)
# CPU per frame over the same frames; a simulated worker's CPU is on its
# own machine at its speed: times the speed, the CPU the same work takes here.
at = [row["cpu_at_delivery"][i] for i in order]
speeds = row["worker_speeds"]
simulated = [(b - a) / max(frames - 1 - pstart, 1) for a, b in zip(at[pstart], at[-1])]
simulated = [simulated[0], simulated[-1], *(c * s for c, s in zip(simulated[1:-1], speeds))]
measured_cpu = [float(x) for x in cpu.split(",")]
fps = lambda s: 1 / s if s > 0 else math.nan
report = {
    "workers": int(workers), "cpu_percent": [float(p) for p in percents.split(",")] if percents else [],
    "worker_speeds": speeds, "links": links,
    "worker_mbit": [float(m) for m in mbits.split(",")] if mbits else [],
    "master_mbit": float(master_mbit) if master_mbit else None,
    "job": {"scene": "cockpit", "detail": float(detail), "width": int(width), "height": int(height),
            "quality": "full", "frames": frames},
    "measured_from_completion": measure_from, "measured_from_arrival": start, "predicted_from_arrival": pstart, "cores": int(cores), "load_average": load, "others_cores": float(others),
    "frame_seconds": measured, "predicted_frame_seconds": predicted,
    "frames_per_second": fps(measured), "predicted_frames_per_second": fps(predicted),
    "measured_over_predicted": fps(measured) / fps(predicted),
    "result_mb_per_frame": sent,
    # Per worker: periods its quota throttled it in, periods it ran in.
    "quota_throttled_periods": [list(map(int, t.split("/"))) for t in throttled.split(",")] if throttled else [],
    # Per worker: the share of its quota it used (CPU per frame x frames per
    # second over the share): below 1, it waited for work.
    "quota_used": [c * fps(measured) / (float(p) / 100) for c, p in zip(measured_cpu[2:], percents.split(","))]
                  if percents else [],
    "cpu_per_frame": {"master": measured_cpu[0], "submitter": measured_cpu[1], "workers": measured_cpu[2:]},
    "predicted_cpu_per_frame": {"master": simulated[0], "submitter": simulated[1], "workers": simulated[2:]},
}
print(headline)
print(f"  frames per second over the second half (completions at the master from the {measure_from}th on): measured {fps(measured):.3f} ({measured:.3f} s per frame), "
      f"predicted {fps(predicted):.3f} ({predicted:.3f} s); measured/predicted {report['measured_over_predicted']:.2f}")
if master_mbit:
    print(f"  results per frame: {sent:.3f} MB ({sent * 8 / float(master_mbit):.3f} s of the master link)")
else:
    print(f"  results per frame: {sent:.3f} MB")
w = lambda c: " + ".join(f"{x:.3f}" for x in c)
print(f"  CPU per frame (after arrival {start}, predicted after {pstart}, each the end of a bunch): master {measured_cpu[0]:.3f} s, submitter {measured_cpu[1]:.3f} s, workers {w(measured_cpu[2:])} s")
print(f"     simulated:  master {simulated[0]:.3f} s, submitter {simulated[1]:.3f} s, workers {w(simulated[2:])} s")
if percents:
    use = ", ".join(f"{u * 100:.0f}%" for u in report["quota_used"])
    held = ", ".join(f"{t} of {p}" for t, p in report["quota_throttled_periods"])
    print(f"  the workers used {use} of their quotas; throttled in {held} periods")
print(f"  load average {load}")
if out:
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
PY
