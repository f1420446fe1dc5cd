#!/usr/bin/env bash
# Installs the Debian packages ganache needs (only those missing), fetches the meshes of assets/ (scripts/assets.sh)
# and builds ganache into build/ (Release).
# Sourced by scripts/run.sh and scripts/test.sh; safe to run again: installed packages and the build are reused.
# scripts/sanitize.sh and scripts/fuzz.sh build elsewhere: they set GANACHE_BUILD_DIR, GANACHE_CMAKE_ARGS (extra
# configure arguments), GANACHE_EXTRA_PACKAGES and GANACHE_BUILD_TARGETS (default: all) before sourcing it.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

packages=(
  cmake g++ make pkg-config ccache
  libeigen3-dev libtbb-dev libopenvdb-dev libboost-dev libboost-iostreams-dev libassimp-dev libosmesa6-dev libyaml-cpp-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev libfmt-dev nlohmann-json3-dev libpng-dev
  ${GANACHE_EXTRA_PACKAGES:-}
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}\n' "$p" 2>/dev/null | grep -q '^install ok installed$' || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}" >&2
  if [ "$(id -u)" -ne 0 ]; then
    echo "setup: installing packages needs root; run as root or install: ${missing[*]}" >&2
    exit 1
  fi
  apt-get update -q
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

./scripts/assets.sh
build_dir="${GANACHE_BUILD_DIR:-build}"
# shellcheck disable=SC2086  # the extra arguments are meant to split
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release ${GANACHE_CMAKE_ARGS:-}
# shellcheck disable=SC2086
cmake --build "$build_dir" --parallel "$(nproc)" ${GANACHE_BUILD_TARGETS:+--target $GANACHE_BUILD_TARGETS}
