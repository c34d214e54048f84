"""Cost of the moving-boundary coupling: ``python -m validation.bench coupling --bodies 100 --bodies 1000``.

Cubes of ``--edge`` cells on a lattice of pitch ``--pitch`` cells fill a periodic fluid box; each moves
(kinematic, 0.02 cells per step, slowly spinning) so that cells are covered and refilled every step.
Timed after a warm-up: the coupling passes (cells, refill, mass, links and forces), the LBM step and the
DEM step; reported per boundary link and as a share of the full coupled step.

``--large LX,LY,LZ`` adds one large moving box (edges in cells, a stand-in for the hull) in the middle of the
box, and ``--tile-cells N`` sets how many cells of a body's cell box one launch row takes
(``iceresist.coupling.coupler.TILE_CELLS``; 0: never split a body), to measure what splitting a large body
buys: ``python -m validation.bench coupling --bodies 100 --large 192,48,40 --tile-cells 0 --tile-cells 32768``.
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
    parser.add_argument("--large", default=None,
                        help="edges LX,LY,LZ (cells) of one large moving box added to the cubes (default: none)")
    parser.add_argument("--no-film", action="store_true", help="without the contact film (its cost: compare)")
    parser.add_argument("--tile-cells", type=int, action="append",
                        help="cells of a body's box per launch row, 0 = never split (repeatable; default: the "
                             "coupler's TILE_CELLS)")


def _large_edges(text):
    from iceresist.errors import InputError

    try:
        edges = tuple(float(v) for v in text.split(","))
    except ValueError:
        edges = ()
    if len(edges) != 3 or min(edges) <= 0:
        raise InputError(f"--large: three positive cell counts LX,LY,LZ, e.g. 192,48,40 (got {text!r})")
    return edges


def _case(nbodies, edge, pitch, precision, operator, target, large=None, film=True):
    from iceresist.coupling import Box, FluidStructureCoupling
    from iceresist.units import Units
    from iceresist.dem import DEMSystem, box
    from iceresist.grid.forest import BlockForest
    from iceresist.lbm.solver import LBMSolver

    per = int(math.ceil(nbodies ** (1 / 3)))
    side = int(math.ceil(per * pitch / 8) * 8)
    shape = [side] * 3
    if large is not None:
        shape = [max(side, int(math.ceil((n + 16) / 8) * 8)) for n in large]
    fo = BlockForest.uniform(tuple(shape))
    solver = LBMSolver(fo, tau=0.6, operator=operator, precision=precision, target=target)
    solver.initialize()
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    rng = np.random.default_rng(1)
    idx = np.stack(np.meshgrid(*(np.arange(per),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)[:nbodies]
    for i, j, k in idx:
        dem.add_body(box((edge,) * 3, 900.0), position_m=(pitch * (np.array([i, j, k]) + 0.5)),
                     velocity_m_s=rng.normal(0, 0.02, 3), angular_velocity_rad_s=rng.normal(0, 0.005, 3),
                     kinematic=True)
    geometries = [Box((edge,) * 3)] * nbodies
    if large is not None:
        dem.add_body(box(large, 900.0), position_m=np.array(shape) / 2 + 0.3, velocity_m_s=(0.02, 0.0, 0.0),
                     kinematic=True)
        geometries.append(Box(large))
    cp = FluidStructureCoupling(solver, dem, geometries, Units.lattice(tau=solver.tau),
                                contact_film=film)
    return fo, solver, dem, cp


def run(args) -> list[dict]:
    from iceresist.backends import jit
    from iceresist.coupling.coupler import TILE_CELLS

    target = jit.resolve_backend(args.backend)
    large = None if args.large is None else _large_edges(args.large)
    rows = []
    for precision, nb, tile in ((p, n, t) for p in args.precision or ["float32"] for n in args.bodies or [100, 1000]
                                for t in args.tile_cells or [TILE_CELLS]):
        t0 = time.perf_counter()
        fo, solver, dem, cp = _case(nb, args.edge, args.pitch, precision, args.operator, target, large,
                                    film=not args.no_film)
        cp.tile_cells = tile if tile > 0 else 2 ** 62
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
                     "compile_seconds": compile_s, "large_box_cells": None if large is None else list(large),
                     "tile_cells": tile, "contact_film": not args.no_film,
                     "launch_rows": nb + (large is not None) if cp._tile_body is None
                     else len(cp._tile_body)})
    return rows
