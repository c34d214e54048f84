"""BGK reference operator: conserves mass, adds exactly F of momentum, relaxes to f_eq."""

import numpy as np
import pytest

from iceresist import lattice as L
from iceresist.backends.jit import real_type
from iceresist.lbm.collide import build_collide_bgk


def _run_cpu(f, omega, F, real):
    from iceresist.backends import jit

    collide = build_collide_bgk(jit.cpu, real)
    return np.array(collide(tuple(real(v) for v in f), real(omega), *(real(v) for v in F)))


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_bgk_conservation_and_force(precision, rng):
    real = real_type(precision)
    feq = L.equilibrium(1.02, 0.04, -0.03, 0.02)
    f = feq * (1 + 0.01 * rng.standard_normal(27)) - L.W
    F = np.array([1e-4, -2e-4, 3e-5])
    out = _run_cpu(f, 1.3, F, real).astype(float)
    tol = 1e-6 if precision == "float32" else 1e-14
    assert abs(out.sum() - f.sum()) < tol
    assert np.allclose(L.C.T @ out - L.C.T @ f, F, atol=tol)


def test_bgk_omega_one_gives_equilibrium(rng):
    f = L.equilibrium(0.98, 0.02, 0.01, -0.05) * (1 + 0.02 * rng.standard_normal(27))
    rho = f.sum()
    u = L.C.T @ f / rho
    out = _run_cpu(f - L.W, 1.0, (0, 0, 0), np.float64) + L.W
    assert np.allclose(out, L.equilibrium(rho, *u), atol=1e-14)
