#!/usr/bin/env bash
# Soak test of the farm on localhost: one job of FRAMES frames on WORKERS
# worker processes, a random worker killed with -9 (and restarted) every
# KILL_EVERY seconds on average, and the master killed with -9 and restarted
# once, half way. Every frame must be byte-identical to `vtfarm render` of the
# same view; the master's and the workers' resident memory is reported every
# tenth of the frames (a killed worker starts afresh, so its figure restarts). Everything runs niced (the machine may be shared).
#
#   cargo build --release
#   scripts/soak.sh                      # 1000 frames of 96x54
#   FRAMES=200 WIDTH=160 HEIGHT=90 scripts/soak.sh
#
# Exit status 0 when every frame matched.
set -euo pipefail

FRAMES=${FRAMES:-1000}
WORKERS=${WORKERS:-3}
WIDTH=${WIDTH:-96}
HEIGHT=${HEIGHT:-54}
VIEWS=${VIEWS:-10}          # distinct eye points, cycled through the frames
KILL_EVERY=${KILL_EVERY:-8} # mean seconds between worker kills
PORT=${PORT:-47931}
VTFARM=${VTFARM:-$(pwd)/target/release/vtfarm}
WORK=${WORK:-$(mktemp -d /tmp/vtfarm-soak.XXXXXX)}

[[ -x $VTFARM ]] || { echo "no $VTFARM: run cargo build --release first" >&2; exit 2; }
mkdir -p "$WORK/ref" "$WORK/out" "$WORK/logs"
echo "soak: $FRAMES frames of ${WIDTH}x$HEIGHT, $WORKERS workers, work dir $WORK"

# `nice` execs vtfarm, so $! of `nice ... &` is vtfarm's own pid.
NICE="nice -n 10"
run() { $NICE "$VTFARM" "$@"; }
declare -A PIDS=()
cleanup() {
    for pid in "${PIDS[@]}"; do kill -9 "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
}
trap cleanup EXIT

eye() { # the eye point of view $1
    awk -v k="$1" -v n="$VIEWS" 'BEGIN { printf "[%.4f, 1.4, 0.1]", -0.55 + 0.01 * (k - n / 2) }'
}
job_file() { # $1: file, $2: first view, $3: number of extra frames
    {
        printf '[scene]\nbuiltin = "cockpit"\ndetail = 0.2\n'
        printf '[camera]\neye = %s\ntarget = [-0.55, 1.05, -0.6]\nwidth = %d\nheight = %d\n' \
            "$(eye "$2")" "$WIDTH" "$HEIGHT"
        printf '[quality]\nlevel = "full"\n[frames]\neyes = ['
        for ((f = 1; f <= $3; f++)); do
            ((f > 1)) && printf ', '
            eye $((($2 + f) % VIEWS))
        done
        printf ']\n'
    } >"$1"
}

echo "references: $VIEWS views with vtfarm render"
for ((v = 0; v < VIEWS; v++)); do
    job_file "$WORK/ref/view$v.toml" "$v" 0
    run render "$WORK/ref/view$v.toml" -o "$WORK/ref/view$v.png" >/dev/null 2>&1
done
job_file "$WORK/job.toml" 0 $((FRAMES - 1))

run cluster init -o "$WORK/cluster" --master "127.0.0.1:$PORT" >/dev/null
CLUSTER=$WORK/cluster/cluster.toml
start_master() {
    $NICE "$VTFARM" master --cluster "$CLUSTER" --listen "127.0.0.1:$PORT" \
        >>"$WORK/logs/master.log" 2>&1 &
    PIDS[master]=$!
}
start_worker() {
    $NICE "$VTFARM" worker --cluster "$CLUSTER" --name "w$1" --threads 1 \
        --cache "$WORK/cache$1" >>"$WORK/logs/w$1.log" 2>&1 &
    PIDS[w$1]=$!
}
rss() { ps -o rss= -p "$1" 2>/dev/null | tr -d ' ' || echo 0; }
report_rss() {
    local line="rss at $(frames_done) frames ($1): master $(rss "${PIDS[master]}") kB, workers"
    for ((w = 0; w < WORKERS; w++)); do line+=" $(rss "${PIDS[w$w]}")"; done
    echo "$line kB"
}
frames_done() { find "$WORK/out" -name 'frame_*.png' | wc -l; }

start_master
for ((try = 0; ; try++)); do # the master answers before anything else starts
    run status --cluster "$CLUSTER" >/dev/null 2>&1 && break
    ((try < 20)) || { echo "the master does not answer; see $WORK/logs/master.log" >&2; exit 1; }
    sleep 0.5
done
for ((w = 0; w < WORKERS; w++)); do start_worker "$w"; done
start=$(date +%s)
$NICE "$VTFARM" submit "$WORK/job.toml" --cluster "$CLUSTER" -o "$WORK/out" \
    >"$WORK/logs/submit.log" 2>&1 &
PIDS[submit]=$!

kills=0
restarted=no
next_report=$((FRAMES / 20))
next_kill=$((start + RANDOM % (2 * KILL_EVERY) + 1))
while kill -0 "${PIDS[submit]}" 2>/dev/null; do
    sleep 0.5
    done_now=$(frames_done)
    if ((done_now >= next_report)); then
        report_rss "every tenth"
        next_report=$((next_report + FRAMES / 10))
    fi
    if [[ $restarted == no && $done_now -ge $((FRAMES / 2)) ]]; then
        report_rss "before the master restart"
        kill -9 "${PIDS[master]}"
        wait "${PIDS[master]}" 2>/dev/null || true
        start_master
        restarted=yes
        echo "master killed and restarted at $done_now frames"
    fi
    if (($(date +%s) >= next_kill)); then
        w=$((RANDOM % WORKERS))
        kill -9 "${PIDS[w$w]}" 2>/dev/null || true
        wait "${PIDS[w$w]}" 2>/dev/null || true
        start_worker "$w"
        kills=$((kills + 1))
        next_kill=$(($(date +%s) + RANDOM % (2 * KILL_EVERY) + 1))
    fi
done
report_rss end
wait "${PIDS[submit]}" && submitted=0 || submitted=$?
unset 'PIDS[submit]'
elapsed=$(($(date +%s) - start))

mismatches=0
for ((f = 0; f < FRAMES; f++)); do
    frame=$(printf '%s/out/frame_%04d.png' "$WORK" "$f")
    if ! cmp -s "$frame" "$WORK/ref/view$((f % VIEWS)).png"; then
        mismatches=$((mismatches + 1))
        ((mismatches <= 5)) && echo "frame $f differs from vtfarm render (or is missing)"
    fi
done
echo "soak: $FRAMES frames in ${elapsed} s, $kills worker kills, master restarted: $restarted," \
    "submit exit $submitted, $mismatches frames differ"
[[ $submitted == 0 && $mismatches == 0 ]]
