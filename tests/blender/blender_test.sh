#!/usr/bin/env bash
# The Blender add-on (tools/blender/) against Debian's Blender, headless: ganache writes the tiny scene twice (binary
# PLY meshes with the particles exported as PLY; OBJ meshes) and blender_test.py imports and checks both.
#   blender_test.sh GANACHE          exit 77 (skipped) when Blender is not installed (scripts/test.sh installs it)
set -euo pipefail
ganache=$(realpath "${1:?usage: blender_test.sh GANACHE}")
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root="$here/../.."
command -v blender >/dev/null || { echo "blender is not installed (apt-get install blender)" >&2; exit 77; }
work=$(mktemp -d /tmp/ganache-blender-test.XXXXXX)
trap 'rm -rf "$work"' EXIT
sed -e 's/^particles: {\(.*\)}/particles: {\1, export: ply}/' -e 's/^surface: {\(.*\)}/surface: {\1, mesh_format: ply}/' \
  "$root/tests/scenes/tiny.yaml" >"$work/tiny.yaml"
grep -q 'export: ply' "$work/tiny.yaml" && grep -q 'mesh_format: ply' "$work/tiny.yaml"
"$ganache" run "$work/tiny.yaml" --out "$work/ply" 2>/dev/null
"$ganache" run "$root/tests/scenes/tiny.yaml" --out "$work/obj" 2>/dev/null
blender -b --factory-startup --python-exit-code 1 --python "$here/blender_test.py" -- "$root/tools/blender" \
  "$work/ply" "$work/obj" 2>&1 | grep -v '^Read prefs\|^Blender quit\|^$'
