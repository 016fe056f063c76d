#!/usr/bin/env bash
# Builds the container image `penumbra:local` on a machine with no container registry (as
# root, or with sudo): installs Docker Engine from Debian (`docker.io`) when missing, starts
# `dockerd` when none is running (no bridge, no iptables: containers use the host network),
# makes the `debian:bookworm-slim` base image from Debian's packages with debootstrap when it
# is missing, builds penumbra on the host and packages that binary (`--target prebuilt`).
# On an ordinary machine `docker build -f deploy/Dockerfile -t penumbra:local .` is all it takes.
#
#   deploy/build-image.sh [TAG]          (default penumbra:local)
#   PENUMBRA_BINARY=path/to/penumbra deploy/build-image.sh   packages that binary instead of building one
set -euo pipefail
cd "$(dirname "$0")/.."
tag="${1:-penumbra:local}"
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"

need=""
command -v dockerd >/dev/null 2>&1 || need="$need docker.io"
command -v debootstrap >/dev/null 2>&1 || need="$need debootstrap"
if [ -n "$need" ]; then
    echo "build-image: installing$need" >&2
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $need >/dev/null
fi

if ! $sudo docker info >/dev/null 2>&1; then
    echo "build-image: starting dockerd (log: /var/log/penumbra-dockerd.log)" >&2
    $sudo sh -c 'nohup dockerd --bridge=none --iptables=false >/var/log/penumbra-dockerd.log 2>&1 &'
    for _ in $(seq 1 60); do
        $sudo docker info >/dev/null 2>&1 && break
        sleep 1
    done
    $sudo docker info >/dev/null 2>&1 || { echo "build-image: dockerd did not start; see /var/log/penumbra-dockerd.log" >&2; exit 1; }
fi

if ! $sudo docker image inspect debian:bookworm-slim >/dev/null 2>&1; then
    echo "build-image: making debian:bookworm-slim with debootstrap" >&2
    root="$(mktemp -d)"
    $sudo debootstrap --variant=minbase bookworm "$root" "${DEBIAN_MIRROR:-http://deb.debian.org/debian}" >/dev/null
    $sudo rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/*
    $sudo tar -C "$root" -c . | $sudo docker import - debian:bookworm-slim >/dev/null
    $sudo rm -rf "$root"
fi

binary="${PENUMBRA_BINARY:-}"
if [ -z "$binary" ]; then
    cargo build --release --locked --bin penumbra
    binary=target/release/penumbra
fi
mkdir -p deploy/.bin
cp "$binary" deploy/.bin/penumbra
# Line tables help a developer's backtraces, not a container: ~100 MB → ~40 MB.
if command -v strip >/dev/null 2>&1; then strip --strip-debug deploy/.bin/penumbra; fi
# The host's binary links glibc, libstdc++ (the FLIP metric) and loads the Vulkan loader at
# run time: all in bookworm-slim plus Mesa, so a binary built on bookworm runs in the image.
$sudo docker build --network host -f deploy/Dockerfile --target prebuilt -t "$tag" .
echo "build-image: built $tag" >&2
