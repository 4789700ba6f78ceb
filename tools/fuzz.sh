#!/usr/bin/env bash
# Builds the libFuzzer scene fuzzer (tests/fuzz/scene_fuzzer.cpp; clang, ASan + UBSan) into
# build-fuzz/ and runs it for N seconds (default 60) on a copy of the seed corpus
# tests/fuzz/corpus/. Any crash, sanitizer report, leak or timeout (10 s per input) or an input
# needing more than 2 GiB fails the run (exit code != 0); libFuzzer then leaves the input as
# build-fuzz/findings/crash-*, leak-*, timeout-* or oom-*: minimise it, copy it to
# tests/fuzz/regressions/ (replayed by tests/reliability_test.cpp) and fix the bug.
#   tools/fuzz.sh [SECONDS] [extra libFuzzer flags...]
# Environment: BUILD (default build-fuzz), JOBS (default: nproc).
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_TO_RUN="${1:-60}"
shift || true
BUILD="${BUILD:-build-fuzz}"
JOBS="${JOBS:-$(nproc)}"

if [ ! -f "$BUILD/CMakeCache.txt" ]; then
  CC=clang CXX=clang++ cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DMOBIRT_FUZZ=ON -DMOBIRT_TESTS=OFF -DMOBIRT_WERROR="$([ "${CI:-}" = true ] && echo ON || echo OFF)" >/dev/null
fi
cmake --build "$BUILD" --target scene_fuzzer -j "$JOBS"

# libFuzzer adds what it finds to the first corpus folder: a scratch copy keeps the seeds clean.
rm -rf "$BUILD/corpus" && mkdir -p "$BUILD/corpus" "$BUILD/findings"
cp tests/fuzz/corpus/* "$BUILD/corpus/"
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:symbolize=1}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$PWD/tests/sanitizers/lsan.supp:print_suppressions=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
set +e
"$BUILD/tests/fuzz/scene_fuzzer" "$BUILD/corpus" -max_total_time="$SECONDS_TO_RUN" -timeout=10 \
  -rss_limit_mb=2048 -max_len=16384 -artifact_prefix="$BUILD/findings/" -print_final_stats=1 \
  -dict=tests/fuzz/scene.dict "$@" 2>&1 | tee "$BUILD/fuzz.log" | grep -av '^#[0-9].*\(NEW\|REDUCE\|pulse\)' 
status=${PIPESTATUS[0]}
set -e
if [ "$status" -ne 0 ]; then
  echo "fuzz: FAILED (exit $status); findings in $BUILD/findings/:" >&2
  ls -l "$BUILD/findings" >&2
  exit 1
fi
echo "fuzz: no findings in ${SECONDS_TO_RUN} s ($(grep -ao 'stat::number_of_executed_units: *[0-9]*' "$BUILD/fuzz.log" | grep -o '[0-9]*$') executions)"
