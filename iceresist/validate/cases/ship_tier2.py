"""The ship in brash ice, tier 2 (coupled LBM-DEM with free surface): mean ice resistance against the cell size.

Case A-c68-v1.0 (Bow A, 68 % brash ice, 1 knot) through :class:`iceresist.models.tier2.Tier2Model`. The rung refines the
lattice cell dx in a fixed physical tank (the cells of every axis scaled together, whole 8x8x8 blocks), so the
cubes, the hull's wetted shape and the free surface are resolved more finely; the DEM (hull sphere spacing, cube
clumps, contact law) is the same on every rung. The record interval is fixed in seconds to a whole number of LBM
steps on every rung (4, 6, 8 steps on the quick ladder, 2, 3, 4 on the full one), so each rung averages the
contact force over the same time samples.

* Quick ladder: the CI-sized tank of :data:`iceresist.sweep.TINY_TIER2_OVERRIDES` (0.875 x 0.219 x 0.219 m,
  0.48 m hull, 4 cubes, 0.06 s) at 64x16x16, 96x24x24 and 128x32x32 cells: 3, 4.5 and 6 cells per 41 mm cube.
* Full ladder: the ``quick`` tier-2 preset of :mod:`iceresist.scene.case_scenes` (68 % channel of 1.39 m, water
  0.9 m deep) in a tank of whole multiples of eight cubes (5.248 x 1.312 x 0.984 m, against the preset's
  5.13 x 1.39 x 1.07 m, so that every rung fills whole blocks) at 2, 3 and 4 cells per cube (256x64x48 to
  512x128x96 cells): a GPU ladder.

The headline quantity is the mean ice (DEM contact) force on the hull in the steady window
(:func:`iceresist.post.ice_resistance_from_timeseries`, as in ``iceresist sweep``; water resistance excluded, as
the paper's section 4.2), in N at model scale; the mean fluid force on the hull over the run is kept in ``extra``.
There is no external reference: ``reference`` is NaN and :mod:`iceresist.validate.ladder` measures the error
against the Richardson extrapolation of the three rungs (Roache 1998) where they converge monotonically, else
against the finest rung. On the quick ladder the steady window holds 8 records of a contact force that comes in
a few impacts, so its 95 % interval (``extra["ci95_N"]``, about 2 N) exceeds the mean (about 1.5 N): the
differences between its rungs are sampling noise, not discretisation error, and the ladder measures the
protocol and the cost per rung, not a converged order. The full ladder's window is about 0.8 m of travel.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from iceresist.io.hdf5 import RunFile
from iceresist.post.case import analyse_case, analyse_ensemble
from iceresist.post.scaling import force_to_full_scale
from iceresist.scene.case_scenes import case_scene
from iceresist.sweep import TINY_TIER2_OVERRIDES, run_case
from iceresist.validate.result import CaseResult
from iceresist.validate.rung import rung_folder

NAME = "ship_tier2"
REFERENCE = ("no measurement at these sizes: the Richardson extrapolation of the three finest rungs (observed "
             "order from the three), else the finest rung, of the mean ice (contact) force on the hull in the "
             "steady window (case A-c68-v1.0, tier 2 coupled LBM-DEM)")
CASE = "A-c68-v1.0"
CUBE_M = 0.041
#: Quick ladder: the tank of TINY_TIER2_OVERRIDES (64 x 16 x 16 cells of 41/3 mm) and its cells per rung.
QUICK_TANK_CELLS_AT_3 = (64, 16, 16)
QUICK_CELLS = ((64, 16, 16), (96, 24, 24), (128, 32, 32))
#: Full ladder: the tank in cubes (multiples of 8, so that 2, 3 and 4 cells per cube fill whole blocks).
FULL_TANK_CUBES = (128, 32, 24)
FULL_CELLS_PER_CUBE = (2, 3, 4)
#: LBM steps per record on the coarsest rung, quick and full (the record interval in seconds is the same on every
#: rung: 4.66 ms quick, 3.50 ms full, near the presets' 4 ms).
STEPS_PER_RECORD_COARSEST = {True: 4, False: 2}


def ladder(quick: bool) -> list[dict]:
    """Three cell sizes in one tank: 3, 4.5, 6 cells per cube (quick), 2, 3, 4 cells per cube (full)."""
    if quick:
        dx0 = CUBE_M / 3.0
        width_m = QUICK_TANK_CELLS_AT_3[1] * dx0
        rungs = [(c, width_m / c[1]) for c in QUICK_CELLS]
    else:
        rungs = [(tuple(k * n for k in FULL_TANK_CUBES), CUBE_M / n) for n in FULL_CELLS_PER_CUBE]
    out = []
    for cells, dx in rungs:
        n = CUBE_M / dx
        out.append({"label": f"{n:g} cells/cube ({cells[0]}x{cells[1]}x{cells[2]})", "resolution": n,
                    "cells": list(cells), "dx_m": dx, "tier": 2, "tiny": quick,
                    "coarsest_dx_m": rungs[0][1], "coarsest_steps_per_record": STEPS_PER_RECORD_COARSEST[quick]})
    return out


def overrides(params: dict) -> dict:
    """Scene overrides of one rung: the tank and cell size, and the record interval fixed in seconds."""
    ov = copy.deepcopy(TINY_TIER2_OVERRIDES) if params.get("tiny", True) else {}
    ov["domain"] = {"cells": [int(c) for c in params["cells"]], "dx_m": float(params["dx_m"])}
    # the LBM step is proportional to dx (the Mach rule of iceresist.models.tier2): take the coarsest rung's step
    coarse = copy.deepcopy(ov)
    coarse["domain"] = {**ov["domain"], "dx_m": float(params["coarsest_dx_m"])}
    lbm_dt_s = case_scene(CASE, "quick", 2, **coarse).units().dt_s
    # a hair under a whole number of steps, so the ceiling in Tier2Model gives 4, 6, 8 ... steps exactly
    steps = int(params["coarsest_steps_per_record"])
    ov.setdefault("contact", {})["sample_interval_s"] = steps * lbm_dt_s * (1.0 - 1e-7)
    return ov


#: (backend, precision) pairs whose kernels this process has compiled (see :func:`warm_up`).
_WARM: set = set()


def warm_up(backend: str, precision: str) -> float:
    """Compile the tier-2 kernels once per process with one record of the coarsest quick rung, so that the
    ``wall_s`` of a rung is its stepping alone (the kernels are specialised on types, not on the grid size).
    Returns the seconds spent (0 when already warm)."""
    if (backend, precision) in _WARM:
        return 0.0
    ov = overrides(ladder(True)[0])
    ov.setdefault("numerics", {})["precision"] = precision
    ov["run"] = {"end_time_s": ov["contact"]["sample_interval_s"]}
    t0 = time.perf_counter()
    with rung_folder(None, NAME, "warm-up") as tmp:
        run_case(CASE, "quick", 2, tmp, backend=backend, overrides=ov)
    _WARM.add((backend, precision))
    return time.perf_counter() - t0


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One tier-2 run through :func:`iceresist.sweep.run_case` into ``OUT/runs/NAME/LABEL/`` (a scratch folder
    without ``out_dir``; a killed rung continues from its checkpoint) (the LBM in ``precision``,
    the DEM in float64), after :func:`warm_up` (its seconds in ``extra["compile_s"]``)."""
    compile_s = warm_up(backend, precision)
    return run_rung(NAME, params, overrides(params), backend=backend, precision=precision, out_dir=out_dir,
                    compile_s=compile_s)


def run_rung(name: str, params: dict, ov: dict, *, backend: str, precision: str, out_dir, seeds=None,
             **extra) -> CaseResult:
    """Case A-c68-v1.0 at the quick fidelity, tier 2, with the scene overrides ``ov`` (the LBM in ``precision``),
    through :func:`iceresist.sweep.run_case` into ``OUT/runs/NAME/LABEL/`` (a scratch folder without ``out_dir``),
    as a :class:`CaseResult` (:func:`case_result`, ``extra`` added). ``seeds``: one run per ice seed in turn, into
    ``LABEL/seed-N/``, the result over all of them (:func:`ensemble_result`). A run finished there before (the
    same scene) is read back, not run again."""
    ov.setdefault("numerics", {})["precision"] = precision
    with rung_folder(out_dir, name, params["label"]) as tmp:
        t0 = time.perf_counter()
        if seeds is None:
            path = run_case(CASE, "quick", 2, tmp, backend=backend, overrides=ov, reuse_finished=True)
            return case_result(name, params, path, backend=backend, precision=precision,
                               total_s=time.perf_counter() - t0, **extra)
        paths = []
        for seed in seeds:
            ov_seed = copy.deepcopy(ov)
            ov_seed.setdefault("ice", {})["seed"] = int(seed)
            paths.append(run_case(CASE, "quick", 2, tmp / f"seed-{int(seed)}", backend=backend, overrides=ov_seed,
                                  reuse_finished=True))
        return ensemble_result(name, params, paths, backend=backend, precision=precision,
                               total_s=time.perf_counter() - t0, **extra)


def ensemble_result(name: str, params: dict, paths, *, backend: str, precision: str, total_s: float,
                    **extra) -> CaseResult:
    """The :class:`CaseResult` of one rung run from several ice arrangements (finished files ``paths``,
    :func:`iceresist.post.case.analyse_ensemble`): the mean ice force over all their steady windows and the
    interval of their pooled batch means; the records, steps and wall time of all runs; each run's mean and
    interval in ``extra``."""
    ens = analyse_ensemble(paths)
    rows = ens["runs"]
    return _rung_result(name, params, paths, rows, ens["mean_force_N"], ens["ci95_N"], backend=backend,
                        precision=precision, total_s=total_s, ci_method=ens["ci_method"],
                        n_batches=int(ens["n_batches"]), seeds=len(paths),
                        # each run's mean and its own interval (a table cell each: space-separated)
                        run_means_N=" ".join(f"{v:.4g}" for v in ens["run_means_N"]),
                        run_ci95_N=" ".join(f"{float(r['ci95_N']):.4g}" for r in rows),
                        tau_int_s=float(ens["tau_int_s"]), **extra)


def case_result(name: str, params: dict, path, *, backend: str, precision: str, total_s: float,
                **extra) -> CaseResult:
    """The :class:`CaseResult` of one finished tier-2 run file ``path`` (:func:`iceresist.post.case.analyse_case`):
    the mean ice force in the steady window, its interval, the records and steps (LBM steps: level-0 steps on
    levels), the mean fluid force on the hull; ``extra`` added."""
    row = analyse_case(path)
    return _rung_result(name, params, [path], [row], row["mean_force_N"], row["ci95_N"], backend=backend,
                        precision=precision, total_s=total_s, **extra)


def _rung_result(name: str, params: dict, paths, rows, value: float, ci95: float, *, backend: str, precision: str,
                 total_s: float, **extra) -> CaseResult:
    """A rung's :class:`CaseResult` from its finished run files ``paths`` and their rows ``rows``
    (:func:`iceresist.post.case.analyse_case`): ``value`` and ``ci95`` the mean ice force and its interval; the
    records, LBM steps (level-0 steps on levels) and wall time of all runs, their mean fluid force on the hull."""
    fluid = []
    for path in paths:
        with RunFile(path, "r") as rf:
            fluid.extend(rf.h5["timeseries/Fx_fluid_N"][1:])   # row 0 is the state before the first step
            model = rf.meta_object("model")
    per_record = int(model["lbm_steps_per_record"])
    records = sum(int(r["steps"]) for r in rows)
    first = rows[0]
    return CaseResult(case=name, label=params["label"], resolution=float(params["resolution"]),
                      cells=int(first["cells"]), steps=records * per_record,
                      wall_s=sum(float(r["wall_time_s"]) for r in rows),
                      quantity="mean ice (contact) force on the hull in the steady window (N, model scale)",
                      value=float(value), reference=float("nan"), error=float("nan"),
                      backend=backend, precision=precision,
                      extra={"dem_precision": "float64", "ci95_N": float(ci95), "records": records,
                             "lbm_steps_per_record": per_record, "total_s": total_s,
                             "dx_m": float(first["resolution_m"]),
                             "R_sim_kN": float(force_to_full_scale(value, first["scale"])) / 1e3,
                             "mean_fluid_Fx_N": float(np.mean(fluid)) if fluid else float("nan"), **extra})
