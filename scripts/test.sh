#!/usr/bin/env bash
# Set up, build, and run every test through CTest; exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
# The farm tests start a one-node Slurm cluster of their own (tests/farm/cluster.sh): munge and Slurm's daemons.
# The Blender add-on is tested in Debian's Blender (its Python needs numpy).
export GANACHE_EXTRA_PACKAGES="${GANACHE_EXTRA_PACKAGES:-} slurm-wlm blender python3-numpy"
source scripts/setup.sh
ctest --test-dir build --output-on-failure --parallel "$(nproc)"
