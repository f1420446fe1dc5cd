#!/usr/bin/env bash
# Set up, build, and run every test through CTest; exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
ctest --test-dir build --output-on-failure --parallel "$(nproc)"
