"""Reference case: a sphere settling in a closed box, terminal velocity against ten Cate et al. (2002).

Experiment (ten Cate, Nieuwstad, Derksen and Van den Akker 2002, Phys. Fluids 14, 4012): a nylon sphere,
d = 15 mm, rho_s = 1120 kg/m^3, released 120 mm above the bottom of a 100 x 100 x 160 mm box of silicone oil.
Cases (rho_f kg/m^3, mu Pa s, terminal velocity m/s, Re): E1 970, 0.373, 0.038, 1.5; E2 965, 0.212, 0.060,
4.1; E3 962, 0.113, 0.091, 11.6; E4 960, 0.058, 0.128, 31.9 (as ``tests/test_settling.py``). The headline
quantity is the largest settling velocity of the run (the sphere reaches its terminal velocity well before
the wall slows it).

Full ladder (GPU): case E2 at d = 8, 12, 16 cells, cumulant, 1.2 s. Quick ladder (2-core x86 VM): case E1
(Re 1.5) at d = 5, 6, 8 cells, BGK, 2.0 s (E1 peaks at about 1.5 s; at 0.8 s it is still 1.5 % below its
peak; the bottom slows it from about 2.5 s); the box is the experiment's to the nearest cell (solid cells fill
the grid up to whole blocks: ``domain.pad_to_blocks``). The set-up is the scene file
iceresist/validate/scenes/settling_sphere.toml (E1 at 6 cells per diameter); a rung sets its case and resolution
over it and runs it through the driver.
"""

from __future__ import annotations

import numpy as np

from iceresist.models import build_model
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of
from iceresist.validate.scenes import scene_data

NAME = "settling_sphere"
REFERENCE = "ten Cate et al. (2002), Phys. Fluids 14, 4012: terminal velocity of a 15 mm sphere in silicone oil"

CASES = {"E1": (970.0, 0.373, 0.038), "E2": (965.0, 0.212, 0.060), "E3": (962.0, 0.113, 0.091),
         "E4": (960.0, 0.058, 0.128)}
DIAMETER_M = 0.015
RHO_SPHERE = 1120.0
BOX_M = (0.1, 0.1, 0.16)
RELEASE_HEIGHT_M = 0.12


def ladder(quick: bool) -> list[dict]:
    """Resolutions (cells per diameter) from coarse to fine."""
    if quick:
        return [{"label": f"{d} cells/diameter, E1", "resolution": d, "case": "E1", "operator": "bgk",
                 "t_end_s": 2.0, "u_lattice": 0.04} for d in (5, 6, 8)]
    return [{"label": f"{d} cells/diameter, E2", "resolution": d, "case": "E2", "operator": "cumulant",
             "t_end_s": 1.2, "u_lattice": 0.04} for d in (8, 12, 16)]


def scene(case: str, d_cells: float, *, u_lattice: float = 0.04, t_end_s: float = 1.2, operator: str = "cumulant",
          backend: str = "cpu", precision: str = "float32", levels: int = 0, band_cells: float = 2.0):
    """The scene of case ``case`` at ``d_cells`` cells per diameter: the scene file
    (iceresist/validate/scenes/settling_sphere.toml, E1 at 6 cells per diameter) with the case's oil, the cell size
    d / d_cells, the time step u_lattice dx / u_terminal, the operator, the run length int(t_end_s / dt) and the
    sphere's release point (the middle of the box of whole cells, 120 mm above the floor) set over it.

    The box is the experiment's to the nearest cell, walls half a cell beyond the last fluid cell (half-way
    bounce-back); ``domain.pad_to_blocks`` rounds the grid up to whole blocks with solid cells, so that every rung
    of a ladder sees the same box (rounding the box itself up to blocks widened it by up to 20 %, and the wall
    effect at d / L = 0.15 with it).

    ``levels`` > 0: ``d_cells`` is the resolution of the finest of ``levels`` + 1 levels, which follow the sphere
    (block AMR: ``refinement.body_band_m`` of ``band_cells`` level-0 cells, a regrid every 10 level-0 steps);
    level 0 has d_cells / 2^levels cells per diameter and must tile the box with whole blocks (6 cells per diameter
    does: 40 x 40 x 64), the time step is level 0's."""
    rho_f, mu, u_ref = CASES[case]
    d = DIAMETER_M
    dx = d / d_cells * 2 ** levels
    dt = u_lattice * dx / u_ref
    n = [int(round(L / dx)) for L in BOX_M]
    if levels and (any(k % 8 for k in n) or not np.allclose(np.array(n) * dx, BOX_M)):
        raise ValueError(f"settling sphere on {levels + 1} levels: level 0 at {d_cells / 2 ** levels:g} cells per "
                         f"diameter does not tile the box with whole blocks ({n} cells); use 6 cells per diameter")
    data = scene_data(NAME)
    data["scene"].update(name=f"{NAME}-{case}-{d_cells:g}", description=f"ten Cate {case}, 15 mm nylon sphere in "
                         f"silicone oil, {d_cells:g} cells per diameter")
    data["domain"].update(size_m=list(BOX_M), dx_m=dx, pad_to_blocks=not levels)
    if levels:
        data["refinement"] = {"levels": levels, "body_band_m": band_cells * dx, "regrid_every_steps": 10}
    data["fluid"].update(nu_m2_s=mu / rho_f, rho_kg_m3=rho_f, operator=operator)
    data["numerics"].update(dt_s=dt, u_max_m_s=u_ref, precision=precision, backend=backend)
    data["run"] = {"steps": int(t_end_s / dt)}
    data["bodies"][0].update(radius_m=d / 2, density_kg_m3=RHO_SPHERE,
                             position_m=[n[0] * dx / 2, n[1] * dx / 2, RELEASE_HEIGHT_M + d / 2])
    return scene_of(data, f"{NAME} {case} {d_cells:g} cells/diameter")


#: Steps between time-series rows of a rung (the peak velocity is read from them; E1 peaks on a plateau, where 5
#: steps change the velocity by less than 1e-4 of it, and a row every step doubled the run with its watchdog check).
SAMPLE_EVERY = 5


def settle(case: str, d_cells: float, *, u_lattice: float = 0.04, t_end_s: float = 1.2, operator: str = "cumulant",
           backend: str = "cpu", precision: str = "float32", levels: int = 0, sample_every: int = SAMPLE_EVERY):
    """Settling velocity history (t_s, w_m_s) of case ``case`` at ``d_cells`` cells per diameter, a value every
    ``sample_every`` steps, with the cell count, the number of steps, the wall time of the stepping (the first,
    compiling chunk excluded) and the cell updates (every level's cells times its sub-steps, summed over the
    steps): the model of :func:`scene` (``levels``: on levels that follow the sphere) run through the driver into a
    scratch folder (:func:`~iceresist.validate.rung.run_rung`)."""
    sc = scene(case, d_cells, u_lattice=u_lattice, t_end_s=t_end_s, operator=operator, backend=backend,
               precision=precision, levels=levels)
    model = build_model(sc)
    steps = int(sc.run.steps)
    updates = []
    count = {"updates": (lambda sim: updates.append(sim.model.lattice_updates_per_step), 1)}
    rung = run_rung(model, sc, None, NAME, {"label": f"{case} {d_cells:g} cells/diameter", "case": case,
                                            "resolution": d_cells, "levels": levels},
                    steps=steps, sample_every=sample_every, callbacks=count)
    ts = rung.timeseries
    after = ts["iteration"] > 0
    return ts["time_s"][after], -ts["sphere_vz_m_s"][after], int(model.cells), steps, rung.wall_s, int(sum(updates))


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung through the driver (:func:`iceresist.validate.rung.run_rung`): the largest settling velocity of
    the time series (``-sphere_vz_m_s``, a row every step) against the measured terminal velocity."""
    case = params["case"]
    sc = scene(case, params["resolution"], u_lattice=params["u_lattice"], t_end_s=params["t_end_s"],
               operator=params["operator"], backend=backend, precision=precision)
    model = build_model(sc)
    rung = run_rung(model, sc, out_dir, NAME, params, steps=int(sc.run.steps), sample_every=SAMPLE_EVERY)
    t, w = rung.timeseries["time_s"], -rung.timeseries["sphere_vz_m_s"]
    u_ref = CASES[case][2]
    value = float(w.max())
    return CaseResult(case=NAME, label=params["label"], resolution=float(params["resolution"]),
                      cells=int(model.cells), steps=rung.steps, wall_s=rung.run_time_s,
                      quantity="terminal velocity (m/s)", value=value, reference=u_ref,
                      error=relative_error(value, u_ref), backend=backend, precision=precision,
                      extra={"experiment": case, "operator": params["operator"],
                             "t_peak_s": float(t[int(np.argmax(w))]), "result_file": str(rung.path)})


def write_curves(curves: dict, path, case: str = "E1"):
    """Settling velocity against time, ``{label: (t_s, w_m_s)}``, as a CSV (columns label, time_s, w_m_s,
    experiment, terminal_m_s: the measured terminal velocity of ``case``) that
    :func:`reports.validation.settling_velocity_figure` draws."""
    import pandas as pd

    frames = [pd.DataFrame({"label": label, "time_s": t, "w_m_s": w}) for label, (t, w) in curves.items()]
    table = pd.concat(frames, ignore_index=True).assign(experiment=case, terminal_m_s=CASES[case][2])
    table.to_csv(path, index=False, float_format="%.8g")


if __name__ == "__main__":  # python -m iceresist.validate.cases.settling_sphere OUT.csv [d ...]: docs/notes/settling-sphere.md
    import sys

    ds = [float(a) for a in sys.argv[2:]] or [5.0, 6.0, 8.0]
    curves = {}
    for d in ds:
        t, w, *_ = settle("E1", d, u_lattice=0.04, t_end_s=3.0, operator="bgk")
        curves[f"{d:g} cells per diameter"] = (t, w)
    write_curves(curves, sys.argv[1])
