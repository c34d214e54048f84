"""The stability matrix of ``iceresist validate --stability``: every extreme setting runs stable or is refused.

Each row is one setting along one axis (DEM stiffness, tau - 1/2 per operator, lattice Mach, ship speed, ice
concentration, ice density, time step, and settings beyond the measured limits with ``numerics.check_limits =
false``). A row ends in one of three outcomes:

* ``refused``: a pre-run limit (:mod:`iceresist.limits`, :mod:`iceresist.units`, the scene schema) refused the
  scene before anything ran, with a one-line message naming the key, the limit and a value that works;
* ``stopped by watchdog``: the run watchdog (:mod:`iceresist.watchdog`) stopped it, the diagnostic is in
  ``cases/<row>.watchdog.json`` and the result file stays readable;
* ``stable``: it ran to its end with a finite, bounded kinetic energy and (fluid) its mass kept.

A run that ends in none of these (finishes with NaN, energy blown up or mass lost) is reported as
``unstable (not caught)``: the tests assert there is none.

:func:`measure_operator_limits` is the measurement behind :data:`iceresist.limits.CELL_REYNOLDS_MAX`.
"""

from __future__ import annotations

import argparse
import copy
import json
import logging
import math
import tempfile
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iceresist.driver import Outputs, Stop, run_model
from iceresist.errors import InputError
from iceresist.limits import touching_concentration
from iceresist.models import build_model
from iceresist.scene.case_scenes import KNOT_M_S, scene_data, to_toml
from iceresist.scene.load import parse_scene, preset_text
from iceresist.simulation import IterationInterval
from iceresist.validate.cases.taylor_green import vortex
from iceresist.validate.rung import scene_of

log = logging.getLogger(__name__)

OUTCOMES = ("stable", "refused", "stopped by watchdog")
NOT_CAUGHT = "unstable (not caught)"
#: Relative fluid-mass change a stable run may show (float32 round-off over a few hundred steps).
MASS_TOLERANCE = 1e-4
#: Steps a fluid row runs (quick, full).
FLUID_STEPS = {True: 300, False: 2000}
#: Steps of the rows beyond the limits (long enough for them to blow up).
BEYOND_STEPS = {True: 1000, False: 3000}
#: Simulated time of a tier-1 row (s): quick, full.
TIER1_END_S = {True: 0.12, False: 0.5}


@dataclass
class Setting:
    """One row of the matrix: ``axis``, a short ``label`` of the setting, its ``value`` and the scene data."""

    axis: str
    label: str
    value: float
    kind: str          #: "fluid" or "tier1"
    data: dict         #: scene sections (TOML-like dict)
    steps: int | None = None  #: cap on the steps actually run (the limits see the whole scene)


# -- scenes ---------------------------------------------------------------------------------------------
def _cavity(quick: bool, *, lid: float = 0.05, tau: float = 0.6, operator: str = "cumulant", mach=None,
            check: bool = True) -> dict:
    d = tomllib.loads(preset_text("cavity"))
    d["domain"]["faces"]["z_max"] = {"kind": "moving_wall", "velocity_m_s": [lid, 0.0, 0.0]}
    d["fluid"].pop("nu_m2_s", None)
    d["fluid"]["operator"] = operator
    d["numerics"].update({"tau": tau, "backend": "cpu", "check_limits": check})
    if mach is not None:
        d["numerics"]["mach"] = mach
    d["run"] = {"steps": FLUID_STEPS[quick]}
    d["output"] = {"fields": [], "timeseries_every_steps": 50}
    return d


def _poiseuille(dt_s=None) -> dict:
    d = tomllib.loads(preset_text("poiseuille"))
    d["numerics"]["backend"] = "cpu"
    if dt_s is not None:
        d["numerics"]["dt_s"] = dt_s
    d["output"] = {"fields": [], "timeseries_every_steps": 50}
    return d


def _tier1(quick: bool, *, knots: float = 1.0, **overrides) -> dict:
    """A micro tier-1 scene: the quick B-063 case, a 0.1 m long channel (2 x 28 cubes), the stem 2 cm before it."""
    d = scene_data("A-c68-v1.0", "quick", 1)
    d["ice"].update({"channel_length_m": 0.1 if quick else 0.3})
    d["ship"].update({"start_x_m": 3.98, "sphere_band_m": 0.03, "sphere_spacing_m": 0.05,
                      "speed_m_s": round(knots * KNOT_M_S, 6), "steady_window_m": [4.0, 4.1]})
    d["contact"].update({"sample_interval_s": 0.002})
    d["run"] = {"end_time_s": TIER1_END_S[quick]}
    d["numerics"]["backend"] = "cpu"
    for section, values in overrides.items():
        d.setdefault(section, {}).update(values)
    return d


def settings(quick: bool = True) -> list[Setting]:
    """The rows of the matrix, axis by axis."""
    rows: list[Setting] = []
    k0 = _tier1(quick)["contact"]["stiffness_N_m"]
    for f in (1, 10, 100, 1000):
        rows.append(Setting("DEM stiffness", f"k x {f}", k0 * f, "tier1",
                            _tier1(quick, contact={"stiffness_N_m": k0 * f})))
    for op, excesses in (("cumulant", (1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-9)),
                         ("bgk", (1e-1, 1e-2, 1e-4, 1e-6))):
        for e in excesses:
            rows.append(Setting(f"tau - 1/2 ({op})", f"{e:.0e}", e, "fluid",
                                _cavity(quick, tau=0.5 + e, operator=op)))
    for lid in (0.05, 0.1, 0.2, 0.3, 0.35):
        rows.append(Setting("lattice Mach (cumulant)", f"u = {lid:g}", lid, "fluid",
                            _cavity(quick, lid=lid, tau=0.7, mach=lid)))
    for kn in (1.0, 2.0, 3.0, 4.0):
        rows.append(Setting("ship speed (knots)", f"{kn:g} kn", kn, "tier1", _tier1(quick, knots=kn)))
    d = _tier1(quick)
    c_touch = touching_concentration(d["domain"]["size_m"][1], d["ice"]["channel_length_m"], 0.041)
    for c in (0.5, 0.68, 0.88, c_touch, 1.0):
        rows.append(Setting("ice concentration", f"{100 * c:.1f} %", c, "tier1",
                            _tier1(quick, ice={"concentration": c})))
    for rho in (900.0, 950.0, 990.0, 999.0, 1000.0, 1020.0):
        rows.append(Setting("ice density (kg/m^3)", f"{rho:g}", rho, "tier1",
                            _tier1(quick, ice={"density_kg_m3": rho})))
    for dt in (1e-1, 1e-2, 1e-4, 1e-6, 1e-9):
        rows.append(Setting("fluid time step (s)", f"dt = {dt:.0e} s", dt, "fluid", _poiseuille(dt),
                            steps=FLUID_STEPS[quick]))
    for dt in (1e-6, 2e-3, 1e-1):
        rows.append(Setting("tier-1 record interval (s)", f"{dt:.0e} s", dt, "tier1",
                            _tier1(quick, contact={"sample_interval_s": dt})))
    for op, e in (("bgk", 1e-3), ("cumulant", 1e-4)):
        d = _cavity(quick, lid=0.1, tau=0.5 + e, operator=op, check=False)
        d["run"]["steps"] = BEYOND_STEPS[quick]
        rows.append(Setting("beyond the limits (tau - 1/2, lid 0.1, check_limits = false)", f"{op} {e:.0e}", e,
                            "fluid", d))
    return rows


# -- one row --------------------------------------------------------------------------------------------
def _slug(s: Setting, i: int) -> str:
    keep = "".join(ch if ch.isalnum() else "_" for ch in f"{s.axis}_{s.label}")
    return f"{i:02d}_{keep.strip('_')[:60]}"


def run_setting(s: Setting, out_dir: Path, name: str, *, backend: str = "cpu") -> dict:
    """Build, run and classify one setting; returns its row."""
    row = {"axis": s.axis, "setting": s.label, "value": s.value, "outcome": "", "message": "",
           "dem_substeps": np.nan, "dem_substep_s": np.nan, "steps": 0, "wall_s": 0.0,
           "kinetic_energy_final": np.nan, "mass_drift": np.nan}
    t0 = time.perf_counter()
    data = copy.deepcopy(s.data)
    data.setdefault("scene", {})["name"] = name
    try:
        scene = parse_scene(to_toml(data), f"{name}.toml")
        model = build_model(scene, backend=backend)
    except InputError as exc:
        row.update(outcome="refused", message=str(exc).removeprefix(f"{name}.toml: "), wall_s=time.perf_counter() - t0)
        return row
    if s.kind == "tier1":
        row.update(dem_substeps=int(model.substeps_per_step), dem_substep_s=float(model.substep_s))
    cases = Path(out_dir) / "cases"
    cases.mkdir(parents=True, exist_ok=True)
    h5 = cases / f"{name}.h5"
    stop_it = scene.run.steps
    if s.steps is not None:
        stop_it = s.steps if stop_it is None else min(stop_it, s.steps)
    end_s = scene.run.end_time_s if s.steps is None else None
    mass0 = model.lbm.solvers[0].mass() if s.kind == "fluid" else None
    outputs = Outputs(timeseries=IterationInterval(scene.output.timeseries_every_steps), checkpoint=None,
                      checkpoint_final=False, watchdog_every=50 if s.kind == "fluid" else 5)
    result = run_model(model, scene, h5, None, stop=Stop(iteration=stop_it, time_s=end_s), outputs=outputs,
                       meta={"setting": s.label, "axis": s.axis}, progress=False)
    sim, dog = result.sim, result.watchdog
    row["steps"] = int(sim.steps_done)
    row["wall_s"] = time.perf_counter() - t0
    if dog.report is not None:
        row.update(outcome="stopped by watchdog", message=sim.stop_reason)
        return row
    probe = model.watchdog_probe()
    ke = float(probe.get("kinetic_energy", np.nan))
    ref = float(probe.get("kinetic_energy_ref", np.inf))
    row["kinetic_energy_final"] = ke
    problems = []
    if sim.diverged or not probe["finite"][0]:
        problems.append(sim.stop_reason or "NaN in the state")
    if not (math.isfinite(ke) and ke <= 10.0 * max(ref, 0.0) + 1e-300):
        problems.append(f"kinetic energy {ke:.3g} above 10 x the reference {ref:.3g}")
    if mass0 is not None:
        drift = abs(model.lbm.solvers[0].mass() - mass0) / mass0
        row["mass_drift"] = drift
        if not drift <= MASS_TOLERANCE:
            problems.append(f"mass changed by {drift:.2e} (tolerance {MASS_TOLERANCE:.0e})")
    if problems:
        row.update(outcome=NOT_CAUGHT, message="; ".join(problems))
    else:
        row.update(outcome="stable", message=sim.stop_reason or "")
    return row


def run_stability_matrix(out_dir, quick: bool = True, backend: str = "cpu"):
    """Run every setting of :func:`settings` into ``out_dir`` (``cases/``, ``stability.csv``); returns the table.

    Columns: axis, setting, value, outcome (stable | refused | stopped by watchdog), message, dem_substeps
    (per record; tier-1 rows), dem_substep_s, steps, wall_s, kinetic_energy_final, mass_drift.
    """
    import pandas as pd

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, s in enumerate(settings(quick)):
        row = run_setting(s, out, _slug(s, i), backend=backend)
        log.info("stability %-40s %-28s %-20s %.1f s", s.axis, s.label, row["outcome"], row["wall_s"])
        rows.append(row)
    df = pd.DataFrame(rows)
    df.to_csv(out / "stability.csv", index=False)
    return df


def markdown_table(df) -> str:
    """The matrix as a Markdown table (docs/VALIDATION.md), written by pandas (``DataFrame.to_markdown``)."""
    import pandas as pd

    df = df.reset_index(drop=True)
    shown = pd.DataFrame({
        "axis": df["axis"], "setting": df["setting"], "outcome": df["outcome"],
        "DEM sub-steps per record": ["" if pd.isna(n) else f"{int(n)} x {dt:.2e} s"
                                     for n, dt in zip(df["dem_substeps"], df["dem_substep_s"])],
        "message": df["message"].astype(str).str.replace("|", "/", regex=False)})
    return shown.to_markdown(index=False, disable_numparse=True)


# -- the measurement behind the operator limits ---------------------------------------------------------
def _limit_scene(operator: str, case: str, u0: float, tau_excess: float, n: int, steps: int):
    """The scene of one point of :func:`measure_operator_limits` (lattice units, float32, the operator limits off,
    ``numerics.mach`` at the speed): an ``n``^3 lid-driven cavity (lid speed ``u0``) or a periodic box for the
    Taylor-Green vortex (amplitude ``u0``, set on the model), tau = 1/2 + ``tau_excess``."""
    sides = ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")
    if case == "cavity":
        faces = {f: "wall" for f in sides}
        faces["z_max"] = {"kind": "moving_wall", "velocity_m_s": [u0, 0.0, 0.0]}
    else:
        faces = {f: "periodic" for f in sides}
    name = f"limits-{operator}-{case}"
    return scene_of({"scene": {"name": name, "units": "lattice"}, "domain": {"cells": [n, n, n], "faces": faces},
                     "fluid": {"operator": operator},
                     "numerics": {"tau": 0.5 + tau_excess, "u_max_m_s": u0, "mach": max(u0, 0.1),
                                  "precision": "float32", "backend": "cpu", "check_limits": False},
                     "run": {"steps": steps}, "output": {"fields": [], "timeseries_every_steps": 100}},
                    f"{name} u {u0:g} tau-1/2 {tau_excess:g}")


def measure_operator_limits(operators=("cumulant", "bgk"), speeds=(0.02, 0.05, 0.1, 0.2, 0.3),
                            excesses=(1e-1, 3e-2, 1e-2, 3e-3, 1e-3, 1e-4, 1e-5, 1e-6), *, n: int = 16,
                            steps: int = 1000, cases=("cavity", "tgv")):
    """Run each operator on an ``n``^3 lid-driven cavity (lid speed u) and Taylor-Green vortex (amplitude u)
    for every (u, tau - 1/2) with the limits off, through the driver with the run watchdog checking every 100 steps
    (:mod:`iceresist.watchdog`: lattice speed, density band, kinetic energy); a run is unstable when the watchdog
    stops it within ``steps``. Returns a DataFrame (operator, case, u, tau_excess, cell_reynolds, stable, step)."""
    import pandas as pd

    rows = []
    with tempfile.TemporaryDirectory(prefix="iceresist-limits-") as tmp:
        for op in operators:
            for case in cases:
                for u0 in speeds:
                    for e in excesses:
                        scene = _limit_scene(op, case, u0, e, n, steps)
                        model = build_model(scene)
                        if case == "tgv":
                            model.lbm.initialize(*vortex(n, u0))
                        outputs = Outputs(timeseries=IterationInterval(100), checkpoint=None, checkpoint_final=False,
                                          watchdog_every=100)
                        res = run_model(model, scene, Path(tmp) / f"{op}-{case}.h5", None, stop=Stop(iteration=steps),
                                        outputs=outputs, lattice_units=True, progress=False)
                        stable = res.watchdog.report is None and not res.sim.diverged
                        rows.append({"operator": op, "case": case, "u": u0, "tau_excess": e,
                                     "cell_reynolds": 3 * u0 / e, "stable": stable,
                                     "step": steps if stable else int(res.sim.steps_done)})
    return pd.DataFrame(rows)


# -- command line ---------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("--out", "--output", dest="out", default="runs/validate", help="result folder")
    p.add_argument("--quick", action="store_true", help="the short matrix (the default)")
    p.add_argument("--full", action="store_true", help="longer runs and a longer channel (minutes)")
    p.add_argument("--backend", choices=("cpu", "cuda", "auto"), default="cpu")
    p.add_argument("--json", action="store_true", help="one JSON object per row on stdout")
    return p


def main(argv=None) -> int:
    """``iceresist validate --stability [--out DIR] [--full] [--json]``: the matrix and stability.csv."""
    p = add_arguments(argparse.ArgumentParser(prog="iceresist validate --stability"))
    args = p.parse_args([a for a in (argv or []) if a != "--stability"])
    return run_matrix(args.out, quick=not args.full, backend=args.backend, json_output=args.json)


def run_matrix(out_dir, *, quick: bool = True, backend: str = "cpu", json_output: bool = False) -> int:
    """Run the matrix into ``out_dir`` (``stability.csv``; the map is drawn from it by
    :func:`reports.validation.write_stability_map`); exit status 1 if a row is in between."""
    out = Path(out_dir)
    df = run_stability_matrix(out, quick=quick, backend=backend)
    if json_output:
        for r in df.to_dict(orient="records"):
            print(json.dumps({"name": "stability", **{k: (None if isinstance(v, float) and math.isnan(v) else v)
                                                      for k, v in r.items()}}, default=str))
    bad = df[~df["outcome"].isin(OUTCOMES)]
    for _, r in bad.iterrows():
        log.error("stability: %s %s ended in between: %s", r["axis"], r["setting"], r["message"])
    return 1 if len(bad) else 0
