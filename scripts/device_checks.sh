#!/usr/bin/env bash
# The GPU checks of one borrowed-GPU session, as one command (docs/performance.md, GPU):
#   1. the card and JAX's view of it;
#   2. scripts/bench_gpu.py: glass-drum-3d through the product path at N = 1e5 and 1e6, float64,
#      mixed and float32 mechanics: particle-steps/s and peak device memory per particle;
#   3. the tests of the newer heat features (coupled contact times, friction heat, drum wall,
#      coarse-graining) and of the DEM's run loop on the GPU: the same code must give the same
#      physics there (the suite itself never needs one; the tests that compare two runs bit
#      for bit, marked bitwise, are skipped there: a GPU adds in no fixed order).
# Environment knobs: PRECISIONS (default "float64 mixed float32"), NS ("100000 1000000"), TRACE
# (steps of a profiler trace after each timing, 0 = none; the trace files go to $OUT, the
# per-kernel lines to bench_gpu.log only), TESTS (the test files), TEST_SECONDS (their limit).
# Wheels a GPU machine without network lacks (tomli_w; jax-md and its needs for the tests) may
# lie in .whl/ (git-ignored; `pip download --no-deps --only-binary=:all: --python-version 3.12
# -d .whl NAME`): they are installed into /tmp/site first. Logs and JSON go to $OUT.
#
# Usage (on the device machine, from the repository root): bash scripts/device_checks.sh [SECONDS]
set -u -o pipefail
OUT=${OUT:-/tmp/device_out}
mkdir -p "$OUT"
SECONDS_PER_CASE=${1:-8}
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm,clocks.mem --format=csv
python3 -c "import jax; print('jax', jax.__version__, jax.devices())"
TESTS=${TESTS:-tests/test_coupled.py tests/test_friction_heat.py tests/test_drum_wall.py tests/test_coarse_grain.py tests/test_mechanics_runner.py}
# shellcheck disable=SC2086  # word splitting of the lists is meant
timeout 330 python3 scripts/bench_gpu.py --n ${NS:-100000 1000000} \
  --precision ${PRECISIONS:-float64 mixed float32} --seconds "$SECONDS_PER_CASE" --warm 200 \
  --timeout 150 --json "$OUT/bench_gpu.jsonl" --trace "${TRACE:-0}" --trace-dir "$OUT" \
  2>&1 | tee "$OUT/bench_gpu.log" | grep -v '^  '
# shellcheck disable=SC2086
timeout "${TEST_SECONDS:-120}" python3 -m pytest -q -x -p no:cacheprovider -o addopts="" \
  -m "not slow" $TESTS 2>&1 | tee "$OUT/tests_gpu.log" | tail -15
