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

# frame_figures STATS_JSON: prints the mean interval between frame arrivals
# at the submitter (first frame left out: it includes the scene transfer and
# BVH builds), the mean master frame wall time, the result MB per frame as
# sent, and the same pixels' MB at the previous 40 bytes each.
frame_figures() {
  python3 - "$1" <<'PY'
import json, sys
frames = json.load(open(sys.argv[1]))
arrivals = [f["arrival_micros"] for f in frames]
gaps = [b - a for a, b in zip(arrivals, arrivals[1:])] or [arrivals[0]]
walls = [f["wall_micros"] for f in frames[1:]] or [frames[0]["wall_micros"]]
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
# submitter's; output to LOG), bounded to 600 s, and sets `job_cpu` to the
# CPU seconds per frame after the first of the farm's processes (the first
# PID, the submitter, then the other PIDs; comma-separated) and
# `job_others` to the cores the machine's other processes used meanwhile
# (/proc/stat less the farm's). CPU is sampled when the first frame
# arrives and at the end: the frames between are the ones the frame
# interval counts. Needs `work` (a scratch directory).
measured_submit() {
  local out="$1" log="$2" frames="$3" pids=() submitter reaped_before deadline
  shift 3
  while [ "$1" != -- ]; do pids+=("$1"); shift; done
  shift
  reaped_cpu_ticks; reaped_before=$children_ticks
  "$@" >"$log" 2>&1 &
  submitter=$!
  local at_first=() machine_first=() last machine_last
  deadline=$((SECONDS + 600))
  while kill -0 "$submitter" 2>/dev/null && [ ! -e "$out/stats.json" ]; do
    if [ ${#at_first[@]} -eq 0 ] && [ -e "$out/frame_0000.png" ]; then
      cpu_ticks "${pids[@]}" "$submitter"; at_first=("${ticks[@]}")
      machine_cpu_ticks; machine_first=("$machine_ticks" "$machine_at")
    fi
    [ "$SECONDS" -lt "$deadline" ] || { kill "$submitter"; echo "submit timed out" >&2; exit 1; }
    read -rt 0.02 -u "$sleeper" || true
  done
  cpu_ticks "${pids[@]}"; last=("${ticks[@]}")
  machine_cpu_ticks; machine_last=("$machine_ticks" "$machine_at")
  wait "$submitter" || { cat "$log" >&2; exit 1; }
  reaped_cpu_ticks
  last+=($((children_ticks - reaped_before)))
  read -r job_cpu job_others < <(python3 - "$frames" "$(getconf CLK_TCK)" "${at_first[*]}" "${last[*]}" \
    "${machine_first[*]:-}" "${machine_last[*]}" <<'PY'
import sys
frames, hz = int(sys.argv[1]), int(sys.argv[2])
first, last = [list(map(int, a.split())) for a in sys.argv[3:5]]
if len(first) != len(last):
    first = [float("nan")] * len(last)  # the first frame was not seen
per = [(b - a) / hz / max(frames - 1, 1) for a, b in zip(first, last)]
machine = [a.split() for a in sys.argv[5:7]]
others = float("nan")
if len(machine[0]) == 2:
    (t0, w0), (t1, w1) = [(int(t), float(w)) for t, w in machine]
    farm = sum(b - a for a, b in zip(first, last))
    others = max(0.0, (t1 - t0 - farm) / hz / (w1 - w0))
print(",".join(f"{x:.4f}" for x in [per[0], per[-1], *per[1:-1]]), f"{others:.3f}")
PY
)
}
