#!/usr/bin/env sh
# Builds the real-model suite (`penumbra eval --scenes DIR`) in DIR (default
# $PENUMBRA_TOOLS/real-models, PENUMBRA_TOOLS defaulting to ~/.cache/penumbra-tools): the
# models deploy/real-models.list names, converted to GLB by Debian's assimp-utils, and links to
# the glTF 2.0 files of assimp-testmodels' glTF2 folder that Khronos' gltf-validator passes
# (no errors, no required extension, some triangles). Prints DIR. Cached: a model already
# converted is not converted again; a list that changed rebuilds the folder.
# Needs: assimp-testmodels, assimp-utils, node with gltf-validator (install-test-deps.sh).
set -eu
here="$(cd "$(dirname "$0")" && pwd)"
tools="${PENUMBRA_TOOLS:-$HOME/.cache/penumbra-tools}"
out="${1:-$tools/real-models}"
models="${PENUMBRA_ASSIMP_MODELS:-/usr/share/assimp/models}"
list="$here/real-models.list"

stamp="$(cat "$list" "$here/real-models.sh" | sha256sum | cut -c1-16)"
if [ -f "$out/.stamp" ] && [ "$(cat "$out/.stamp")" = "$stamp" ]; then
    echo "$out"
    exit 0
fi
rm -rf "$out"
mkdir -p "$out"

# Others' formats, through a real converter. A model assimp cannot read is a failure of this
# script (the list names only models it converts), not a silent gap in the suite.
grep -v '^#' "$list" | grep -v '^$' | while read -r source; do
    name="$(echo "$source" | sed 's|/|-|g; s|\.[^.]*$||').glb"
    if ! assimp export "$models/$source" "$out/$name" -fglb2 >/dev/null 2>&1; then
        echo "real-models: assimp cannot convert $source" >&2
        exit 1
    fi
done

# The glTF2 folder's valid files, as they are (links: a .gltf reads its files beside it).
validator="$tools/node/node_modules/gltf-validator"
find "$models/glTF2" -type f \( -name '*.gltf' -o -name '*.glb' \) | sort > "$out/.gltf2-files"
# shellcheck disable=SC2046 # one argument per file; the corpus' names have no spaces
GLTF_VALIDATOR="$validator" node "$here/../tests/gltf/validate.js" $(cat "$out/.gltf2-files") |
    python3 -c '
import json, sys
for line in sys.stdin:
    v = json.loads(line)
    if v["errors"] == 0 and not v["required"] and v["triangles"] > 0:
        print(v["file"])' |
    while read -r file; do
        relative="${file#"$models/glTF2/"}"
        ln -s "$file" "$out/glTF2-$(echo "$relative" | sed 's|/|-|g')"
    done
rm "$out/.gltf2-files"
echo "$stamp" > "$out/.stamp"
echo "$out"
