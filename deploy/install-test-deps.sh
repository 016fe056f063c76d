#!/usr/bin/env sh
# Installs what the test suite needs on a Debian/Ubuntu machine, beyond rendering (which
# `install-vulkan.sh`, run first, provides): Debian's `chromium` for the dashboard test.
# Idempotent: installs only what is missing. Used by the README's test command and CI.
set -eu
cd "$(dirname "$0")"
./install-vulkan.sh

need=""
command -v "${PENUMBRA_CHROMIUM:-chromium}" >/dev/null 2>&1 || need="$need chromium"

if [ -z "$need" ]; then
    exit 0
fi
if [ "$(id -u)" -eq 0 ]; then
    sudo=""
else
    sudo="sudo"
fi
echo "install-test-deps: installing$need" >&2
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $need >/dev/null
