#!/usr/bin/env bash
# The whole test suite under AddressSanitizer (with LeakSanitizer) and UndefinedBehaviorSanitizer, built with g++
# into build-asan/. Any report fails the test it happens in; exits non-zero on any failure.
# About 30 minutes to build and 33 minutes to test on 2 cores (the programs run about 10x slower than in Release).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
GANACHE_BUILD_DIR=build-asan
GANACHE_CMAKE_ARGS="-DCMAKE_BUILD_TYPE=RelWithDebInfo -DGANACHE_BUILD_BENCHMARKS=OFF -DGANACHE_SANITIZE=ON"
source scripts/setup.sh
export ASAN_OPTIONS="detect_leaks=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# Leaks inside the system's OpenGL driver (Mesa's llvmpipe) are not ganache's; everything else must be clean.
export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
ctest --test-dir build-asan --output-on-failure --parallel "$(nproc)" --timeout 1800 "$@"
