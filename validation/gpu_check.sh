#!/bin/bash
# The GPU checks of docs/PERFORMANCE.md on a machine with an NVIDIA GPU, in the order that matters most when time is
# short. Each section writes into OUT (default gpu-check/); name sections to run only those (default: all, in order):
#   cuda   the tests that launch CUDA kernels, on the device
#   mpi    `mpirun -n 2` with backend = "cuda": the cavity and the floating cube (needs mpirun and the iceresist
#          script beside the interpreter: the `mpi` extra and `pip install -e .`)
#   ship   the coupled quick tier-2 step launcher by launcher, beside the pure fused LBM step, with and without
#          CUDA graphs; the launches of a step and a whole record with its diagnostics
#   graphs the tests of the step replayed as a CUDA graph, the DEM launchers and the launch budget, on the device
#   case   the whole quick tier-2 case A-c68-v1.0 (iceresist run, backend cuda) with its records: wall time
#   amr    the block-refined LBM on two and three levels, per level, beside the uniform finest grid
#   lbm    the fused LBM at 256^3 against the device's copy bandwidth
#   rest   the other tests of the CI selection
#   campaign  tier 2 on refined levels in one 9-minute visit: the ladder, the quick case's rate, the quick sweep and the
#          paper's levels, each phase to a deadline (validation/gpu_campaign.sh; not in the default list)
# PYTHON picks the interpreter (default python3), PYTEST_WORKERS the pytest-xdist workers (default 8 where
# pytest-xdist is installed), SECTION_TIMEOUT the seconds each section may run (default: no limit).
#
#   bash validation/gpu_check.sh [OUT [SECTION ...]]
set -u
OUT=${1:-gpu-check}
shift || true
SECTIONS=${*:-cuda mpi ship graphs case amr lbm rest}
PYTHON=${PYTHON:-python3}
LIMIT=${SECTION_TIMEOUT:+timeout $SECTION_TIMEOUT}
mkdir -p "$OUT"
export NUMBA_ENABLE_CUDASIM=0 PYTHONUNBUFFERED=1
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
  "$PYTHON" -c "import numba, numpy, importlib.metadata as m; from numba import cuda; d = cuda.get_current_device(); print('numba', numba.__version__, 'numba-cuda', m.version('numba-cuda'), 'numpy', numpy.__version__); print(d.name, d.compute_capability)"
} > "$OUT/env.txt" 2>&1 || { echo "no usable CUDA device: $(grep -i -E 'error|not found' "$OUT/env.txt" | tail -1) (all: $OUT/env.txt)"; exit 2; }
cat "$OUT/env.txt"
XDIST=""
if "$PYTHON" -c "import xdist" 2>/dev/null; then XDIST="-n ${PYTEST_WORKERS:-8}"; fi
for section in $SECTIONS; do
  echo "== $section ($(date -u +%H:%M:%S))"
  case $section in
    cuda) $LIMIT "$PYTHON" -m pytest -v $XDIST -p no:cacheprovider -m "not slow and not mpi" \
            -k "cuda or gpu or transfer" -rfE > "$OUT/pytest_cuda.log" 2>&1
          echo "exit $?"; tail -4 "$OUT/pytest_cuda.log" ;;
    mpi)  bin=$("$PYTHON" -c "import sys, pathlib; print(pathlib.Path(sys.executable).parent)")
          if [ ! -x "$bin/mpirun" ] || [ ! -x "$bin/iceresist" ]; then
            echo "skipped: no mpirun or iceresist in $bin (pip install mpich mpi4py, then pip install -e .)"; continue
          fi
          $LIMIT "$PYTHON" -m pytest -q -p no:cacheprovider -m mpi -k cuda -rfE > "$OUT/pytest_mpi.log" 2>&1
          echo "exit $?"; tail -4 "$OUT/pytest_mpi.log" ;;
    ship) $LIMIT "$PYTHON" -m validation.bench ship --preset quick --backend cuda --precision float32 --compare-pure \
            --by-label --records 3 --json > "$OUT/ship.json" 2> "$OUT/ship.err"
          echo "exit $?"; cat "$OUT/ship.json"; tail -3 "$OUT/ship.err" ;;
    graphs) $LIMIT "$PYTHON" -m pytest -v -p no:cacheprovider -m "gpu or not gpu" tests/test_graphs.py \
            tests/test_dem_cuda.py tests/test_launch_budget.py -rfE > "$OUT/pytest_graphs.log" 2>&1
          echo "exit $?"; tail -6 "$OUT/pytest_graphs.log" ;;
    case) work=$(mktemp -d)      # the result file stays out of OUT
          printf '[case]\nname = "A-c68-v1.0"\nfidelity = "quick"\ntier = 2\n' > "$work/case_t2.toml"
          start=$(date +%s)
          $LIMIT "$PYTHON" -m iceresist run "$work/case_t2.toml" --backend cuda --no-progress --output "$work/run" \
            --force > "$OUT/case.log" 2>&1
          echo "exit $? after $(( $(date +%s) - start )) s"; grep -E "wall time|mean ice" "$OUT/case.log" | tail -3 ;;
    amr)  $LIMIT "$PYTHON" -m validation.bench amr --backend cuda --precision float32 --n 64 --steps 20 --levels 1 --levels 2 --json \
            > "$OUT/amr.json" 2> "$OUT/amr.err"
          echo "exit $?"; cat "$OUT/amr.json"; tail -3 "$OUT/amr.err" ;;
    lbm)  $LIMIT "$PYTHON" -m validation.bench lbm --backend cuda --precision float32 --precision float64 --n 256 \
            --steps 50 --json > "$OUT/lbm.json" 2> "$OUT/lbm.err"
          echo "exit $?"; cat "$OUT/lbm.json"; tail -3 "$OUT/lbm.err" ;;
    rest) $LIMIT "$PYTHON" -m pytest -q $XDIST -p no:cacheprovider -m "not slow and not mpi" \
            -k "not (cuda or gpu or transfer)" -rfE > "$OUT/pytest_rest.log" 2>&1
          echo "exit $?"; tail -4 "$OUT/pytest_rest.log" ;;
    campaign) PYTHON="$PYTHON" bash "$(dirname "$0")/gpu_campaign.sh" "$OUT"
          echo "exit $?" ;;
    *)    echo "unknown section '$section': use cuda, mpi, ship, graphs, case, amr, lbm, rest or campaign"; exit 2 ;;
  esac
done
