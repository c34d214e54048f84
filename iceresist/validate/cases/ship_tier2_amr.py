"""The ship in brash ice, tier 2 on two refined levels: mean ice resistance against the finest cell size (block AMR).

Case A-c68-v1.0 (Bow A, 68 % brash ice, 1 knot) through :class:`iceresist.models.tier2.Tier2Model` on levels
with the refinement of the ``quick`` preset's ``[tier2.quick.amr]`` (the surface band and the band about the hull and
every ice piece on level 1, the deep water on level 0, the band following the bodies): rungs at 3, 4.5, 6 and 9
cells per 41 mm cube on the finest level (the issue's 3, 4.5 and 6, and 9 where time allows), level 0 twice as
coarse. One tank on every rung: 128 x 32 cubes (5.248 x 1.312 m, against the preset's 5.13 x 1.39 m), the smallest
in whole level-0 blocks at all four (a block is 16 / n cubes at n cells per cube), water 0.93 m deep (the preset's on
levels); only the lid moves, to the first level-0 block face at least 30 mm (the preset's surface band) above the
water, so the gas above the surface (0.05 to 0.16 m) differs between rungs. The DEM (hull spheres, cube clumps, contact law) is the
same on every rung, the record interval fixed in seconds to whole level-0 steps (2, 3, 4, 6 steps of 1.81 ms to
0.60 ms: 3.6 ms), the bands at least 2.5 finest cells about the bodies and 8 about the surface (what the start's
checks ask for), so the finest level also holds one more level-0 layer under the surface at 3 and 4.5 cells per
cube.

This is a GPU ladder (``iceresist validate --full --cases ship_tier2_amr --backend cuda``): its rungs hold 1.6e6 to
3.3e7 leaf cells and take 4.8e9 to 2.8e11 cell updates (:meth:`Tier2Model.plan` counts them without building);
the quick ladder has no rungs on levels (the CI-sized tank of ``ship_tier2`` is narrower than one level-0 block
at 4.5 cells per cube). As for ``ship_tier2``, there is no external reference: :mod:`iceresist.validate.ladder`
measures the error against the Richardson extrapolation of the three finest rungs where they converge monotonically,
else against the finest rung; the headline is the mean ice (contact) force on the hull in the steady window.
"""

from __future__ import annotations

import math

from iceresist.scene.case_scenes import case_scene
from iceresist.ship.cases import REFINEMENT_KEYS, amr_overrides
from iceresist.validate.cases.ship_tier2 import run_rung
from iceresist.validate.result import CaseResult

NAME = "ship_tier2_amr"
REFERENCE = ("no measurement at these sizes: the Richardson extrapolation of the three finest rungs (observed "
             "order from the three), else the finest rung, of the mean ice (contact) force on the hull in the "
             "steady window (case A-c68-v1.0, tier 2 coupled LBM-DEM on two refined levels)")
CASE = "A-c68-v1.0"
CUBE_M = 0.041
#: Cells per cube on the finest level, one rung each.
CELLS_PER_CUBE = (3.0, 4.5, 6.0, 9.0)
#: The tank's length and width in cubes: whole level-0 blocks (16 / n cubes) at every rung.
TANK_CUBES = (128, 32)
#: Water depth (m), the ``quick`` preset's on levels.
WATER_DEPTH_M = 0.93
#: Level-0 steps per record on the coarsest rung (the record interval, in seconds, the same on every rung).
STEPS_PER_RECORD_COARSEST = 2
#: The band about the bodies in finest cells at least (the start asks for two cells to spare).
BODY_BAND_CELLS = 2.5
#: The ice arrangements of every rung: the channel's cubes moved by random offsets of up to half the gap, one run per
#: seed, the rung's mean and interval over all of them (the pooled batch means of their steady windows, so the
#: interval holds the spread between arrangements). On the regular arrangement the force's correlation time was
#: 0.10 s, a window (0.8 m of travel) about 15 of them and its interval from 5 batches; on a random one 0.015 s
#: (3 cells per cube, seed 0).
ICE_ARRANGEMENT = "random"
SEEDS = (0, 1, 2, 3, 4)
#: The band about the surface in finest cells at least (the start asks for the surface 8 finest cells or more from the
#: finest level's edge: :class:`~iceresist.freesurface.refined.RefinedFreeSurface`).
SURFACE_BAND_CELLS = 8.0


def rung(n: float) -> dict:
    """The parameters of the rung with ``n`` cells per cube on the finest level: level-0 cells and dx, the water depth,
    the bands, the record interval's steps."""
    ref = amr_overrides("quick")["refinement"]
    dx0 = 2.0 * CUBE_M / n
    block_m = 8.0 * dx0
    nx, ny = (c * n / 2.0 for c in TANK_CUBES)
    if abs(nx - round(nx)) > 1e-9 or abs(ny - round(ny)) > 1e-9 or round(nx) % 8 or round(ny) % 8:
        raise ValueError(f"{n:g} cells per cube: the tank of {TANK_CUBES} cubes is not whole level-0 blocks")
    lid_blocks = math.ceil((WATER_DEPTH_M + ref["surface_band_m"]) / block_m - 1e-9)
    steps = STEPS_PER_RECORD_COARSEST * n / CELLS_PER_CUBE[0]
    # the seeds in the label: a ladder.csv row (which a ladder run again skips) or rung folder of a single
    # arrangement is not taken for a rung of several
    return {"label": f"{n:g} cells/cube on level 1 ({int(round(nx))}x{int(round(ny))}x{8 * lid_blocks} level 0), "
                     f"{len(SEEDS)} ice seeds",
            "resolution": n, "cells": [int(round(nx)), int(round(ny)), 8 * lid_blocks], "dx_m": dx0,
            "water_depth_m": WATER_DEPTH_M, "levels": int(ref["levels"]),
            "surface_band_m": max(ref["surface_band_m"], SURFACE_BAND_CELLS * dx0 / 2.0),
            "body_band_m": max(ref["body_band_m"], BODY_BAND_CELLS * dx0 / 2.0),
            **{k: ref[k] for k in ("regrid_every_steps", "regrid_slack", "regrid_lookahead_steps")},
            "steps_per_record": int(round(steps))}


def ladder(quick: bool) -> list[dict]:
    """The four rungs of the full ladder; none on the quick one (module docstring)."""
    return [] if quick else [rung(n) for n in CELLS_PER_CUBE]


def overrides(params: dict) -> dict:
    """Scene overrides of one rung: the level-0 tank and cell size, the water depth, the refinement, and the record
    interval fixed in seconds (``steps_per_record`` level-0 steps of the rung, a hair under so that the ceiling in
    the model gives them exactly)."""
    ov = {"domain": {"cells": list(params["cells"]), "dx_m": float(params["dx_m"])},
          "free_surface": {"water_depth_m": float(params["water_depth_m"])},
          "ice": {"arrangement": ICE_ARRANGEMENT},
          "refinement": {k: params[k] for k in REFINEMENT_KEYS}}
    dt_s = case_scene(CASE, "quick", 2, **ov).units().dt_s
    ov["contact"] = {"sample_interval_s": int(params["steps_per_record"]) * dt_s * (1.0 - 1e-7)}
    return ov


def scene(params: dict):
    """The validated scene of one rung."""
    return case_scene(CASE, "quick", 2, **overrides(params))


def run(params: dict, *, backend: str = "cuda", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung, a run per seed of :data:`SEEDS` (:func:`iceresist.validate.cases.ship_tier2.run_rung`; a killed
    run continues from its checkpoint, a finished one is read back); its steps are level-0 steps."""
    return run_rung(NAME, params, overrides(params), backend=backend, precision=precision, out_dir=out_dir,
                    seeds=SEEDS, dx_finest_m=CUBE_M / float(params["resolution"]))
