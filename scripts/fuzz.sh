#!/usr/bin/env bash
# Smoke fuzzing: builds the libFuzzer targets with clang (AddressSanitizer and UndefinedBehaviorSanitizer on) into
# build-fuzz/ and runs each for SECONDS (default 60) from the seeds (the project's scenes; tests/fuzz/corpus/mesh). New inputs go to out/fuzz/,
# never into the repository; a finding (crash, sanitizer report, exception other than InputError, timeout) is
# saved there as crash-*/timeout-* and the script exits non-zero: add it to tests/fuzz/regressions/<target>/ with
# the fix. Usage: scripts/fuzz.sh [SECONDS] [scene|mesh]...
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
seconds="${1:-60}"
shift || true
targets=("$@")
((${#targets[@]})) || targets=(scene mesh)

GANACHE_BUILD_DIR=build-fuzz
GANACHE_EXTRA_PACKAGES="clang libclang-rt-14-dev"
GANACHE_CMAKE_ARGS="-DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo -DGANACHE_FUZZ=ON
  -DGANACHE_BUILD_TESTS=OFF -DGANACHE_BUILD_BENCHMARKS=OFF"
GANACHE_BUILD_TARGETS="${targets[*]/%/_fuzzer}"
source scripts/setup.sh

# Leaks inside system libraries (see the file) are theirs; everything else is a finding.
export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# Seeds: the project's own scenes (the library, the study's, the tests' and the broken ones), the mesh corpus.
declare -A seeds=([scene]="scenes tests/scenes" [mesh]="tests/fuzz/corpus/mesh")
status=0
for t in "${targets[@]}"; do
  mkdir -p "out/fuzz/$t"
  echo "fuzz: $t for ${seconds} s" >&2
  # -timeout: an input that takes longer than 10 s is a hang; -rss_limit_mb: one that needs 4 GiB is a finding too.
  ./build-fuzz/tests/fuzz/${t}_fuzzer -max_total_time="$seconds" -timeout=10 -rss_limit_mb=4096 -max_len=16384 \
    -print_final_stats=1 -artifact_prefix="out/fuzz/$t/" "out/fuzz/$t" ${seeds[$t]} || status=1
done
exit $status
