#!/usr/bin/env bash
# Puts the real meshes the scenes use into assets/cgal/: the Stanford bunny and an armadillo statue from Debian's
# libcgal-demo package (its data archive). Only the package file is fetched and unpacked; nothing is installed.
# Called by scripts/setup.sh; does nothing when the meshes are already there.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

dest=assets/cgal
meshes=(bunny00.off armadillo.off)
have=1
for m in "${meshes[@]}"; do [ -s "$dest/$m" ] || have=0; done
((have)) && exit 0

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "assets: fetching libcgal-demo for ${meshes[*]}" >&2
if ! (cd "$work" && apt-get download -q libcgal-demo >/dev/null 2>&1); then
  # A fresh machine may have no package lists yet.
  if [ "$(id -u)" -eq 0 ]; then apt-get update -q >/dev/null; fi
  (cd "$work" && apt-get download -q libcgal-demo) || {
    echo "assets: could not download libcgal-demo; scenes that use $dest/ will report the missing mesh" >&2
    exit 1
  }
fi
dpkg-deb -x "$work"/libcgal-demo_*.deb "$work/pkg"
data=$(find "$work/pkg" -name data.tar.gz | head -n 1)
tar -xzf "$data" -C "$work" "${meshes[@]/#/data/meshes/}"
mkdir -p "$dest"
for m in "${meshes[@]}"; do
  cp "$work/data/meshes/$m" "$dest/$m.tmp" && mv "$dest/$m.tmp" "$dest/$m"
done
echo "assets: ${meshes[*]} in $dest" >&2
