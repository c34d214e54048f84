"""``python -m validation.bench gpu_build``: compile every CUDA kernel of tiers 1 and 2 (and the plain LBM step)
for sm_90 on any machine, and print each kernel's registers, spill and stack bytes, float64 instructions and
whether it launches (:mod:`iceresist.validate.gpu_build`). Needs the ``gpu`` extra and, since the CUDA
simulator replaces ``numba.cuda``, ``NUMBA_ENABLE_CUDASIM=0`` (the default outside the tests).

The common ``--backend``/``--precision``/``--n``/``--steps`` flags do not apply: the check always traces the
CI-sized scenes on the ``cuda`` target in both precisions. Exit status 1 when a kernel does not build or launch.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path


def add_arguments(p):
    p.add_argument("--keep-ptx", type=Path, default=None, metavar="DIR", help="write each kernel's PTX here")


COLUMNS = ("name", "threads", "registers", "spill_stores_bytes", "spill_loads_bytes", "stack_bytes",
           "float64_ops", "float32", "launchable", "compile_seconds", "error")


def run(args) -> list[dict]:
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1":
        raise SystemExit("the GPU build check compiles for a real device: run it with NUMBA_ENABLE_CUDASIM=0")
    from iceresist.validate import gpu_build

    try:
        gpu_build.toolkit()
    except RuntimeError as exc:
        raise SystemExit(str(exc)) from None

    def progress(i, n, b):
        if not args.json:
            state = "ok" if b.launchable else "FAILS"
            print(f"[{i}/{n}] {b.name}: {state} ({b.compile_seconds:.1f} s)", file=sys.stderr)

    builds = gpu_build.run_check(keep=args.keep_ptx, progress=progress)
    rows = []
    for b in builds:
        r = b.row()
        rows.append({"name": r["name"], **{c: r[c] for c in COLUMNS[1:]}, "signature": r["signature"],
                     "scenes": ",".join(r["scenes"]), "backend": "cuda", "cc": "sm_90"})
    if not all(b.launchable for b in builds):
        args.exit_status = 1
    return rows
