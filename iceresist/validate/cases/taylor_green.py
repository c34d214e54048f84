"""Viscous decay of the 3-D Taylor-Green vortex: the viscosity from the energy decay rate against nu.

Vortex of Brachet et al. (1983) on a periodic N^3 box, k = 2 pi / N (the set-up of tests/test_taylor_green.py):
at low Reynolds number the kinetic energy decays as E ~ exp(-6 nu k^2 t). tau = 0.7 at every N (diffusive
scaling), the amplitude U = Re nu k keeps Re = U / (nu k) = 0.5, the run lasts 1.8 e-folding times of E
(t = 1.8 / (6 nu k^2)) sampled 12 times. Error: the fitted nu against nu = (tau - 1/2)/3; it holds the
O(k^2) lattice error of the diagonal mode and the residual nonlinear transfer at Re = 0.5.
"""

from __future__ import annotations

import math
import time

import numpy as np

from iceresist.validate.result import CaseResult, relative_error

NAME = "taylor_green"
REFERENCE = ("lattice viscosity nu = (tau - 1/2)/3 against nu fitted to the energy decay E ~ exp(-6 nu k^2 t) "
             "of the Taylor-Green vortex at Re = 0.5 (Brachet et al. 1983)")
TAU = 0.7
NU = (TAU - 0.5) / 3.0
REYNOLDS = 0.5
E_FOLDINGS = 1.8
SAMPLES = 12


def ladder(quick: bool) -> list[dict]:
    """Cells per wavelength: 16/24/32 (quick), 32/48/64 (full); cumulant collision. (At 8 cells the run lasts
    8 steps, shorter than the initial layer of the non-equilibrium stress: not a rung.)"""
    ns = (16, 24, 32) if quick else (32, 48, 64)
    return [{"label": f"{n} cells/wavelength", "resolution": float(n), "n": n, "operator": "cumulant"}
            for n in ns]


def vortex(n: int, amplitude: float):
    """Density (n,n,n) and velocity (3,n,n,n) on cell centres, rho = 1 + 3 p' (c_s^2 = 1/3)."""
    k = 2.0 * np.pi / n
    x = k * (np.arange(n) + 0.5)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    u = np.zeros((3, n, n, n))
    u[0] = amplitude * np.sin(X) * np.cos(Y) * np.cos(Z)
    u[1] = -amplitude * np.cos(X) * np.sin(Y) * np.cos(Z)
    p = amplitude ** 2 / 16.0 * (np.cos(2 * X) + np.cos(2 * Y)) * (np.cos(2 * Z) + 2.0)
    return 1.0 + 3.0 * p, u


def kinetic_energy(rho, u) -> float:
    return float(0.5 * np.mean(rho * np.sum(u * u, axis=0)))


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    from iceresist.backends.jit import resolve_backend
    from iceresist.grid.forest import BlockForest
    from iceresist.lbm.solver import LBMSolver

    n = int(params["n"])
    k = 2.0 * math.pi / n
    amplitude = REYNOLDS * NU * k
    fo = BlockForest.uniform((n, n, n))
    s = LBMSolver(fo, tau=TAU, operator=params.get("operator", "cumulant"), precision=precision,
                  target=resolve_backend(backend))
    s.step(1)                       # compile outside the timed loop
    s.synchronize()
    rho, u = vortex(n, amplitude)
    s.initialize(rho, u)
    steps = int(math.ceil(E_FOLDINGS / (6.0 * NU * k * k)))
    every = max(1, steps // SAMPLES)
    t, e = [0.0], [kinetic_energy(rho, u)]
    wall = 0.0
    while s.iteration < steps:
        t0 = time.perf_counter()
        s.step(min(every, steps - s.iteration))
        s.synchronize()
        wall += time.perf_counter() - t0
        r, v = s.macroscopic()
        t.append(float(s.iteration))
        e.append(kinetic_energy(r, v))
    slope = np.polyfit(np.asarray(t[1:]), np.log(np.asarray(e[1:])), 1)[0]   # first sample: initial layer
    nu_fit = -slope / (6.0 * k * k)
    return CaseResult(case=NAME, label=params["label"], resolution=float(n), cells=fo.cells, steps=steps,
                      wall_s=wall, quantity="lattice viscosity from the decay rate", value=float(nu_fit),
                      reference=NU, error=relative_error(nu_fit, NU), backend=backend, precision=precision,
                      extra={"amplitude_lattice": amplitude, "energy_ratio": e[-1] / e[0]})
