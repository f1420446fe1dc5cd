#!/usr/bin/env bash
# The main job: set up, build, and run the default scene end to end. Extra arguments go to `ganache run`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
./build/src/ganache run scenes/chocolate_bunny.yaml "$@"
