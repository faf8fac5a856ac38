#!/usr/bin/env bash
# The GPU checks of one borrowed-GPU session, as one command (docs/performance.md, GPU):
#   1. the card and JAX's view of it;
#   2. scripts/bench_gpu.py: glass-drum-3d through the product path at N = 1e5 and 1e6, float32
#      and float64 mechanics: particle-steps/s and peak device memory per particle;
#   3. the tests of the newer heat features (friction heat, drum wall, coarse-graining) on the
#      GPU: the same code must give the same physics there (the suite itself never needs one).
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
timeout 330 python3 scripts/bench_gpu.py --n 100000 1000000 --precision float32 float64 \
  --seconds "$SECONDS_PER_CASE" --warm 200 --timeout 150 --json "$OUT/bench_gpu.jsonl" \
  2>&1 | tee "$OUT/bench_gpu.log"
timeout 120 python3 -m pytest -q -x -p no:cacheprovider -o addopts="" -m "not slow" \
  tests/test_friction_heat.py tests/test_drum_wall.py tests/test_coarse_grain.py \
  2>&1 | tee "$OUT/tests_gpu.log" | tail -15
