"""3-D Taylor-Green vortex on the block-forest solver: viscosity from the energy decay, Galilean
invariance, and (slow) the Re = 1600 transition against the DNS dissipation peak.

Vortex (Brachet et al. 1983): u = U sin(kx) cos(ky) cos(kz), v = -U cos(kx) sin(ky) cos(kz), w = 0,
p = p0 + rho0 U^2/16 (cos 2kx + cos 2ky)(cos 2kz + 2), k = 2 pi / N. At low Reynolds number the
vortex decays viscously: kinetic energy E ~ exp(-6 nu k^2 t), nu = (tau - 1/2)/3 (lattice units).
"""

from __future__ import annotations

import logging

import numpy as np
import pytest

from iceresist.grid.forest import BlockForest
from iceresist.lbm.solver import LBMSolver

log = logging.getLogger(__name__)


def taylor_green_fields(n: int, amplitude: float, carrier=(0.0, 0.0, 0.0)):
    """Density (n,n,n) and velocity (3,n,n,n) of the Taylor-Green vortex on cell centres x = i + 1/2,
    lattice units, rho = 1 + 3 p' (c_s^2 = 1/3), plus a uniform carrier velocity."""
    k = 2.0 * np.pi / n
    x = k * (np.arange(n) + 0.5)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    u = np.zeros((3, n, n, n))
    u[0] = amplitude * np.sin(X) * np.cos(Y) * np.cos(Z) + carrier[0]
    u[1] = -amplitude * np.cos(X) * np.sin(Y) * np.cos(Z) + carrier[1]
    u[2] = carrier[2]
    p = amplitude ** 2 / 16.0 * (np.cos(2 * X) + np.cos(2 * Y)) * (np.cos(2 * Z) + 2.0)
    return 1.0 + 3.0 * p, u


def kinetic_energy(rho, u, carrier=(0.0, 0.0, 0.0)) -> float:
    """Mean kinetic energy per cell, 1/2 <rho |u - U|^2>, in the frame moving with the carrier U."""
    du = u - np.asarray(carrier, dtype=float)[:, None, None, None]
    return float(0.5 * np.mean(rho * np.sum(du * du, axis=0)))


def energy_history(n, tau, amplitude, steps, every, *, operator="cumulant", precision="float32", carrier=(0, 0, 0)):
    """Run the vortex and return times (steps) and kinetic energies sampled every ``every`` steps."""
    solver = LBMSolver(BlockForest.uniform((n, n, n)), tau=tau, operator=operator, precision=precision)
    rho, u = taylor_green_fields(n, amplitude, carrier)
    solver.initialize(rho, u)
    t, e = [0], [kinetic_energy(rho, u, carrier)]
    while solver.iteration < steps:
        solver.step(every)
        r, v = solver.macroscopic()
        t.append(solver.iteration)
        e.append(kinetic_energy(r, v, carrier))
    return np.asarray(t, dtype=float), np.asarray(e)


def fitted_viscosity(t, e, n) -> float:
    """nu from a least-squares fit of ln E = a - 6 nu k^2 t (first sample left out: initial layer)."""
    k = 2.0 * np.pi / n
    slope = np.polyfit(t[1:], np.log(e[1:]), 1)[0]
    return -slope / (6.0 * k * k)


N_LOW_RE = 32
TAU_LOW_RE = 0.7
U_LOW_RE = 0.02
STEPS_LOW_RE = 120          # ~1.8 viscous e-folding times of the energy, 1/(6 nu k^2) = 65 steps


@pytest.fixture(scope="module")
def low_re_decay():
    """Energy history of the resting vortex at Re = U/(nu k) = 1.5, cumulant, float32."""
    return energy_history(N_LOW_RE, TAU_LOW_RE, U_LOW_RE, STEPS_LOW_RE, 10)


def test_taylor_green_viscosity(low_re_decay):
    """The decay rate gives nu = (tau - 1/2)/3 within 1 % (cumulant, 32^3, float32)."""
    t, e = low_re_decay
    nu = fitted_viscosity(t, e, N_LOW_RE)
    nu_ref = (TAU_LOW_RE - 0.5) / 3.0
    log.info("Taylor-Green 32^3: nu fitted %.6f, nu = (tau - 1/2)/3 = %.6f", nu, nu_ref)
    assert nu == pytest.approx(nu_ref, rel=0.01)
    assert np.all(np.diff(e) < 0)


def test_taylor_green_galilean_invariance(low_re_decay):
    """The same vortex carried by U = 0.05 along x decays at the same rate within 2 %."""
    t0, e0 = low_re_decay
    carrier = (0.05, 0.0, 0.0)
    t1, e1 = energy_history(N_LOW_RE, TAU_LOW_RE, U_LOW_RE, STEPS_LOW_RE, 10, carrier=carrier)
    nu0 = fitted_viscosity(t0, e0, N_LOW_RE)
    nu1 = fitted_viscosity(t1, e1, N_LOW_RE)
    log.info("Taylor-Green 32^3: nu at rest %.6f, carried by U = 0.05 %.6f", nu0, nu1)
    assert nu1 == pytest.approx(nu0, rel=0.02)


def dissipation_history(n, reynolds, amplitude, t_star_end, samples_per_unit=4, precision="float32"):
    """Re = U L / nu with L = n / (2 pi): nondimensional time t* = t U / L, energy E* = E / U^2 and
    dissipation eps* = -dE*/dt* (Brachet et al. 1983; van Rees et al. 2011)."""
    length = n / (2.0 * np.pi)
    nu = amplitude * length / reynolds
    tau = 0.5 + 3.0 * nu
    steps_per_unit = length / amplitude
    every = max(1, int(round(steps_per_unit / samples_per_unit)))
    steps = int(round(t_star_end * steps_per_unit))
    t, e = energy_history(n, tau, amplitude, steps, every, precision=precision)
    t_star = t / steps_per_unit
    e_star = e / amplitude ** 2
    eps = -np.gradient(e_star, t_star)
    return t_star, e_star, eps, tau


@pytest.mark.slow
def test_taylor_green_re1600_transition():
    """64^3, Re = 1600, U = 0.05, 20 convective times without NaN; the dissipation peak lies within
    10 % and 1 t* of the DNS value eps* = 0.0127 at t* = 9 (Brachet et al. 1983; van Rees et al. 2011).
    Measured (docs/VALIDATION.md): 0.01206 at t* = 8.51 (sampled every 0.25 t*), 16 min on the 2-core VM."""
    t, e, eps, tau = dissipation_history(64, 1600.0, 0.05, 20.0)
    assert np.all(np.isfinite(e))
    i = int(np.argmax(eps))
    log.info("TGV Re 1600 64^3 tau %.6f: peak eps* %.5f at t* %.2f", tau, eps[i], t[i])
    assert abs(t[i] - 9.0) < 1.0
    assert eps[i] == pytest.approx(0.0127, rel=0.10)
