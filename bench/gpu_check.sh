#!/usr/bin/env bash
# The GPU checks in one run, each under its own time limit, for a machine whose GPU is at hand
# for a short while: first the tests that run the engine's GPU paths (the event scheme's rounds
# against the serial reference, the physics and conservation tests, the collision cases), then
# the GPU benchmark's throughput rows (10^4 to 10^8 circles, f32; `bench/bench.py --arch gpu`,
# placement and radius-spread sections left out), then where an event step's time goes at 10^7
# circles (`bench/diagnostics/kernel_profile.py --arch gpu --scheme event`: each task's share, and the rounds
# and bound sweeps a step). A check stopped by its limit keeps what it wrote: the tests' log, the
# benchmark's log (each row as it is measured, copied into the summary), the tables of the
# sections it finished (it rewrites them after every section) and the profile's log.
#
# Usage, from the repository root, with the project's packages importable:
#   bash bench/gpu_check.sh OUTDIR [TEST_SECONDS] [BENCH_SECONDS] [PROFILE_SECONDS]
# (defaults 150, 270 and 90: 510 s, which leaves a call of ten minutes time to install the
# project first). OUTDIR gets summary.txt (each check's exit status, 124 for one stopped by its
# limit, the tests' last lines, the throughput rows and the profile's first rows), tests.log,
# bench.log, bench/<gpu name>/ (results.md and the CSV tables) and profile.log.
# CIRCLES_CHECK_ARCH=cpu runs the same checks on the CPU, to try the script on a machine without
# a GPU; CIRCLES_CHECK_PROFILE_N sets the profile's circles (1e7).
set -uo pipefail
out=${1:?usage: bash bench/gpu_check.sh OUTDIR [TEST_SECONDS] [BENCH_SECONDS] [PROFILE_SECONDS]}
test_s=${2:-150}
bench_s=${3:-270}
profile_s=${4:-90}
profile_n=${CIRCLES_CHECK_PROFILE_N:-1e7}
arch=${CIRCLES_CHECK_ARCH:-gpu}
python=${PYTHON:-python3}
cd "$(dirname "$0")/.."
mkdir -p "$out" || exit 2
summary="$out/summary.txt"
: > "$summary"
{
  echo "gpu_check on $(date -u '+%Y-%m-%d %H:%M UTC'), arch $arch, limits ${test_s} s (tests), ${bench_s} s (bench) and ${profile_s} s (profile)"
  git rev-parse --short HEAD 2>/dev/null | sed 's/^/commit /'
  command -v nvidia-smi > /dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
} >> "$summary" 2>&1

# -o addopts="": every test of these files, slow ones too, in one process (no pytest-xdist there).
CIRCLES_TEST_ARCH=$arch timeout "$test_s" "$python" -m pytest -q -x -p no:cacheprovider -o addopts="" --durations=10 \
  tests/test_reference.py tests/test_physics.py tests/test_conservation.py tests/test_collisions.py \
  > "$out/tests.log" 2>&1
echo "tests: exit $?" >> "$summary"
tail -n 3 "$out/tests.log" | sed -e '$a\' >> "$summary"  # a log cut by its limit may end mid-line

timeout "$bench_s" "$python" bench/bench.py --arch "$arch" --skip placement,spread --out "$out/bench" \
  > "$out/bench.log" 2>&1
echo "bench: exit $?" >> "$summary"
grep -E "circle-steps/s" "$out/bench.log" | tail -n 20 >> "$summary"

timeout "$profile_s" "$python" bench/diagnostics/kernel_profile.py --arch "$arch" --n "$profile_n" --scheme event --steps 5 \
  --warm 10 > "$out/profile.log" 2>&1
echo "profile: exit $?" >> "$summary"
grep -E "circle-steps/s|per step|%" "$out/profile.log" | head -n 24 >> "$summary"
cat "$summary"
