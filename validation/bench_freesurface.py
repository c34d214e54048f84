"""Phase-field LBM benchmark: MLUPS of one phase-field step (phi pass + stream-collide pass) on an n^3 box
with a spherical drop advected diagonally, per h lattice (DESIGN.md section 11).

``python -m validation.bench freesurface [--backend cpu|cuda] [--precision float32] [--n 32] [--steps 20] [--json]``
"""

from __future__ import annotations

import time

import numpy as np

from iceresist.backends.jit import resolve_backend
from iceresist.freesurface.hlattice import H_LATTICES
from iceresist.freesurface.phasefield import PhaseField
from iceresist.grid.forest import CELLS, BlockForest


def add_arguments(parser):
    parser.add_argument("--h-lattice", action="append", choices=sorted(H_LATTICES),
                        help="repeatable; default: all four")


def run(args) -> list[dict]:
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
            pf = PhaseField(fo, mobility=0.05, h_lattice=lat, precision=precision, target=target)
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
                         "cells": cells, "steps": int(args.steps), "seconds": sec,
                         "mlups": cells * int(args.steps) / sec / 1e6, "compile_seconds": compile_s})
    return rows


def _sync(target):
    if target.is_cuda:
        from numba import cuda

        cuda.synchronize()
