# Shared by scripts/scaling.sh and scripts/lab.sh (sourced, not run).

# write_job FILE FRAMES WIDTH HEIGHT DETAIL: the cockpit job, `full`, frame 0
# from the driver's eye and the others from eyes 1 cm apart.
write_job() {
  local file="$1" frames="$2" width="$3" height="$4" detail="$5" eyes="" i
  for ((i = 1; i < frames; i++)); do
    eyes+="[$(awk -v i="$i" 'BEGIN { printf "%.3f", -0.55 + 0.01 * i }'), 1.4, 0.1],"
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

# steady_frame STATS_JSON: prints the first frame of the steady state: the
# first whose work started (its arrival less its wall time on the master)
# after frame 0 had arrived. Frame 0 includes the scene transfer and the
# BVH builds; frames pipelined meanwhile arrive in a bunch right after it,
# and counted from frame 0 they made the interval up to half the real one.
# 1 if no frame started that late.
steady_frame() {
  python3 - "$1" <<'PY'
import json, sys
frames = json.load(open(sys.argv[1]))
first = frames[0]["arrival_micros"]
late = [i for i, f in enumerate(frames) if i > 0 and f["arrival_micros"] - f["wall_micros"] >= first]
print(late[0] if late and late[0] < len(frames) - 1 else min(1, len(frames) - 1))
PY
}

# frame_figures STATS_JSON FROM: prints the mean interval between frame
# arrivals at the submitter from frame FROM on (see steady_frame), the mean
# master frame wall time of those frames, the result MB per frame as sent,
# and the same pixels' MB at the previous 40 bytes each.
frame_figures() {
  python3 - "$1" "$2" <<'PY'
import json, sys
frames, start = json.load(open(sys.argv[1])), int(sys.argv[2])
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
# first steady frame (steady_frame), `job_cpu` to the CPU seconds per frame
# after it of the farm's processes (the first PID, the submitter, then the
# other PIDs; comma-separated) and `job_others` to the cores the machine's
# other processes used meanwhile (/proc/stat less the farm's). CPU is
# sampled as each frame arrives and at the end. Needs `work` (a scratch
# directory).
measured_submit() {
  local out="$1" log="$2" frames="$3" pids=() submitter reaped_before deadline next=0 png
  shift 3
  while [ "$1" != -- ]; do pids+=("$1"); shift; done
  shift
  local samples="$work/cpu-samples"
  : >"$samples"
  reaped_cpu_ticks; reaped_before=$children_ticks
  "$@" >"$log" 2>&1 &
  submitter=$!
  deadline=$((SECONDS + 600))
  while kill -0 "$submitter" 2>/dev/null && [ ! -e "$out/stats.json" ]; do
    printf -v png '%s/frame_%04d.png' "$out" "$next"
    if [ -e "$png" ]; then
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
  job_from=$(steady_frame "$out/stats.json")
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
