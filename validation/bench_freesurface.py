"""Free-surface benchmarks (docs/PERFORMANCE.md).

* ``--part coupled`` (default): MLUPS of the whole free-surface step (fused f update with eq. 11, velocity
  extension, phase-field h update, pool rows, reflag) in a closed n x n x n tank filled to 1/4, 1/2 and 3/4
  with a small standing wave, with the share of cells in water, gas and interface (liquid cells with a gas
  neighbour) and the population rows held; MLUPS counts every cell of the box.
* ``--part phase``: MLUPS of the phase field alone (phi pass + stream-collide pass) on an n^3 box with a
  spherical drop advected diagonally, per h lattice.

``python -m validation.bench freesurface [--part coupled|phase] [--backend cpu|cuda] [--precision float32]
[--n 32] [--steps 20] [--phase-form block|cell] [--json]``
"""

from __future__ import annotations

import time

import numpy as np

from iceresist.backends.jit import resolve_backend
from iceresist.freesurface.hlattice import H_LATTICES
from iceresist.freesurface.phasefield import PhaseField
from iceresist.grid.forest import CELLS, BlockForest


def add_arguments(parser):
    parser.add_argument("--part", choices=("coupled", "phase"), default="coupled",
                        help="coupled: the whole f + h step in a tank (default); phase: the phase field alone")
    parser.add_argument("--h-lattice", action="append", choices=sorted(H_LATTICES),
                        help="repeatable; default: D3Q15 for --part coupled, all four for --part phase")
    parser.add_argument("--operator", choices=("bgk", "cumulant"), default="cumulant")
    parser.add_argument("--phase-form", choices=("block", "cell"), default="block",
                        help="--part phase on the CPU: the vectorised block form (default) or the per-cell form")


def run(args) -> list[dict]:
    if getattr(args, "part", "coupled") == "coupled":
        return run_coupled(args)
    return run_phase(args)


def run_coupled(args) -> list[dict]:
    """The whole free-surface step in a closed tank at three fill levels (module docstring)."""
    from iceresist.freesurface.fluid import FreeSurfaceFluid
    from iceresist.grid import flags as FL

    target = resolve_backend(args.backend)
    n = int(args.n)
    rows = []
    for precision in args.precision or ["float32"]:
        for lat in args.h_lattice or ["D3Q15"]:
            for fill in (0.25, 0.5, 0.75):
                fo = BlockForest.uniform((n, n, n))
                depth = fill * n
                t0 = time.perf_counter()
                fs = FreeSurfaceFluid(fo, tau=0.55, gravity_lattice=1e-4, depth_cells=depth, mobility=0.02,
                                      h_lattice=lat, operator=args.operator, precision=precision, target=target)
                x = np.arange(n) + 0.5
                surface = depth + 0.5 * np.cos(2 * np.pi * x / n)[:, None] * np.ones(n)[None, :]
                fs.initialize(surface=surface)
                fs.step(1)
                fs.fluid.synchronize()
                compile_s = time.perf_counter() - t0
                t0 = time.perf_counter()
                fs.step(int(args.steps))
                fs.fluid.synchronize()
                sec = time.perf_counter() - t0
                flags = np.asarray(fs._host(fs.fluid.flags))
                liquid = (flags & FL.FLUID) != 0
                interface = liquid & ((flags & FL.NEAR_SURFACE) != 0)
                gas = (flags & FL.GAS) != 0
                cells = fo.nblocks * CELLS
                rows.append({"name": f"freesurface-coupled-fill{int(100 * fill)}", "backend": target.name,
                             "precision": precision, "operator": args.operator, "h_lattice": lat, "cells": cells,
                             "steps": int(args.steps), "seconds": sec, "mlups": cells * int(args.steps) / sec / 1e6,
                             "water_share": float((liquid & ~interface).sum() / cells),
                             "interface_share": float(interface.sum() / cells),
                             "gas_share": float(gas.sum() / cells),
                             "f_rows": int(fs.fluid.pool.capacity), "blocks": int(fo.nblocks),
                             "compile_seconds": compile_s})
    return rows


def run_phase(args) -> list[dict]:
    target = resolve_backend(args.backend)
    n = int(args.n)
    fo = BlockForest.uniform((n, n, n))
    x = np.arange(n) + 0.5
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    r = np.sqrt((X - n / 2) ** 2 + (Y - n / 2) ** 2 + (Z - n / 2) ** 2)
    phi0 = fo.from_dense(0.5 - 0.5 * np.tanh(2.0 * (r - n / 4) / 3.0))
    rows = []
    for precision in args.precision or ["float32", "float64"]:
        u = np.zeros((fo.nblocks, 3, CELLS), dtype=precision) + np.array([0.04, 0.03, 0.02], dtype=precision)[None, :, None]
        for lat in args.h_lattice or sorted(H_LATTICES):
            t0 = time.perf_counter()
            pf = PhaseField(fo, mobility=0.05, h_lattice=lat, precision=precision, target=target,
                            vector=getattr(args, "phase_form", "block") == "block")
            pf.initialize(phi0, u)
            u_t = pf._u(u)
            pf.step(u_t)
            _sync(target)
            compile_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            for _ in range(int(args.steps)):
                pf.step(u_t)
            _sync(target)
            sec = time.perf_counter() - t0
            cells = fo.nblocks * CELLS
            rows.append({"name": f"freesurface-{lat}", "backend": target.name, "precision": precision,
                         "form": "cell" if target.is_cuda else getattr(args, "phase_form", "block"),
                         "cells": cells, "steps": int(args.steps), "seconds": sec,
                         "mlups": cells * int(args.steps) / sec / 1e6, "compile_seconds": compile_s})
    return rows


def _sync(target):
    if target.is_cuda:
        from numba import cuda

        cuda.synchronize()
