"""Viscous decay of the 3-D Taylor-Green vortex: the viscosity from the energy decay rate against nu.

Vortex of Brachet et al. (1983) on a periodic N^3 box, k = 2 pi / N (the set-up of tests/test_taylor_green.py):
at low Reynolds number the kinetic energy decays as E ~ exp(-6 nu k^2 t). tau = 0.7 at every N (diffusive
scaling), the amplitude U = Re nu k keeps Re = U / (nu k) = 0.5, the run lasts 1.8 e-folding times of E
(t = 1.8 / (6 nu k^2)) sampled 12 times. Error: the fitted nu against nu = (tau - 1/2)/3; it holds the
O(k^2) lattice error of the diagonal mode and the residual nonlinear transfer at Re = 0.5.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.models import FluidModel
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of

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


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The scene of a rung (lattice units): a periodic N^3 box, tau 0.7, run for :func:`steps_for` steps."""
    n = int(params["n"])
    return scene_of({
        "scene": {"name": f"{NAME}-{n}", "description": f"Taylor-Green vortex, {n} cells per wavelength, Re "
                                                        f"{REYNOLDS:g}", "units": "lattice"},
        "domain": {"cells": [n, n, n], "faces": {f: "periodic" for f in ("x_min", "x_max", "y_min", "y_max",
                                                                          "z_min", "z_max")}},
        "fluid": {"operator": params.get("operator", "cumulant")},
        "numerics": {"tau": TAU, "u_max_m_s": amplitude_of(n), "precision": precision, "backend": backend},
        "run": {"steps": steps_for(n)},
    }, f"{NAME} {params['label']}")


def amplitude_of(n: int) -> float:
    """U = Re nu k (lattice units)."""
    return REYNOLDS * NU * 2.0 * math.pi / n


def steps_for(n: int) -> int:
    """Steps of ``E_FOLDINGS`` e-folding times of the energy, 1 / (6 nu k^2) each."""
    k = 2.0 * math.pi / n
    return int(math.ceil(E_FOLDINGS / (6.0 * NU * k * k)))


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung through the driver: the vortex set on the model, its kinetic energy sampled ``SAMPLES`` times,
    nu fitted to the log of the energy after the first sample (the initial layer of the stress)."""
    n = int(params["n"])
    k = 2.0 * math.pi / n
    amplitude = amplitude_of(n)
    sc = scene(params, backend=backend, precision=precision)
    model = FluidModel(sc)
    rho, u = vortex(n, amplitude)
    model.lbm.initialize(rho, u)
    steps = steps_for(n)
    rung = run_rung(model, sc, out_dir, NAME, params, steps=steps, sample_every=max(1, steps // SAMPLES),
                    initial=f"Taylor-Green vortex (Brachet et al. 1983), amplitude {amplitude:.6g}, k = 2 pi / {n}")
    t, e = rung.timeseries["iteration"].astype(float), rung.timeseries["kinetic_energy_J"]
    slope = np.polyfit(t[1:], np.log(e[1:]), 1)[0]   # first sample: initial layer
    nu_fit = -slope / (6.0 * k * k)
    return CaseResult(case=NAME, label=params["label"], resolution=float(n), cells=n ** 3, steps=rung.steps,
                      wall_s=rung.run_time_s, quantity="lattice viscosity from the decay rate", value=float(nu_fit),
                      reference=NU, error=relative_error(nu_fit, NU), backend=backend, precision=precision,
                      extra={"amplitude_lattice": amplitude, "energy_ratio": float(e[-1] / e[0]),
                             "result_file": str(rung.path)})
