# shellcheck shell=bash
# Shared by scripts/scaling.sh, scripts/lab.sh and scripts/hosts.sh (sourced,
# not run).

# write_job FILE FRAMES WIDTH HEIGHT DETAIL: the cockpit job, `full`, frame 0
# from the driver's eye and each next one from an eye 1 cm beside the last,
# swinging to 3 cm either side and back (0, +1, +2, +3, +2, ..., -3, -2, ...).
# Why it swings: the simulator's prediction replays the costs of frame 0, and
# an eye that drifted on (47 cm over 48 frames) left ever less of the glass
# on screen (109,000 glass pixels at 47 cm against 213,000), so a long run's
# frames got cheaper than the recorded one and outran the prediction.
write_job() {
  local file="$1" frames="$2" width="$3" height="$4" detail="$5" eyes="" i
  for ((i = 1; i < frames; i++)); do
    eyes+="[$(awk -v i="$i" 'BEGIN { k = i % 12; s = k <= 3 ? k : (k <= 9 ? 6 - k : k - 12); printf "%.3f", -0.55 + 0.01 * s }'), 1.4, 0.1],"
  done
  cat > "$file" <<TOML
[scene]
builtin = "cockpit"
detail = $detail
[camera]
width = $width
height = $height
[quality]
level = "full"
[frames]
eyes = [${eyes%,}]
TOML
}

# Frames are counted in the order they arrived at the submitter (a farm
# of whole frames finishes them out of order): "arrival k" is the k-th to
# arrive, from 0.

# steady_frame STATS_JSON: prints the first arrival of the steady state: the
# first frame to arrive whose work started (its arrival less its wall time
# on the master) after the first arrival. The first frame includes the
# scene transfer and the BVH builds; frames pipelined meanwhile arrive in a
# bunch right after it, and counted from the first they made the interval
# up to half the real one. 1 if no frame started that late.
steady_frame() {
  python3 - "$1" <<'PY'
import json, sys
frames = sorted(json.load(open(sys.argv[1])), key=lambda f: f["arrival_micros"])
first = frames[0]["arrival_micros"]
late = [i for i, f in enumerate(frames) if i > 0 and f["arrival_micros"] - f["wall_micros"] >= first]
print(late[0] if late and late[0] < len(frames) - 1 else min(1, len(frames) - 1))
PY
}

# Where scripts/steady_window.py is, for the Python below and in lab.sh.
farm_scripts=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

# window_start STATS_JSON K: prints the arrival the steady window starts
# at: the last of the bunch that holds arrival K (steady_window.bunch_end).
window_start() {
  python3 - "$1" "$2" "$farm_scripts" <<'PY'
import json, sys
sys.path.insert(0, sys.argv[3])
from steady_window import bunch_end
frames = json.load(open(sys.argv[1]))
print(bunch_end(sorted(f["arrival_micros"] for f in frames), int(sys.argv[2])))
PY
}

# frame_figures STATS_JSON FROM: prints the mean interval between frame
# arrivals at the submitter from arrival FROM on (see steady_frame), the
# mean master frame wall time of those frames, the result MB per frame as
# sent, and the same pixels' MB at the previous 40 bytes each.
frame_figures() {
  python3 - "$1" "$2" <<'PY'
import json, sys
frames = sorted(json.load(open(sys.argv[1])), key=lambda f: f["arrival_micros"])
start = int(sys.argv[2])
arrivals = [f["arrival_micros"] for f in frames[start:]]
gaps = [b - a for a, b in zip(arrivals, arrivals[1:])] or [arrivals[0]]
walls = [f["wall_micros"] for f in frames[max(start, 1):]] or [frames[0]["wall_micros"]]
results = sum(w["bytes_out"] for f in frames for w in f["workers"]) / len(frames)
pixels = sum(f["totals"]["pixels"] for f in frames) / len(frames)
print(f"{sum(gaps) / len(gaps) / 1e6:.4f} {sum(walls) / len(walls) / 1e6:.4f} {results / 1e6:.3f} {pixels * 40 / 1e6:.3f}")
PY
}

# Sets `ticks` to the CPU time (user + system, clock ticks) each of the
# processes "$@" has spent so far (no subshell: its own CPU would count).
ticks=()
cpu_ticks() {
  local p line fields
  ticks=()
  for p in "$@"; do
    read -r line <"/proc/$p/stat"
    read -ra fields <<<"${line##*) }"
    ticks+=($((fields[11] + fields[12])))
  done
}
# Sets `children_ticks` to the CPU time of this shell's reaped children.
children_ticks=0
reaped_cpu_ticks() {
  local line user system
  times >"$work/times"
  { read -r line; read -r user system; } <"$work/times"
  children_ticks=$(awk -v u="$user" -v s="$system" -v hz="$(getconf CLK_TCK)" 'BEGIN {
    split(u, a, /[ms]/); split(s, b, /[ms]/); printf "%d", (a[1] * 60 + a[2] + b[1] * 60 + b[2]) * hz + 0.5 }')
}
# Sets `machine_ticks` to the CPU time every process on this machine has
# spent so far (clock ticks, all cores), and `machine_at` to the time.
machine_ticks=0; machine_at=0
exec {sleeper}<> <(:)  # `read -t` on it sleeps without starting a process
machine_cpu_ticks() {
  local cpu user nice system idle iowait irq softirq steal rest
  read -r cpu user nice system idle iowait irq softirq steal rest </proc/stat
  machine_ticks=$((user + nice + system + irq + softirq + steal))
  machine_at=$EPOCHREALTIME
}

# measured_submit OUT LOG FRAMES PID... -- COMMAND...: runs COMMAND (a
# `vtfarm submit` writing to OUT, exec'd so that its process is the
# submitter's; output to LOG), bounded to 600 s, and sets `job_from` to the
# first steady frame (steady_frame; `measure_from` when set; moved to the end
# of its bunch by window_start), `job_cpu` to the CPU seconds per frame
# after it of the farm's processes (the first PID, the submitter, then the
# other PIDs; comma-separated) and `job_others` to the cores the machine's
# other processes used meanwhile (/proc/stat less the farm's). CPU is
# sampled at each arrival (a new frame_NNNN.png in OUT, whichever frame)
# and at the end. Needs `work` (a scratch directory).
measured_submit() {
  local out="$1" log="$2" frames="$3" pids=() submitter reaped_before deadline next=0 arrived=()
  shift 3
  while [ "$1" != -- ]; do pids+=("$1"); shift; done
  shift
  local samples="$work/cpu-samples"
  : >"$samples"
  reaped_cpu_ticks; reaped_before=$children_ticks
  "$@" >"$log" 2>&1 &
  submitter=$!
  submit_pid=$submitter  # for a caller's clean-up on an interrupt
  deadline=$((SECONDS + 600))
  while kill -0 "$submitter" 2>/dev/null && [ ! -e "$out/stats.json" ]; do
    shopt -s nullglob
    arrived=("$out"/frame_[0-9][0-9][0-9][0-9].png)
    shopt -u nullglob
    if [ "${#arrived[@]}" -gt "$next" ]; then
      cpu_ticks "${pids[@]}" "$submitter"; machine_cpu_ticks
      echo "${ticks[*]} $machine_ticks $machine_at" >>"$samples"
      next=$((next + 1))
      continue
    fi
    [ "$SECONDS" -lt "$deadline" ] || { kill "$submitter"; echo "submit timed out" >&2; exit 1; }
    read -rt 0.02 -u "$sleeper" || true
  done
  cpu_ticks "${pids[@]}"; machine_cpu_ticks
  local last=("${ticks[@]}") machine_last=("$machine_ticks" "$machine_at")
  wait "$submitter" || { cat "$log" >&2; exit 1; }
  reaped_cpu_ticks
  last+=($((children_ticks - reaped_before)))
  job_from=$(window_start "$out/stats.json" "${measure_from:-$(steady_frame "$out/stats.json")}")
  read -r job_cpu job_others < <(python3 - "$frames" "$(getconf CLK_TCK)" "$job_from" "$samples" \
    "${last[*]} ${machine_last[*]}" <<'PY'
import sys
frames, hz, start = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
samples = [line.split() for line in open(sys.argv[4])]
end = sys.argv[5].split()
if start < len(samples):
    first = samples[start]
    farm = [b - a for a, b in zip(map(int, first[:-2]), map(int, end[:-2]))]
    per = [x / hz / max(frames - 1 - start, 1) for x in farm]
    wall = float(end[-1]) - float(first[-1])
    others = max(0.0, (int(end[-2]) - int(first[-2]) - sum(farm)) / hz / wall)
else:  # that frame's arrival was not seen
    per, others = [float("nan")] * (len(end) - 2), float("nan")
print(",".join(f"{x:.4f}" for x in [per[0], per[-1], *per[1:-1]]), f"{others:.3f}")
PY
)
}

# --- Arguments and CPU quotas (scripts/lab.sh, scripts/hosts.sh) ---

# die CODE MESSAGE: the message on stderr, named by the script, and exit
# CODE (2: bad arguments, 1: the machine cannot do what was asked).
die() {
  echo "$(basename "$0"): $2" >&2
  exit "$1"
}

# is_positive VALUE: a decimal number above 0 (no sign, no exponent).
is_positive() {
  [[ $1 =~ ^[0-9]+([.][0-9]+)?$ ]] && awk -v v="$1" 'BEGIN { exit !(v > 0) }'
}

# per_worker_list NAME OPTION VALUES COUNT: sets the array NAME to COUNT
# positive numbers from VALUES, comma-separated: one for every worker or
# one each (`--cpu-percent 45,15`, `--mbit 100,10`). Exits 2 naming OPTION
# otherwise.
per_worker_list() {
  local -n _per_worker=$1
  local option=$2 values=$3 count=$4 v i
  IFS=, read -ra _per_worker <<<"$values"
  [ "${#_per_worker[@]}" -gt 0 ] || die 2 "$option needs a value"
  for v in "${_per_worker[@]}"; do
    is_positive "$v" || die 2 "$option $values: '$v' is not a positive number"
  done
  if [ "${#_per_worker[@]}" = 1 ]; then
    v=${_per_worker[0]}
    _per_worker=()
    for ((i = 0; i < count; i++)); do _per_worker+=("$v"); done
  elif [ "${#_per_worker[@]}" != "$count" ]; then
    die 2 "$option $values gives ${#_per_worker[@]} values for $count workers (--workers): give one value for every worker, or one each"
  fi
}

# The hierarchy CPU quotas are made in: cgroup v2's unified one, or the
# directory that holds v1's `cpu` hierarchy (the same path on most machines).
cgroup_root=${VTFARM_CGROUP_ROOT:-/sys/fs/cgroup}
# The quota's period: 10 ms, so a 45% worker runs 4.5 ms in every 10 ms
# (smoother shares than the kernel's default 100 ms: no 55 ms stalls).
cpu_period_us=10000
# The cgroups quota_create made, for quota_remove_all.
quota_groups=()

# cpu_quota_us PERCENT: the quota per period for PERCENT of one core; fails
# outside 10..100 % (the kernel takes no quota under 1 ms, and one process
# of one thread cannot use more than a core).
cpu_quota_us() {
  is_positive "$1" || return 1
  awk -v p="$1" -v period="$cpu_period_us" 'BEGIN {
    q = int(p * period / 100 + 0.5); if (q < 1000 || p > 100) exit 1; print q }'
}

# cgroup_version: v2 where $cgroup_root is a unified hierarchy offering the
# cpu controller, v1 where it holds v1's cpu hierarchy; fails otherwise (a
# hybrid machine's v2 part at unified/ usually offers no cpu controller: v1).
cgroup_version() {
  if [ -f "$cgroup_root/cgroup.controllers" ] && grep -qw cpu "$cgroup_root/cgroup.controllers"; then
    echo v2
  elif [ -f "$cgroup_root/cpu/cpu.cfs_quota_us" ]; then
    echo v1
  else
    return 1
  fi
}

# write_cgroup FILE VALUE: writes VALUE to a cgroup's FILE; exits 1 naming it
# when the kernel (or the file system) refuses.
write_cgroup() {
  { printf '%s\n' "$2" >"$1"; } 2>/dev/null ||
    die 1 "cannot write '$2' to $1: CPU quotas need root and a writable cgroup hierarchy; refusing to run without them"
}

# quota_create NAME PERCENT: a cgroup NAME whose processes together get at
# most PERCENT of one core (cgroup v2: cpu.max; v1: cpu.cfs_quota_us over
# cpu.cfs_period_us), both over $cpu_period_us. Sets `quota_dir` to it and
# `quota_version`, and remembers it for quota_remove_all. Exits 2 for a bad
# percent and 1, saying why, where no quota can be made: never a run
# without one.
quota_create() {
  local name=$1 percent=$2 quota
  quota=$(cpu_quota_us "$percent") ||
    die 2 "--cpu-percent $percent: give a share of one core from 10 to 100 (the quota is at least 1 ms of each $((cpu_period_us / 1000)) ms period)"
  quota_version=$(cgroup_version) ||
    die 1 "no CPU quotas here: $cgroup_root has neither cgroup v2's cpu controller (cgroup.controllers) nor cgroup v1's cpu hierarchy (cpu/cpu.cfs_quota_us); refusing to run without quotas"
  case $quota_version in
    v2) quota_dir=$cgroup_root/$name;;
    v1) quota_dir=$cgroup_root/cpu/$name;;
  esac
  mkdir "$quota_dir" 2>/dev/null ||
    die 1 "cannot create the cgroup $quota_dir: CPU quotas need root and a writable cgroup hierarchy; refusing to run without them"
  quota_groups+=("$quota_dir")
  case $quota_version in
    v2)
      # Children get the cpu controller only where their parent hands it on.
      grep -qw cpu "$cgroup_root/cgroup.subtree_control" 2>/dev/null ||
        write_cgroup "$cgroup_root/cgroup.subtree_control" +cpu
      write_cgroup "$quota_dir/cpu.max" "$quota $cpu_period_us";;
    v1)
      # The period first: a quota is checked against the period in force.
      write_cgroup "$quota_dir/cpu.cfs_period_us" "$cpu_period_us"
      write_cgroup "$quota_dir/cpu.cfs_quota_us" "$quota";;
  esac
}

# in_cgroup DIR: sets the array `in_cgroup_cmd` to a command prefix that
# moves the process into the cgroup DIR (its PID into cgroup.procs, which
# v1 and v2 both have) and then execs the rest, so the process is held from
# its first instruction and keeps its PID.
in_cgroup() {
  # shellcheck disable=SC2016 # $$ and $@ belong to the inner shell
  in_cgroup_cmd=(sh -c 'echo $$ >"$0" && exec "$@"' "$1/cgroup.procs")
}

# quota_throttled DIR: prints how many of the quota's periods throttled the
# group, and how many periods it ran in ("THROTTLED PERIODS", from its
# cpu.stat, alike in v1 and v2): proof the quota held.
quota_throttled() {
  awk '$1 == "nr_periods" { p = $2 } $1 == "nr_throttled" { t = $2 } END { print t + 0, p + 0 }' "$1/cpu.stat"
}

# quota_remove_all: removes the cgroups quota_create made (their processes
# must have ended), newest first; says which stay.
quota_remove_all() {
  local i
  for ((i = ${#quota_groups[@]} - 1; i >= 0; i--)); do
    rmdir "${quota_groups[i]}" 2>/dev/null || echo "$(basename "$0"): the cgroup ${quota_groups[i]} stays (rmdir failed)" >&2
  done
  quota_groups=()
}

# alive PID: the process exists and has not ended (a zombie has).
alive() {
  local line
  { read -r line <"/proc/$1/stat"; } 2>/dev/null || return 1
  line=${line##*) }
  [ "${line%% *}" != Z ]
}

# stop_pids PID...: asks the processes to end (TERM), gives them 5 s, then
# kills what is left, and reaps them: bounded, whatever they do.
stop_pids() {
  local p deadline=$((SECONDS + 5))
  [ $# -gt 0 ] || return 0
  kill "$@" 2>/dev/null || true
  for p in "$@"; do
    while alive "$p" && [ "$SECONDS" -lt "$deadline" ]; do read -rt 0.05 -u "$sleeper" || true; done
  done
  kill -KILL "$@" 2>/dev/null || true
  for p in "$@"; do wait "$p" 2>/dev/null || true; done
}

# cpu_list LIST: a kernel CPU list ("0-2,5") as cores, comma-separated
# ("0,1,2,5").
cpu_list() {
  local part parts=() expanded=() i
  IFS=, read -ra parts <<<"$1"
  for part in "${parts[@]}"; do
    if [[ $part == *-* ]]; then
      for ((i = ${part%-*}; i <= ${part#*-}; i++)); do expanded+=("$i"); done
    else
      expanded+=("$part")
    fi
  done
  (IFS=,; echo "${expanded[*]}")
}

# allowed_cpus: this process's allowed cores, comma-separated (from
# Cpus_allowed_list in /proc/self/status).
allowed_cpus() {
  cpu_list "$(awk '/^Cpus_allowed_list:/ { print $2 }' /proc/self/status)"
}
