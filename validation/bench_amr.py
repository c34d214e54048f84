"""Block-refinement benchmark: a periodic box of ``--n`` level-0 cells per side with its centre refined to two and
three levels (a cube of half the side on level 1, of a quarter on level 2), against the uniform grid at the finest
spacing. Per level: cells, steps per level-0 step, seconds in its fused kernel and its MLUPS; the level exchange
(host NumPy) apart; the whole step as fine-equivalent cell updates per second (the uniform finest grid's cells
times its steps, over the refined run's wall time) beside the uniform finest grid's own rate. BGK, on the CPU or
(``--backend cuda``) a GPU, where the level exchange is the ``level_transfer`` kernel.

    python -m validation.bench amr [--backend cuda] [--n 64] [--steps 20] [--precision float32] [--json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def add_arguments(parser: argparse.ArgumentParser):
    parser.add_argument("--levels", type=int, action="append", help="refined levels to time (default 1 and 2)")


def _octree(n: int, levels: int):
    from iceresist.grid.octree import BlockOctree

    c = n / 2.0

    def wanted(lo, hi):
        level = np.zeros(len(lo), dtype=np.int64)
        for lv in range(1, levels + 1):
            half = n / 2 ** (lv + 1)             # level lv: a cube of side n / 2^lv around the centre
            inside = ((lo < c + half) & (hi > c - half)).all(axis=1)
            level = np.where(inside, lv, level)
        return level

    return BlockOctree((n // 8,) * 3, levels, periodic=(True, True, True)).refine(wanted)


def _timed(model, level: int, bucket: dict):
    """Step ``level`` of ``model`` (a RefinedLBM) through a wrapper that adds its seconds up in ``bucket[level]``
    (the device waited for before and after on CUDA, so the seconds are the level's own)."""
    step = model.steppers[level]
    sync = model.target.synchronize

    def timed():
        sync()
        t0 = time.perf_counter()
        step()
        sync()
        bucket[level] = bucket.get(level, 0.0) + time.perf_counter() - t0

    model.set_stepper(level, timed)


def measure(n: int, levels: int, steps: int, precision: str, target=None) -> list[dict]:
    from iceresist.grid.forest import BlockForest, Face
    from iceresist.lbm.refinement import RefinedLBM
    from iceresist.backends import jit
    from iceresist.lbm.solver import LBMSolver

    target = target or jit.cpu
    faces = {k: Face("periodic") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}
    m = RefinedLBM(_octree(n, levels), tau0=0.6, faces=faces, operator="bgk", precision=precision,
                   target=target)
    m.initialize(1.0, (0.01, 0.0, 0.0))
    m.step(1)                                            # compile
    target.synchronize()
    t0 = time.perf_counter()
    m.step(steps)                                        # the whole step, untouched by the per-level waits
    target.synchronize()
    whole = time.perf_counter() - t0
    spent: dict = {}
    for lv in m.solvers:
        _timed(m, lv, spent)
    t0 = time.perf_counter()
    m.step(steps)
    wall = time.perf_counter() - t0
    rows = []
    fine_cells = (n * 2 ** levels) ** 3
    for lv in m.levels:
        v = m.views[lv]
        updated = v.forest.nblocks * 512 * steps * 2 ** lv    # the kernel steps leaves and ghosts
        rows.append({"name": f"amr {levels + 1} levels: level {lv}", "backend": target.name, "precision": precision,
                     "cells": v.nleaves * 512, "ghost_cells": v.nghosts * 512, "steps": steps * 2 ** lv,
                     "seconds": spent.get(lv, 0.0), "mlups": updated / max(spent.get(lv, 0.0), 1e-12) / 1e6})
    kernel = sum(spent.values())
    rows.append({"name": f"amr {levels + 1} levels: whole step", "backend": target.name, "precision": precision,
                 "cells": sum(r["cells"] for r in rows), "steps": steps, "seconds": whole,
                 "exchange_seconds": wall - kernel,
                 "fine_equivalent_mlups": fine_cells * steps * 2 ** levels / whole / 1e6,
                 "cell_share_of_uniform_fine": sum(r["cells"] for r in rows) / fine_cells})
    fo = BlockForest.uniform((n * 2 ** levels,) * 3, faces)
    s = LBMSolver(fo, tau=0.5 + 0.1 * 2 ** levels, operator="bgk", precision=precision, target=target)
    s.initialize(1.0, (0.01, 0.0, 0.0))
    s.step(1)
    fine_steps = max(1, steps // 2) * 2 ** levels
    s.synchronize()
    t0 = time.perf_counter()
    s.step(fine_steps)
    s.synchronize()
    sec = time.perf_counter() - t0
    rows.append({"name": f"uniform finest grid ({n * 2 ** levels}^3)", "backend": target.name, "precision": precision,
                 "cells": fine_cells, "steps": fine_steps, "seconds": sec, "mlups": fine_cells * fine_steps / sec / 1e6})
    return rows


def run(args) -> list[dict]:
    """Every precision asked for (``args.precision``), two and three levels (``--levels``), on ``--backend``."""
    from iceresist.backends import jit

    target = jit.resolve_backend(args.backend)
    precisions = [args.precision] if isinstance(args.precision, str) else list(args.precision)
    n = max(16, args.n // 16 * 16)
    rows = []
    for p in precisions:
        for levels in getattr(args, "levels", None) or [1, 2]:
            rows += measure(n, levels, args.steps, p, target)
    return rows
