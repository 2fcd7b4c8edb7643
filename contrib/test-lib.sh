# shellcheck shell=bash
# Shared by contrib/*/test-local.sh (sourced, after `repo` is set): bounded waits, skipping, and
# the vtfarm binary to test.

# Says why the test cannot run here and exits 0.
skip() {
    echo "skipped: $*"
    exit 0
}

# Bounded wait: `wait_for SECONDS WHAT COMMAND...` polls COMMAND every half second.
wait_for() {
    local seconds=$1 what=$2
    shift 2
    for _ in $(seq $((seconds * 2))); do
        "$@" >/dev/null 2>&1 && return 0
        sleep 0.5
    done
    echo "FAIL: no $what after $seconds s" >&2
    return 1
}

# Sets `vtfarm` to $VTFARM, or to target/release/vtfarm, building it if absent.
find_vtfarm() {
    vtfarm=${VTFARM:-$repo/target/release/vtfarm}
    if [[ ! -x $vtfarm ]]; then
        echo "== building $vtfarm"
        cargo build --release --locked --bin vtfarm --manifest-path "$repo/Cargo.toml"
    fi
    vtfarm=$(realpath "$vtfarm")
}
