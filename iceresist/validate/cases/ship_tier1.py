"""The ship in brash ice, tier 1 (DEM with water models): mean ice resistance against the hull's sphere spacing.

Case A-c68-v1.0 (Bow A, 68 % brash ice, 1 knot). The hull is a clump of spheres on its faces
(:func:`iceresist.ship.from_scene.hull_shape`); the rung refines their spacing, the resolution of the hull surface the ice
touches. Quick ladder: the CI-sized channel of :data:`iceresist.sweep.TINY_OVERRIDES` (0.3 m of ice, 0.75 s);
full ladder: the ``quick`` fidelity of :mod:`iceresist.scene.case_scenes` (1.39 m of ice). The headline quantity is the
mean ice force in the steady window (:func:`iceresist.post.ice_resistance_from_timeseries`, as in
``iceresist sweep``). There is no external reference: ``reference`` is NaN and :mod:`iceresist.validate.ladder`
measures the error against the Richardson extrapolation of the three finest rungs (Roache 1998) where they
converge monotonically, else against the finest rung. Tier 2 (coupled LBM-DEM) has no ship model yet, so the
ladder holds tier-1 rungs only.
"""

from __future__ import annotations

import copy
import time

from iceresist.post.case import analyse_case
from iceresist.scene.case_scenes import case_scene
from iceresist.sweep import TINY_OVERRIDES, run_case
from iceresist.validate.result import CaseResult
from iceresist.validate.rung import rung_folder

NAME = "ship_tier1"
REFERENCE = ("no measurement at these sizes: the Richardson extrapolation of the three finest rungs (observed "
             "order from the three), else the finest rung, of the mean ice force in the steady window "
             "(case A-c68-v1.0, tier 1; tier 2 has no ship model yet)")
CASE = "A-c68-v1.0"


def ladder(quick: bool) -> list[dict]:
    """Hull sphere spacing 50/35/25 mm on the 0.3 m channel (quick), 40/28/20 mm on the 1.39 m channel (full)."""
    spacings = (0.05, 0.035, 0.025) if quick else (0.04, 0.028, 0.02)
    beam = beam_m()
    return [{"label": f"hull spheres {1e3 * s:g} mm", "resolution": beam / s, "spacing_m": s, "tier": 1,
             "tiny": quick} for s in spacings]


def beam_m() -> float:
    return float(case_scene(CASE, "quick", 1).ship.beam_m)


def overrides(params: dict) -> dict:
    ov = copy.deepcopy(TINY_OVERRIDES) if params.get("tiny", True) else {}
    ov.setdefault("ship", {})["sphere_spacing_m"] = float(params["spacing_m"])
    return ov


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One tier-1 run through :func:`iceresist.sweep.run_case` into ``OUT/runs/NAME/LABEL/`` (a scratch folder
    without ``out_dir``); the DEM runs in float64, as every tier-1 run: ``precision`` is recorded, not used."""
    with rung_folder(out_dir, NAME, params["label"]) as tmp:
        t0 = time.perf_counter()
        path = run_case(CASE, "quick", 1, tmp, backend=backend, overrides=overrides(params))
        total = time.perf_counter() - t0
        row = analyse_case(path)
    return CaseResult(case=NAME, label=params["label"], resolution=float(params["resolution"]),
                      cells=int(row["spheres"]), steps=int(row["dem_substeps"]), wall_s=float(row["wall_time_s"]),
                      quantity="mean ice force in the steady window (N, model scale)",
                      value=float(row["mean_force_N"]), reference=float("nan"), error=float("nan"),
                      backend=backend, precision=precision,
                      extra={"dem_precision": "float64", "ci95_N": float(row["ci95_N"]), "records": int(row["steps"]), "total_s": total,
                             "R_sim_kN": float(row["R_sim_kN"])})
