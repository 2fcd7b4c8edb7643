#!/usr/bin/env bash
# Builds the vtfarm image, runs docker-compose.yml (a master and two workers), submits the default
# job (configs/cockpit.toml) from a container and from this host (through the master's port
# published on 127.0.0.1), and checks both frames equal `vtfarm render`'s byte for byte; then
# removes the containers, volumes and images it made.
#
# Offline route (no registry needed): the image comes from contrib/docker/Dockerfile.prebuilt with
# the host's binary, on BASE (default debian:bookworm-slim if present, else a bookworm image made
# with debootstrap from this machine's apt mirror and `docker import`). Needs a running Docker
# daemon, or root to start one (installing Debian's docker.io and docker-compose if absent).
# Where containers cannot run, it says why and exits 0.
#
#   contrib/docker/test-local.sh     # VTFARM=path/to/vtfarm, BASE=image to override
set -euo pipefail

repo=$(cd "$(dirname "$0")/../.." && pwd)
project=vtfarmtest
image="vtfarm-test:prebuilt"
host_port=27903

# shellcheck source=contrib/test-lib.sh
source "$repo/contrib/test-lib.sh"

work=$(mktemp -d /tmp/vtfarm-docker.XXXXXX)
compose=(env "VTFARM_IMAGE=$image" "VTFARM_HOST_PORT=$host_port"
    docker-compose -p "$project" -f "$repo/docker-compose.yml" --ansi never)
dockerd_pid=
made_base=
cleanup() {
    local rc=$?
    if [[ $rc -ne 0 ]] && docker info >/dev/null 2>&1; then
        "${compose[@]}" logs --no-color --tail=20 2>/dev/null || true
    fi
    if docker info >/dev/null 2>&1; then
        docker rm -f "$project-submit" >/dev/null 2>&1 || true
        "${compose[@]}" down -v --remove-orphans >/dev/null 2>&1 || true
        docker rmi "$image" >/dev/null 2>&1 || true
        [[ -z $made_base ]] || docker rmi "$made_base" >/dev/null 2>&1 || true
    fi
    if [[ -n $dockerd_pid ]]; then
        kill "$dockerd_pid" 2>/dev/null || true
        wait "$dockerd_pid" 2>/dev/null || true
    fi
    rm -rf "$work"
    exit "$rc"
}
trap cleanup EXIT

if ! docker info >/dev/null 2>&1; then
    [[ $(id -u) -eq 0 ]] || skip "no Docker daemon reachable, and starting one needs root"
    if ! command -v dockerd >/dev/null || ! command -v docker-compose >/dev/null; then
        echo "== installing docker.io and docker-compose"
        apt-get update -q
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q docker.io docker-compose
    fi
    echo "== starting dockerd (log: $work/dockerd.log)"
    dockerd >"$work/dockerd.log" 2>&1 &
    dockerd_pid=$!
    if ! wait_for 60 "Docker daemon" docker info; then
        tail -n 20 "$work/dockerd.log"
        skip "dockerd does not start on this machine (log above)"
    fi
fi
command -v docker-compose >/dev/null || skip "no docker-compose (Debian: apt-get install docker-compose)"
docker info --format 'docker {{.ServerVersion}}, storage {{.Driver}}, cgroup v{{.CgroupVersion}}'
docker-compose version --short

base=${BASE:-debian:bookworm-slim}
if ! docker image inspect "$base" >/dev/null 2>&1 && [[ -z ${BASE:-} ]]; then
    # No registry: a minimal bookworm from this machine's apt mirror.
    mirror=$(grep -hE '^(URIs:|deb) ' /etc/apt/sources.list /etc/apt/sources.list.d/* 2>/dev/null \
        | grep -oE 'https?://[^ ]*/debian/?( |$)' | grep -v security | head -n 1 | tr -d ' ' || true)
    [[ -n $mirror ]] || skip "no debian:bookworm-slim image, and no Debian apt mirror for debootstrap"
    command -v debootstrap >/dev/null || {
        [[ $(id -u) -eq 0 ]] || skip "no debian:bookworm-slim image, and debootstrap needs root"
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap
    }
    base="vtfarm-test-base:bookworm"
    echo "== debootstrap --variant=minbase bookworm from $mirror"
    start=$(date +%s)
    debootstrap --variant=minbase bookworm "$work/rootfs" "$mirror" >"$work/debootstrap.log" 2>&1 || {
        tail -n 20 "$work/debootstrap.log"
        skip "debootstrap failed (log above)"
    }
    tar -C "$work/rootfs" -c . | docker import - "$base" >/dev/null
    made_base=$base
    rm -rf "$work/rootfs"
    echo "base image $base in $(($(date +%s) - start)) s"
fi

find_vtfarm
echo "== docker build -f contrib/docker/Dockerfile.prebuilt (BASE=$base)"
mkdir "$work/context"
cp "$vtfarm" "$work/context/vtfarm"
start=$(date +%s)
docker build -q -f "$repo/contrib/docker/Dockerfile.prebuilt" --build-arg "BASE=$base" \
    -t "$image" "$work/context"
echo "image $image built in $(($(date +%s) - start)) s"
rm -rf "$work/context"

echo "== vtfarm render (the reference)"
"$vtfarm" render "$repo/configs/cockpit.toml" -o "$work/render.png" | tail -n 1

echo "== docker-compose: init, a master and two workers"
"${compose[@]}" run --rm init
"${compose[@]}" up -d --no-build --scale worker=2 master worker
"${compose[@]}" ps

echo "== 1: submit from a container"
start=$(date +%s%N)
timeout 600 "${compose[@]}" run --name "$project-submit" submit
echo "submit took $((($(date +%s%N) - start) / 1000000)) ms"
docker cp "$project-submit:/out/frame_0000.png" "$work/compose.png"
cmp "$work/compose.png" "$work/render.png"
echo "PASS 1: the containers' frame equals vtfarm render's byte for byte"

echo "== 2: submit from this host through 127.0.0.1:$host_port/udp"
docker cp "$("${compose[@]}" ps -q master):/state/cluster.toml" "$work/cluster.toml"
timeout 600 "$vtfarm" submit "$repo/configs/cockpit.toml" --cluster "$work/cluster.toml" \
    --master "127.0.0.1:$host_port" -o "$work/host-out" | tail -n 5
cmp "$work/host-out/frame_0000.png" "$work/render.png"
echo "PASS 2: the host's submission through the published port matches too"
