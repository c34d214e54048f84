#!/bin/bash
# The GPU checks of docs/PERFORMANCE.md on a machine with an NVIDIA GPU, in the order that matters most when time is
# short: the test suite on the device, the fused LBM at 256^3 against the device's copy bandwidth, the coupled
# quick tier-2 step launcher by launcher. Each writes into OUT (default gpu-check/); PYTHON picks the interpreter
# (default python3), PYTEST_WORKERS the pytest-xdist workers (default: 8 where pytest-xdist is installed).
#
#   bash validation/gpu_check.sh [OUT]
set -u
OUT=${1:-gpu-check}
PYTHON=${PYTHON:-python3}
mkdir -p "$OUT"
export NUMBA_ENABLE_CUDASIM=0 PYTHONUNBUFFERED=1
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
  "$PYTHON" -c "import numba, numpy, importlib.metadata as m; from numba import cuda; d = cuda.get_current_device(); print('numba', numba.__version__, 'numba-cuda', m.version('numba-cuda'), 'numpy', numpy.__version__); print(d.name, d.compute_capability)"
} > "$OUT/env.txt" 2>&1 || { echo "no usable CUDA device: $(grep -i -E 'error|not found' "$OUT/env.txt" | tail -1) (all: $OUT/env.txt)"; exit 2; }
cat "$OUT/env.txt"
XDIST=""
if "$PYTHON" -c "import xdist" 2>/dev/null; then XDIST="-n ${PYTEST_WORKERS:-8}"; fi
echo "== tests on the device (the CUDA ones first)"
"$PYTHON" -m pytest -q $XDIST -p no:cacheprovider -m "not slow and not mpi" -k "cuda or gpu or transfer" -rfE \
    > "$OUT/pytest_cuda.log" 2>&1; echo "exit $?"; tail -3 "$OUT/pytest_cuda.log"
"$PYTHON" -m pytest -q $XDIST -p no:cacheprovider -m "not slow and not mpi" -k "not (cuda or gpu or transfer)" -rfE \
    > "$OUT/pytest_rest.log" 2>&1; echo "exit $?"; tail -3 "$OUT/pytest_rest.log"
echo "== fused LBM, 256^3"
"$PYTHON" -m validation.bench lbm --backend cuda --precision float32 --precision float64 --n 256 --steps 50 --json \
    > "$OUT/lbm.json" 2> "$OUT/lbm.err"; echo "exit $?"; cat "$OUT/lbm.json"
echo "== coupled quick tier-2 step"
"$PYTHON" -m validation.bench ship --preset quick --backend cuda --precision float32 --compare-pure --by-label --records 3 --json \
    > "$OUT/ship.json" 2> "$OUT/ship.err"; echo "exit $?"; cat "$OUT/ship.json"
