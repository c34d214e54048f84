"""Stokes flow through a periodic simple-cubic array of spheres: the drag against Zick and Homsy (1982).

One fixed sphere of radius a in a periodic cube of L cells (the array's unit cell, solid fraction
phi = 4 pi a^3 / (3 L^3)), driven by a uniform body force f along x in the fluid cells, started from rest and run
until the mean flow has settled (``SETTLE`` e-folding times of the slower of the cell's viscous mode,
L^2 / (4 pi^2 nu), and the drag's relaxation of the mean flow, V_fluid / (6 pi nu a K)). The drag
on each sphere is F = 6 pi mu a K U with U the superficial velocity (the mean of u_x over the whole cell, solid
included) and K(phi) from Zick and Homsy's Table 2 (J. Fluid Mech. 115, 13-26, 1982), exact for Stokes flow, so the
case has no blockage or domain error: only the resolution of the sphere.

Which force: Zick and Homsy drive the flow by a mean pressure gradient G, p = -G x + p' (p' periodic), and their F is
the whole force of the fluid on the sphere, which the balance of the fluid in one cell fixes at F = G V_cell (the
cell faces carry G V_cell, the sphere takes it all; Sangani and Acrivos 1982: grad <p> = -F / V_cell). A body force
f on the fluid cells alone gives the same velocity field for f = G, but the sphere then feels only the periodic part
p' and the viscous stress, F_s = f V_fluid: the linear pressure's share G V_sphere is missing. So
F = F_s V_cell / V_fluid, with F_s the momentum exchange on the sphere (eq. 20, the ``sphere_Fx_N`` column) and
V_fluid the fluid cells. Comparing F_s itself with Zick and Homsy's F puts the drag low by the factor 1 - phi
(-12.5 % at phi = 0.125). Settled, F_s equals the body force on the fluid, f N_fluid, which the case records as a
check of the exchange (``force_balance``).

Ladder: phi = 0.125 at 10, 15, 20 cells per diameter (L = 16, 24, 32), cumulant collision, tau = 1 (nu = 1/6; a
rung's ``tau`` sets another); the body force is set for a Reynolds number U d / nu of about ``REYNOLDS``. Solid fractions (:func:`fractions`): 0.064,
0.125 and 0.216 at 16-20 cells per diameter (L a whole number of 8-cell blocks).
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.models import build_model
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of

NAME = "sphere_array"
REFERENCE = ("Zick and Homsy (1982), J. Fluid Mech. 115, 13-26, Table 2: drag K = F / (6 pi mu a U) of a simple "
             "cubic array of spheres in Stokes flow (U the superficial velocity, F = G V_cell the whole force on a "
             "sphere under the mean pressure gradient G)")

#: Zick and Homsy (1982), Table 2, simple cubic array: solid fraction -> K.
ZICK_HOMSY_SC = {0.027: 2.008, 0.064: 2.810, 0.125: 4.292, 0.216: 7.442, 0.343: 15.4, 0.45: 28.1, 0.5236: 42.1}
TAU = 1.0
NU = (TAU - 0.5) / 3.0
#: Reynolds number U d / nu the body force is set for (Stokes flow: inertia changes K by O(Re)).
REYNOLDS = 0.02
#: Run length in e-folding times of the slowest relaxation of the flow (module docstring).
SETTLE = 20.0


def ladder(quick: bool) -> list[dict]:
    """phi = 0.125 at 10 / 15 / 20 cells per diameter (L = 16 / 24 / 32 cells); full: 20 / 30 / 40 per diameter."""
    cells = (16, 24, 32) if quick else (32, 48, 64)
    out = []
    for n in cells:
        d = 2.0 * radius_cells(n, 0.125)
        out.append({"label": f"{d:.3g} cells/diameter (L = {n})", "resolution": d, "cells": n, "phi": 0.125})
    return out


def radius_cells(n: int, phi: float) -> float:
    """Radius (cells) of the sphere of solid fraction ``phi`` in a cube of ``n`` cells."""
    return n * (3.0 * phi / (4.0 * math.pi)) ** (1.0 / 3.0)


def fractions() -> list[dict]:
    """Three solid fractions at 16-20 cells per diameter: 0.064 (L = 32), 0.125 (L = 32), 0.216 (L = 24)."""
    out = []
    for phi, n in ((0.064, 32), (0.125, 32), (0.216, 24)):
        d = 2.0 * radius_cells(n, phi)
        out.append({"label": f"phi = {phi:g}, {d:.3g} cells/diameter (L = {n})", "resolution": d, "cells": n,
                    "phi": phi})
    return out


def force_for(n: int, phi: float, nu: float = NU) -> float:
    """Body force density (lattice units) for U d / nu = ``REYNOLDS`` at Zick and Homsy's drag:
    f n^3 = 6 pi mu a K U with U = REYNOLDS nu / (2 a)."""
    return REYNOLDS * 3.0 * math.pi * nu ** 2 * ZICK_HOMSY_SC[phi] / n ** 3


def viscosity(params: dict) -> float:
    """Lattice viscosity (tau - 1/2) / 3 of a rung (``params["tau"]``, default :data:`TAU`)."""
    return (float(params.get("tau", TAU)) - 0.5) / 3.0


def steps_for(n: int, phi: float = 0.125, nu: float = NU) -> int:
    """``SETTLE`` times the slower of L^2 / (4 pi^2 nu) and (1 - phi) L^3 / (6 pi nu a K)."""
    a = radius_cells(n, phi)
    t = max(n * n / (4.0 * math.pi ** 2 * nu), (1.0 - phi) * n ** 3 / (6.0 * math.pi * nu * a * ZICK_HOMSY_SC[phi]))
    return int(math.ceil(SETTLE * t))


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The unit cell (lattice units): n^3 periodic cells, a fixed sphere at the centre, the body force along x."""
    n, phi, nu = int(params["cells"]), float(params["phi"]), viscosity(params)
    return scene_of({
        "scene": {"name": f"{NAME}-{n}", "description": f"simple cubic sphere array, phi = {phi:g}, L = {n} cells",
                  "units": "lattice"},
        "domain": {"cells": [n, n, n], "faces": {f: "periodic" for f in ("x_min", "x_max", "y_min", "y_max", "z_min",
                                                                         "z_max")}},
        "fluid": {"body_force_N_m3": [force_for(n, phi, nu), 0.0, 0.0],
                  "operator": params.get("operator", "cumulant")},
        "numerics": {"tau": 0.5 + 3.0 * nu, "u_max_m_s": 0.01, "precision": precision, "backend": backend},
        "run": {"steps": steps_for(n, phi, nu)},
        "output": {"fields": ["u", "flags"]},
        "bodies": [{"name": "sphere", "shape": "sphere", "radius_m": radius_cells(n, phi),
                    "position_m": [n / 2.0, n / 2.0, n / 2.0], "motion": "fixed"}],
    }, f"{NAME} {params['label']}")


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung: K from the momentum exchange on the sphere and the superficial velocity, against Zick-Homsy."""
    n, phi, nu = int(params["cells"]), float(params["phi"]), viscosity(params)
    sc = scene(params, backend=backend, precision=precision)
    model = build_model(sc)
    steps = steps_for(n, phi, nu)
    rung = run_rung(model, sc, out_dir, NAME, params, steps=steps, sample_every=max(1, steps // 40),
                    fields=("u",))
    a = radius_cells(n, phi)
    ux = np.nan_to_num(rung.fields["u"][..., 0])
    u_sup = float(ux.mean())                                  # solid cells hold u = 0
    fluid_cells = int(np.count_nonzero(ux != 0.0))            # every fluid cell moves in this Stokes flow
    fx = rung.timeseries["sphere_Fx_N"]
    force = float(np.mean(fx[-4:]))
    drag = force * n ** 3 / fluid_cells                       # F = F_s V_cell / V_fluid (module docstring)
    k = drag / (6.0 * math.pi * nu * a * u_sup)
    ref = ZICK_HOMSY_SC[phi]
    settle = abs(fx[-1] - fx[-5]) / abs(fx[-1]) if len(fx) > 5 else float("nan")
    return CaseResult(case=NAME, label=params["label"], resolution=2.0 * a, cells=n ** 3, steps=rung.steps,
                      wall_s=rung.run_time_s, quantity="drag K = F / (6 pi mu a U)", value=k, reference=ref,
                      error=relative_error(k, ref), backend=backend, precision=precision,
                      extra={"phi": phi, "radius_cells": a, "u_superficial": u_sup, "force": force, "drag": drag,
                             "fluid_fraction": fluid_cells / n ** 3,
                             "force_balance": (force / (force_for(n, phi, nu) * fluid_cells) if fluid_cells
                                               else float("nan")),
                             "reynolds": u_sup * 2 * a / nu, "tau": 0.5 + 3.0 * nu, "last_change": float(settle),
                             "result_file": str(rung.path)})
