"""Reference case: collapse of a water column (dam break) against Martin and Moyce (1952).

Set-up (lattice units): a column of width a (``cells_per_column``) and height 2 a (Martin and Moyce's
n^2 = 2) at rest against the wall x = 0 of a closed tank 4.5 a long (no-slip walls at x and z), a quasi-2D
slab of 8 cells along periodic y. The column starts hydrostatic with a sharp vertical face at x = a, which
the phase field widens to its profile within a few steps; there is no gate. Gravity g is set from the
Mach limit: the Ritter front speed 2 sqrt(2 g a) is held at ``front_speed`` (lattice units).

Measured: the surge front x_f(t), the leading edge of the liquid on the floor, as Martin and Moyce read it
from their photographs: the largest x where the y-mean phi of the bottom cell layer crosses 1/2 (linear
interpolation between cell centres), as Z = x_f / a against their T = n t sqrt(g / a) = t sqrt(2 g / a).
On a no-slip floor the contact line of the diffuse interface moves only by the phase-field flux, so the
mobility sets how closely the floor edge follows the nose above it; ``Z_nose`` in ``extra`` (the furthest
1/2 crossing of the bottom a/4 layers, ``front_rows``) bounds it from above.
``walls = "slip"`` makes the four walls free-slip (specular reflection): the contact line then moves
with the liquid, and the front converges with resolution (docs/VALIDATION.md, "Dam break").
Reference: the ladder's own converged front (Richardson), Z at T = ``t_compare`` (default 2), as the ship case;
beside it Martin and Moyce's n^2 = 2, a = 2.25 in measurements (``iceresist/validate/data/martin_moyce_1952.csv``),
whose errors are in ``extra`` (``error_at_ref``, ``mm_worst_error`` over T <= 3, ``mm_offset_at_T``).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from iceresist.models import FreeSurfaceModel
from iceresist.validate.result import CaseResult
from iceresist.validate.rung import run_rung, scene_of

log = logging.getLogger(__name__)

NAME = "dam_break"
REFERENCE = ("the converged front: Richardson extrapolation of the ladder's Z = x/a at T = 2 (free-slip walls), else "
             "its finest rung; beside it Martin and Moyce (1952), Phil. Trans. R. Soc. Lond. A 244, 312-324 (column "
             "n^2 = 2, a = 2.25 in, fig. 3): the instantaneous release leads their gate-opened front, so the check "
             "against them is the front within 20 % for T <= 3 and the offset converging with the grid")
#: The measure against Martin and Moyce: every measured point with T <= 3 within this fraction.
MM_TOLERANCE = 0.20
MM_T_MAX = 3.0

DATA = Path(__file__).resolve().parents[1] / "data" / "martin_moyce_1952.csv"

DEFAULTS = dict(cells_per_column=16, front_speed=0.1, tau=0.51, operator="cumulant", mobility=0.01, ny=8,
                t_end=2.6, t_compare=2.0, length_columns=4.5, front_rows=None, walls="wall")


def measurements() -> tuple[np.ndarray, np.ndarray]:
    """(T, Z) of Martin and Moyce (1952), n^2 = 2, a = 2.25 in."""
    import pandas as pd

    d = pd.read_csv(DATA, comment="#")
    return d["T"].to_numpy(float), d["Z"].to_numpy(float)


def ladder(quick: bool) -> list[dict]:
    """Columns of 8, 12, 16 cells (quick; < 2 min in all on a 2-core x86 VM after compilation) or 16-48, with
    free-slip walls (the front converges there; on a no-slip floor the edge jumps, docs/notes/dam-break.md), to
    T = 3.05."""
    sizes = (8, 12, 16) if quick else (16, 24, 32, 48)
    return [dict(label=f"a = {n} cells, free slip", resolution=n, cells_per_column=n, walls="slip", t_end=3.05)
            for n in sizes]


def gravity(params: dict) -> float:
    """g (lattice units) from the Ritter front speed 2 sqrt(2 g a) = ``front_speed``."""
    p = {**DEFAULTS, **params}
    return p["front_speed"] ** 2 / (8.0 * p["cells_per_column"])


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The scene of a rung (lattice units): the column of width a and height 2 a against the wall x = 0
    (``free_surface.column_length_m``), the rest of the floor dry, walls of kind ``walls`` at x and z, periodic
    y, gravity from the front speed, run for ``t_end``."""
    p = {**DEFAULTS, **params}
    a = int(p["cells_per_column"])
    nx = 8 * math.ceil(p["length_columns"] * a / 8)
    nz = 8 * math.ceil((2 * a + 6) / 8)
    faces = {k: p["walls"] for k in ("x_min", "x_max", "z_min", "z_max")}
    faces.update(y_min="periodic", y_max="periodic")
    return scene_of({
        "scene": {"name": f"{NAME}-{a}", "description": f"collapse of a water column a = {a} cells, n^2 = 2",
                  "units": "lattice"},
        "domain": {"cells": [nx, int(p["ny"]), nz], "faces": faces},
        "fluid": {"gravity_m_s2": [0.0, 0.0, -gravity(p)], "operator": p["operator"]},
        "numerics": {"tau": p["tau"], "precision": precision, "backend": backend},
        "run": {"steps": steps_for(p)},
        "output": {"fields": []},
        "free_surface": {"water_depth_m": 2.0 * a, "column_length_m": float(a), "mobility_lattice": p["mobility"],
                         "interface_width_cells": 3.0, "h_lattice": "D3Q15", "f_pool_margin": 0.25},
    }, f"{NAME} {p.get('label', a)}")


def steps_per_T(params: dict) -> float:
    """Steps per unit of T = t sqrt(2 g / a)."""
    p = {**DEFAULTS, **params}
    return math.sqrt(float(p["cells_per_column"]) / (2.0 * gravity(p)))


def steps_for(params: dict) -> int:
    p = {**DEFAULTS, **params}
    return int(math.ceil(p["t_end"] * steps_per_T(p)))


def front_position(phi: np.ndarray, rows: int = 1) -> float:
    """x (cells from the wall x = 0) of the leading edge: the largest x where the y-mean phi of one of the
    bottom ``rows`` cell layers crosses 1/2 (rows = 1: the edge on the floor; more rows: the surge's nose)."""
    best = 0.0
    for k in range(rows):
        row = phi[:, :, k].mean(axis=1)
        wet = np.nonzero(row >= 0.5)[0]
        if wet.size == 0:
            continue
        i = int(wet[-1])
        x = float(row.size) if i + 1 >= row.size else i + 0.5 + (row[i] - 0.5) / (row[i] - row[i + 1])
        best = max(best, x)
    return best


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """Run one rung through the driver, Z(T) sampled every 0.05 T; the error of Z at the measured T <= t_compare
    in ``extra``."""
    p = {**DEFAULTS, **params}
    a = float(p["cells_per_column"])
    sc = scene(p, backend=backend, precision=precision)
    t_unit = steps_per_T(p)
    rows = int(p["front_rows"]) if p["front_rows"] else max(2, int(a) // 4)
    rung = run_rung(FreeSurfaceModel(sc), sc, out_dir, NAME, {**p, "label": p.get("label", f"a = {int(a)} cells")},
                    steps=steps_for(p), sample_every=max(1, int(round(0.05 * t_unit))),
                    probes={"Z": lambda m: front_position(m.fluid.phi()) / a,
                            "Z_nose": lambda m: front_position(m.fluid.phi(), rows) / a})
    ts = rung.timeseries["iteration"] / t_unit
    zs, zn = rung.timeseries["Z"], rung.timeseries["Z_nose"]
    t_ref, z_ref = measurements()
    z_sim = np.interp(t_ref, ts, zs)
    err = np.abs(z_sim - z_ref) / z_ref
    within = (t_ref <= min(MM_T_MAX, ts[-1]) + 1e-9)
    z_at = float(np.interp(p["t_compare"], ts, zs))
    extra = dict(T=ts.tolist(), Z=zs.tolist(), Z_nose=zn.tolist(), T_ref=t_ref.tolist(), Z_ref=z_ref.tolist(),
                 Z_sim=z_sim.tolist(), error_at_ref=err.tolist(), g=gravity(p), tau=p["tau"], operator=p["operator"],
                 mobility=p["mobility"], steps_per_T=t_unit, volume=float(rung.timeseries["water_volume_m3"][-1]),
                 result_file=str(rung.path), walls=p["walls"],
                 mm_worst_error=float(err[within].max()) if within.any() else float("nan"),
                 mm_offset_at_T=float(z_at / np.interp(p["t_compare"], t_ref, z_ref) - 1.0))
    log.info("dam break a = %d: Z errors %s at T = %s", int(a), np.round(err, 3), t_ref)
    return CaseResult(case=NAME, label=p.get("label", f"a = {int(a)} cells"),
                      resolution=float(p.get("resolution", a)), cells=int(np.prod(sc.shape_cells())),
                      steps=rung.steps, wall_s=rung.run_time_s,
                      quantity=f"surge front Z = x/a at T = {p['t_compare']:g} ({p['walls']} walls)",
                      value=z_at, reference=float("nan"), error=float("nan"),
                      backend=backend, precision=precision, extra=extra)
