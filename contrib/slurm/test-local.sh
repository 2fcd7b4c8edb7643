#!/usr/bin/env bash
# Runs contrib/slurm/vtfarm.sbatch on a one-node Slurm cluster on localhost and checks that the
# farm's image equals `vtfarm render`'s byte for byte:
#   1. the sbatch file on configs/cockpit.toml with two workers (two tasks of two CPUs);
#   2. the --array variant: a master-only job fed by a two-task worker array (`--join`), which
#      must render the frame alone and stop by itself when the master's job ends.
# Needs root: installs Debian's slurm-wlm and munge if absent and starts munged, slurmctld and
# slurmd (their own config, key, sockets and state under a temporary directory; nothing in
# /etc is changed), all stopped and removed at the end. Without root it says so and exits 0.
#
#   contrib/slurm/test-local.sh          # VTFARM=path/to/vtfarm to use a given binary
set -euo pipefail

repo=$(cd "$(dirname "$0")/../.." && pwd)
# shellcheck source=contrib/test-lib.sh
source "$repo/contrib/test-lib.sh"
[[ $(id -u) -eq 0 ]] || skip "needs root (installs slurm-wlm and munge, starts slurmctld and slurmd)"
find_vtfarm

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    echo "== installing slurm-wlm and munge"
    apt-get update -q
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge
fi

work=$(mktemp -d /tmp/vtfarm-slurm.XXXXXX)
chmod 755 "$work"
# Every Slurm command here, scancel in cleanup included, talks to this test cluster only.
export SLURM_CONF=$work/slurm.conf
pids=()
cleanup() {
    local rc=$?
    if [[ -s $SLURM_CONF ]]; then timeout 20 scancel --full --quiet -u root 2>/dev/null || true; fi
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
    for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
    if [[ $rc -ne 0 ]]; then
        for log in "$work"/*.log; do echo "--- $log"; tail -n 20 "$log"; done
    fi
    rm -rf "$work"
    exit "$rc"
}
trap cleanup EXIT

echo "== munge and slurm under $work"
mkdir -m 700 "$work/munge"
dd if=/dev/urandom of="$work/munge/munge.key" bs=128 count=1 status=none
chmod 400 "$work/munge/munge.key"
munged --foreground --force --socket="$work/munge/socket" --key-file="$work/munge/munge.key" \
    --pid-file="$work/munge/munged.pid" --seed-file="$work/munge/seed" \
    --log-file="$work/munged.log" >/dev/null 2>&1 &
pids+=($!)
wait_for 10 "munge socket" test -S "$work/munge/socket"

cat >"$SLURM_CONF" <<CONF
ClusterName=vtfarmtest
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=26817
SlurmdPort=26818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$work/munge/socket
CredType=cred/munge
StateSaveLocation=$work/ctld
SlurmdSpoolDir=$work/slurmd
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerParameters=sched_interval=2
ReturnToService=2
MpiDefault=none
MailProg=/bin/true
# Four task slots on one node, whatever the machine has.
SlurmdParameters=config_overrides
NodeName=localhost NodeAddr=127.0.0.1 CPUs=4 State=UNKNOWN
PartitionName=local Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
mkdir -p "$work/ctld" "$work/slurmd"
# Both daemons log to their files above; -D keeps them children of this script.
slurmctld -D -i -f "$SLURM_CONF" >/dev/null 2>&1 &
pids+=($!)
slurmd -D -N localhost -f "$SLURM_CONF" >/dev/null 2>&1 &
pids+=($!)
# shellcheck disable=SC2016 # expanded by the inner shell, on every poll
wait_for 60 "idle Slurm node" bash -c '[[ $(sinfo -h -n localhost -o %t) == idle ]]'
sinfo

echo "== vtfarm render (the reference)"
"$vtfarm" render "$repo/configs/cockpit.toml" -o "$work/render.png" | tail -n 3

# Every job dials and binds 127.0.0.1 only.
export VTFARM=$vtfarm VTFARM_MASTER_HOST=127.0.0.1
cd "$work"

echo "== 1: sbatch vtfarm.sbatch, two workers of two threads"
start=$(date +%s%N)
VTFARM_PORT=27901 VTFARM_LISTEN=127.0.0.1:27901 timeout 600 \
    sbatch --wait --parsable --nodes=1 --ntasks=2 --ntasks-per-node=2 --cpus-per-task=2 \
    --time=10 --output="$work/job1.log" \
    "$repo/contrib/slurm/vtfarm.sbatch" "$repo/configs/cockpit.toml" "$work/out1"
end=$(date +%s%N)
cat "$work/job1.log"
echo "sbatch --wait took $(((end - start) / 1000000)) ms"
cmp "$work/out1/frame_0000.png" "$work/render.png"
echo "PASS 1: the Slurm farm's frame equals vtfarm render's byte for byte"
for task in 0 1; do
    grep -q "localhost-w-$task" "$work/out1/stats.json" || {
        echo "FAIL: worker localhost-w-$task is not in stats.json" >&2
        exit 1
    }
done

echo "== 2: a master-only job fed by an --array of workers"
start=$(date +%s%N)
master_job=$(VTFARM_MASTER_ONLY=1 VTFARM_PORT=27902 VTFARM_LISTEN=127.0.0.1:27902 \
    sbatch --parsable --nodes=1 --ntasks=1 --cpus-per-task=1 --time=10 \
    --output="$work/job2.log" \
    "$repo/contrib/slurm/vtfarm.sbatch" "$repo/configs/cockpit.toml" "$work/out2")
array_job=$(sbatch --parsable --array=0-1 --dependency="after:$master_job" --nodes=1 \
    --ntasks=1 --cpus-per-task=1 --time=10 --output="$work/array-%a.log" \
    "$repo/contrib/slurm/vtfarm.sbatch" --join "$master_job")
echo "master job $master_job, worker array $array_job"
wait_for 300 "end of jobs $master_job and $array_job" \
    bash -c "[[ -z \$(squeue -h -j $master_job,$array_job -o %i) ]]"
end=$(date +%s%N)
cat "$work/job2.log"
for log in "$work"/array-*.log; do echo "--- $log"; cat "$log"; done
echo "master job and worker array took $(((end - start) / 1000000)) ms"
scontrol show job "$master_job" | grep -q 'ExitCode=0:0' || {
    echo "FAIL: job $master_job did not exit 0" >&2
    exit 1
}
cmp "$work/out2/frame_0000.png" "$work/render.png"
grep -q 'localhost-a[01]-0' "$work/out2/stats.json" || {
    echo "FAIL: no array worker in stats.json" >&2
    exit 1
}
echo "PASS 2: the array workers rendered it, byte for byte, and stopped with the master's job"
