"""Stokes flow through a periodic simple-cubic array of spheres: the drag against Zick and Homsy (1982).

One fixed sphere of radius a in a periodic cube of L cells (the array's unit cell, solid fraction
phi = 4 pi a^3 / (3 L^3)), driven by a uniform body force f along x in the fluid cells, started from rest and run
until the mean flow has settled (``SETTLE`` e-folding times of the slowest mode, L^2 / (4 pi^2 nu) each). The drag
on each sphere is F = 6 pi mu a K U with U the superficial velocity (the mean of u_x over the whole cell, solid
included) and K(phi) from Zick and Homsy's Table 2 (J. Fluid Mech. 115, 13-26, 1982), exact for Stokes flow, so the
case has no blockage or domain error: only the resolution of the sphere. F is the momentum exchange on the sphere
(eq. 20, the ``sphere_Fx_N`` column); in steady state it equals the body force on the fluid, f N_fluid, which the
case records as a check of the exchange (``force_balance``).

Ladder: phi = 0.125 at 8, 12, 16 cells per diameter (L = 16, 24, 32), cumulant collision, tau = 1 (nu = 1/6); the
Reynolds number U d / nu stays below 0.05.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of

NAME = "sphere_array"
REFERENCE = ("Zick and Homsy (1982), J. Fluid Mech. 115, 13-26, Table 2: drag K = F / (6 pi mu a U) of a simple "
             "cubic array of spheres in Stokes flow (U the superficial velocity)")

#: Zick and Homsy (1982), Table 2, simple cubic array: solid fraction -> K.
ZICK_HOMSY_SC = {0.027: 2.008, 0.064: 2.810, 0.125: 4.292, 0.216: 7.442, 0.343: 15.4, 0.45: 28.1, 0.5236: 42.1}
TAU = 1.0
NU = (TAU - 0.5) / 3.0
#: Body force density (lattice units): small enough for Stokes flow at every rung.
FORCE = 1.0e-6
#: Run length in e-folding times of the slowest viscous mode of the cell.
SETTLE = 12.0


def ladder(quick: bool) -> list[dict]:
    """phi = 0.125 at 8 / 12 / 16 cells per diameter (L = 16 / 24 / 32 cells); full: 16 / 24 / 32 per diameter."""
    cells = (16, 24, 32) if quick else (32, 48, 64)
    out = []
    for n in cells:
        d = 2.0 * radius_cells(n, 0.125)
        out.append({"label": f"{d:.3g} cells/diameter (L = {n})", "resolution": d, "cells": n, "phi": 0.125})
    return out


def radius_cells(n: int, phi: float) -> float:
    """Radius (cells) of the sphere of solid fraction ``phi`` in a cube of ``n`` cells."""
    return n * (3.0 * phi / (4.0 * math.pi)) ** (1.0 / 3.0)


def steps_for(n: int) -> int:
    return int(math.ceil(SETTLE * n * n / (4.0 * math.pi ** 2 * NU)))


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The unit cell (lattice units): n^3 periodic cells, a fixed sphere at the centre, the body force along x."""
    n, phi = int(params["cells"]), float(params["phi"])
    return scene_of({
        "scene": {"name": f"{NAME}-{n}", "description": f"simple cubic sphere array, phi = {phi:g}, L = {n} cells",
                  "units": "lattice"},
        "domain": {"cells": [n, n, n], "faces": {f: "periodic" for f in ("x_min", "x_max", "y_min", "y_max", "z_min",
                                                                         "z_max")}},
        "fluid": {"body_force_N_m3": [FORCE, 0.0, 0.0], "operator": params.get("operator", "cumulant")},
        "numerics": {"tau": TAU, "u_max_m_s": 0.01, "precision": precision, "backend": backend},
        "run": {"steps": steps_for(n)},
        "output": {"fields": ["u", "flags"]},
        "bodies": [{"name": "sphere", "shape": "sphere", "radius_m": radius_cells(n, phi),
                    "position_m": [n / 2.0, n / 2.0, n / 2.0], "motion": "fixed"}],
    }, f"{NAME} {params['label']}")


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung: K from the momentum exchange on the sphere and the superficial velocity, against Zick-Homsy."""
    from iceresist.models import build_model

    n, phi = int(params["cells"]), float(params["phi"])
    sc = scene(params, backend=backend, precision=precision)
    model = build_model(sc)
    steps = steps_for(n)
    rung = run_rung(model, sc, out_dir, NAME, params, steps=steps, sample_every=max(1, steps // 40),
                    fields=("u",))
    a = radius_cells(n, phi)
    u_sup = float(np.nan_to_num(rung.fields["u"][..., 0]).mean())     # solid cells hold u = 0
    fx = rung.timeseries["sphere_Fx_N"]
    force = float(np.mean(fx[-4:]))
    k = force / (6.0 * math.pi * NU * a * u_sup)
    ref = ZICK_HOMSY_SC[phi]
    fluid_cells = int(np.count_nonzero(np.nan_to_num(rung.fields["u"][..., 0]) != 0.0))
    settle = abs(fx[-1] - fx[-5]) / abs(fx[-1]) if len(fx) > 5 else float("nan")
    return CaseResult(case=NAME, label=params["label"], resolution=2.0 * a, cells=n ** 3, steps=rung.steps,
                      wall_s=rung.run_time_s, quantity="drag K = F / (6 pi mu a U)", value=k, reference=ref,
                      error=relative_error(k, ref), backend=backend, precision=precision,
                      extra={"phi": phi, "radius_cells": a, "u_superficial": u_sup, "force": force,
                             "force_balance": force / (FORCE * fluid_cells) if fluid_cells else float("nan"),
                             "reynolds": u_sup * 2 * a / NU, "last_change": float(settle),
                             "result_file": str(rung.path)})
