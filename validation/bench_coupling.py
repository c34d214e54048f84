"""Cost of the moving-boundary coupling: ``python -m validation.bench coupling --bodies 100 --bodies 1000``.

Cubes of ``--edge`` cells on a lattice of pitch ``--pitch`` cells fill a periodic fluid box; each moves
(kinematic, 0.02 cells per step, slowly spinning) so that cells are covered and refilled every step.
Timed after a warm-up: the coupling passes (cells, refill, mass, links and forces), the LBM step and the
DEM step; reported per boundary link and as a share of the full coupled step.
"""

from __future__ import annotations

import math
import time

import numpy as np


def add_arguments(parser):
    parser.add_argument("--bodies", type=int, action="append", help="number of cubes (repeatable; default 100, 1000)")
    parser.add_argument("--edge", type=float, default=4.0, help="cube edge in cells")
    parser.add_argument("--pitch", type=int, default=8, help="spacing of the cubes in cells")
    parser.add_argument("--operator", default="bgk", choices=("bgk", "cumulant"))


def _case(nbodies, edge, pitch, precision, operator, target):
    from iceresist.coupling import Box, FluidStructureCoupling, LatticeUnits
    from iceresist.dem import DEMSystem, box
    from iceresist.grid.forest import BlockForest
    from iceresist.lbm.solver import LBMSolver

    per = int(math.ceil(nbodies ** (1 / 3)))
    side = int(math.ceil(per * pitch / 8) * 8)
    fo = BlockForest.uniform((side, side, side))
    solver = LBMSolver(fo, tau=0.6, operator=operator, precision=precision, target=target)
    solver.initialize()
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    rng = np.random.default_rng(1)
    idx = np.stack(np.meshgrid(*(np.arange(per),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)[:nbodies]
    for i, j, k in idx:
        dem.add_body(box((edge,) * 3, 900.0), position_m=(pitch * (np.array([i, j, k]) + 0.5)),
                     velocity_m_s=rng.normal(0, 0.02, 3), angular_velocity_rad_s=rng.normal(0, 0.005, 3),
                     kinematic=True)
    cp = FluidStructureCoupling(solver, dem, [Box((edge,) * 3)] * nbodies,
                                LatticeUnits(dx_m=1.0, dt_s=1.0, rho_kg_m3=1.0))
    return fo, solver, dem, cp


def run(args) -> list[dict]:
    from iceresist.backends import jit

    target = jit.resolve_backend(args.backend)
    rows = []
    for precision in args.precision or ["float32"]:
        for nb in args.bodies or [100, 1000]:
            t0 = time.perf_counter()
            fo, solver, dem, cp = _case(nb, args.edge, args.pitch, precision, args.operator, target)
            cp.step(2)
            compile_s = time.perf_counter() - t0
            tc = tl = td = 0.0
            links = 0
            for _ in range(args.steps):
                a = time.perf_counter()
                cp.update_boundaries()
                solver.synchronize()
                b = time.perf_counter()
                solver.step(1)
                solver.synchronize()
                c = time.perf_counter()
                dem.step(1.0)
                d = time.perf_counter()
                tc, tl, td = tc + b - a, tl + c - b, td + d - c
                links += int(cp.links.sum())
            total = tc + tl + td
            rows.append({"name": "coupling", "backend": target.name, "precision": precision,
                         "operator": args.operator, "bodies": nb, "cells": fo.cells, "steps": args.steps,
                         "links_per_step": links // args.steps, "active_blocks": cp.active_blocks,
                         "seconds": total, "coupling_s_per_step": tc / args.steps,
                         "lbm_s_per_step": tl / args.steps, "dem_s_per_step": td / args.steps,
                         "ns_per_link": 1e9 * tc / max(links, 1), "coupling_share": tc / total,
                         "compile_seconds": compile_s})
    return rows
