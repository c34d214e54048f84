"""Force-driven Poiseuille flow between half-way bounce-back walls, started from rest.

8 x N x 8 cells, periodic in x and z, walls half a cell outside the first and last fluid cell (cell j lies at
y = j + 1/2, walls at y = 0 and y = N), tau = 0.8 at every N (diffusive scaling), centre-line velocity 0.01
(force 8 nu u_max / N^2). The run starts from rest and lasts until the slowest mode, decaying as
exp(-nu pi^2 t / N^2), has fallen to 1e-5: t = ln(1e5) N^2 / (nu pi^2). Error: relative L2 norm of
u_x(y) against the parabola F / (2 nu) y (N - y) (the set-up of tests/test_poiseuille.py).
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.models import FluidModel
from iceresist.validate.result import CaseResult
from iceresist.validate.rung import run_rung, scene_of

NAME = "poiseuille"
REFERENCE = ("analytic parabola u_x(y) = F/(2 nu) y (N - y) of the force-driven channel; error = relative L2 "
             "norm of the simulated profile after the start-up transient has decayed to 1e-5")
TAU = 0.8
NU = (TAU - 0.5) / 3.0
U_MAX = 0.01
DECAY = 1e-5


def ladder(quick: bool) -> list[dict]:
    """Cells across the channel: 8/16/32 (quick), 16/32/64 (full); cumulant collision."""
    ns = (8, 16, 32) if quick else (16, 32, 64)
    return [{"label": f"{n} cells/width", "resolution": float(n), "n": n, "operator": "cumulant"} for n in ns]


def steps_for(n: int) -> int:
    """Steps for the slowest start-up mode to decay to ``DECAY``."""
    return int(math.ceil(math.log(1.0 / DECAY) * n * n / (NU * math.pi ** 2)))


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The scene of a rung (lattice units): 8 x N x 8 cells, periodic in x and z, walls at y = 0 and y = N, tau
    0.8, the force density of centre-line speed ``U_MAX``, run for :func:`steps_for` steps."""
    n = int(params["n"])
    return scene_of({
        "scene": {"name": f"{NAME}-{n}", "description": f"force-driven Poiseuille flow, {n} cells across",
                  "units": "lattice"},
        "domain": {"cells": [8, n, 8], "faces": {"x_min": "periodic", "x_max": "periodic", "y_min": "wall",
                                                 "y_max": "wall", "z_min": "periodic", "z_max": "periodic"}},
        "fluid": {"body_force_N_m3": [8.0 * NU * U_MAX / n ** 2, 0.0, 0.0],
                  "operator": params.get("operator", "cumulant")},
        "numerics": {"tau": TAU, "u_max_m_s": U_MAX, "precision": precision, "backend": backend},
        "run": {"steps": steps_for(n)},
        "output": {"fields": ["u"]},
    }, f"{NAME} {params['label']}")


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung from rest through the driver; the profile of the final u against the parabola."""
    n = int(params["n"])
    sc = scene(params, backend=backend, precision=precision)
    steps = steps_for(n)
    rung = run_rung(FluidModel(sc), sc, out_dir, NAME, params, steps=steps, sample_every=max(1, steps // 20),
                    fields=("u",))
    force = sc.fluid.body_force_N_m3[0]
    y = np.arange(n) + 0.5
    exact = force / (2 * NU) * y * (n - y)
    prof = rung.fields["u"][..., 0].mean(axis=(0, 2))
    err = float(np.sqrt(np.sum((prof - exact) ** 2) / np.sum(exact ** 2)))
    return CaseResult(case=NAME, label=params["label"], resolution=float(n), cells=8 * n * 8, steps=rung.steps,
                      wall_s=rung.run_time_s, quantity="relative L2 distance of u_x(y) from the parabola", value=err,
                      reference=0.0, error=err, backend=backend, precision=precision,
                      extra={"u_centre_lattice": float(prof[n // 2]), "u_max_exact_lattice": float(exact.max()),
                             "result_file": str(rung.path)})
