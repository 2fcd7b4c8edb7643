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
