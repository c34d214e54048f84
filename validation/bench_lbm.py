"""MLUPS of the fused pull stream-collide kernel on a periodic cube (``python -m validation.bench lbm``).

Measures million lattice-cell updates per second after a warm-up step (compile time reported
apart), the CPU time the timed steps took (``mlups_per_cpu_s``: throughput per busy core-second,
which a loaded shared machine does not depress the way it does the wall-clock figure) with the
1-minute load average, and the memory bandwidth it implies, 2 * 27 * bytes * cells * steps / seconds
(read and write of every population once per step). On CUDA it adds a 256^3 case (``--largest``: also the
largest cube that fits in device memory) and a device-to-device copy bandwidth to set the kernel's figure against.
"""

from __future__ import annotations

import os
import time

import numpy as np

from iceresist.backends import jit
from iceresist.grid import BlockForest
from iceresist.lbm.solver import LBMSolver, operator_available


def add_arguments(parser):
    parser.add_argument("--operator", choices=("auto", "cumulant", "bgk"), default="auto",
                        help="collision operator; auto = cumulant where available, else bgk")
    parser.add_argument("--tau", type=float, default=0.6)
    parser.add_argument("--largest", action="store_true",
                        help="on CUDA also the largest cube whose populations fit the device (its set-up on the host "
                             "needs host memory of the same size: minutes and tens of GB on a large GPU)")


def measure(n, precision, target, operator, steps, tau=0.6):
    """One measurement on an n^3 periodic cube with a small random density perturbation."""
    fo = BlockForest.uniform((n, n, n))
    t0 = time.perf_counter()
    s = LBMSolver(fo, tau=tau, operator=operator, precision=precision, target=target)
    rng = np.random.default_rng(0)
    s.initialize(rho=1 + 1e-3 * rng.standard_normal(fo.shape_cells))
    s.step(1)
    s.synchronize()
    compile_s = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    s.step(steps)
    s.synchronize()
    sec = time.perf_counter() - t0
    cpu_sec = time.process_time() - c0
    if not np.isfinite(s.mass()):
        raise RuntimeError("benchmark state went non-finite")
    itemsize = np.dtype(precision).itemsize
    return {"name": "lbm", "backend": target.name, "precision": precision, "operator": operator, "cells": s.cells,
            "steps": steps, "seconds": sec, "mlups": s.cells * steps / sec / 1e6,
            "bandwidth_GBps": 2 * 27 * itemsize * s.cells * steps / sec / 1e9, "compile_seconds": compile_s,
            # CPU time of this process over the timed steps (all threads) and the machine's load: on a
            # shared machine mlups_per_cpu_s * cores is what the cores would give if they were free
            "cpu_seconds": cpu_sec, "mlups_per_cpu_s": s.cells * steps / max(cpu_sec, 1e-9) / 1e6,
            "load_average_1min": os.getloadavg()[0]}


def copy_bandwidth(nbytes=1 << 30, repeats=10):
    """Device-to-device copy bandwidth (read + write) in GB/s."""
    from numba import cuda

    a = cuda.device_array(nbytes // 4, dtype=np.float32)
    b = cuda.device_array_like(a)
    b.copy_to_device(a)
    cuda.synchronize()
    t0 = time.perf_counter()
    for _ in range(repeats):
        b.copy_to_device(a)
    cuda.synchronize()
    return {"name": "lbm-copy", "backend": "cuda", "cells": 0, "steps": repeats,
            "seconds": time.perf_counter() - t0,
            "bandwidth_GBps": 2 * a.nbytes * repeats / (time.perf_counter() - t0) / 1e9}


def largest_cube(precision):
    """Largest multiple-of-8 cube whose two population buffers fit in 90 % of free device memory."""
    from numba import cuda

    free, _ = cuda.current_context().get_memory_info()
    per_cell = 2 * 27 * np.dtype(precision).itemsize + 1
    n = int((0.9 * free / per_cell) ** (1 / 3)) // 8 * 8
    return max(n, 8)


def run(args):
    target = jit.resolve_backend(args.backend)
    operator = args.operator
    if operator == "auto":
        operator = "cumulant" if operator_available("cumulant") else "bgk"
    rows = []
    for precision in args.precision:
        rows.append(measure(args.n, precision, target, operator, args.steps, args.tau))
        if target.is_cuda and not target.simulator:
            sizes = {256, largest_cube(precision)} if args.largest else {256}
            for n in sorted(sizes - {args.n}):
                rows.append(measure(n, precision, target, operator, args.steps, args.tau))
    if target.is_cuda and not target.simulator:
        rows.append(copy_bandwidth())
        peak = rows[-1]["bandwidth_GBps"]
        for r in rows[:-1]:
            r["bandwidth_fraction_of_copy"] = r["bandwidth_GBps"] / peak
    return rows
