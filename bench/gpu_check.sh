#!/usr/bin/env bash
# The GPU checks in one run, each under its own time limit, for a machine whose GPU is at hand
# for a short while: first the tests that run the engine's GPU paths (the event scheme's rounds
# against the serial reference, the physics and conservation tests, the collision cases), then
# the GPU benchmark's throughput rows (10^4 to 10^8 circles, f32; `bench/bench.py --arch gpu`,
# placement and radius-spread sections left out). A check stopped by its limit keeps what it
# wrote: the tests' log, the benchmark's log (each row as it is measured, copied into the
# summary) and the tables of the sections it finished (it rewrites them after every section).
#
# Usage, from the repository root, with the project's packages importable:
#   bash bench/gpu_check.sh OUTDIR [TEST_SECONDS] [BENCH_SECONDS]
# (defaults 180 and 330: both within ten minutes). OUTDIR gets summary.txt (each check's exit
# status, 124 for one stopped by its limit, and the tests' last lines), tests.log, bench.log and
# bench/<gpu name>/ (results.md and the CSV tables). CIRCLES_CHECK_ARCH=cpu runs the same checks
# on the CPU, to try the script on a machine without a GPU.
set -uo pipefail
out=${1:?usage: bash bench/gpu_check.sh OUTDIR [TEST_SECONDS] [BENCH_SECONDS]}
test_s=${2:-180}
bench_s=${3:-330}
arch=${CIRCLES_CHECK_ARCH:-gpu}
python=${PYTHON:-python3}
cd "$(dirname "$0")/.."
mkdir -p "$out" || exit 2
summary="$out/summary.txt"
: > "$summary"
{
  echo "gpu_check on $(date -u '+%Y-%m-%d %H:%M UTC'), arch $arch, limits ${test_s} s (tests) and ${bench_s} s (bench)"
  git rev-parse --short HEAD 2>/dev/null | sed 's/^/commit /'
  command -v nvidia-smi > /dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
} >> "$summary" 2>&1

CIRCLES_TEST_ARCH=$arch timeout "$test_s" "$python" -m pytest -q -x -p no:cacheprovider --durations=10 \
  tests/test_reference.py tests/test_physics.py tests/test_conservation.py tests/test_collisions.py \
  > "$out/tests.log" 2>&1
echo "tests: exit $?" >> "$summary"
tail -n 3 "$out/tests.log" >> "$summary"

timeout "$bench_s" "$python" bench/bench.py --arch "$arch" --skip placement,spread --out "$out/bench" \
  > "$out/bench.log" 2>&1
echo "bench: exit $?" >> "$summary"
grep -E "circle-steps/s" "$out/bench.log" | tail -n 20 >> "$summary"
cat "$summary"
