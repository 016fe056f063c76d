#!/usr/bin/env sh
# Installs what penumbra needs to render on a machine without a GPU: Mesa's lavapipe
# (software Vulkan) and the Vulkan loader, plus a C++ compiler for the FLIP metric used by
# the tests. Idempotent: does nothing when everything is present. Shared by the README's
# quick start, CI (.ci/run) and the container image (deploy/Dockerfile).
set -eu

need=""
[ -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ] || [ -e /usr/share/vulkan/icd.d/lvp_icd.aarch64.json ] || need="$need mesa-vulkan-drivers"
ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1' || need="$need libvulkan1"
if [ "${PENUMBRA_RUNTIME_ONLY:-0}" != "1" ]; then
    command -v c++ >/dev/null 2>&1 || need="$need g++"
fi

if [ -z "$need" ]; then
    exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
    sudo=""
else
    sudo="sudo"
fi
echo "install-vulkan: installing$need" >&2
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $need >/dev/null
