"""Channel flows against closed forms: force-driven Poiseuille (second order), moving-wall Couette
(exact), and a velocity-inlet / pressure-outlet channel that carries the imposed flow rate.

Walls are half-way: the wall sits half a cell outside the last fluid cell, so with N cells across
cell j (0-based) lies at y = j + 1/2 and the walls at y = 0 and y = N.
"""

from functools import lru_cache

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.grid import BlockForest, Face
from iceresist.lbm.solver import LBMSolver, operator_available

TAU = 0.8                     # fixed for every resolution; nu = (tau - 1/2)/3 = 0.1
NU = (TAU - 0.5) / 3.0
U_MAX = 0.01                  # centre-line velocity kept fixed: force ~ 1/N^2 (diffusive scaling)
OPERATORS = ["bgk"] + (["cumulant"] if operator_available("cumulant") else [])


def run_to_steady(solver, chunk, rtol, max_steps):
    """Step in chunks until the largest velocity change over a chunk is below rtol * max|u|."""
    prev = solver.macroscopic()[1]
    while solver.iteration < max_steps:
        solver.step(chunk)
        u = solver.macroscopic()[1]
        change = np.nanmax(np.abs(u - prev)) / np.nanmax(np.abs(u))
        prev = u
        if change < rtol:
            return u
    raise AssertionError(f"no steady state after {solver.iteration} steps (last relative change {change:.2e})")


@lru_cache(maxsize=None)
def poiseuille_error(n, operator, precision="float64"):
    """Relative L2 error of the steady profile u_x(y) against F/(2 nu) y (N - y)."""
    force = 8.0 * NU * U_MAX / n ** 2
    fo = BlockForest.uniform((8, n, 8), faces={"y-": Face("wall"), "y+": Face("wall")})
    s = LBMSolver(fo, tau=TAU, force=(force, 0.0, 0.0), operator=operator, precision=precision, target=jit.cpu)
    y = np.arange(n) + 0.5
    exact = force / (2 * NU) * y * (n - y)
    u0 = np.zeros((3, 8, n, 8))
    u0[0] = exact[None, :, None]
    s.initialize(u=u0)
    # the slowest mode decays as exp(-nu pi^2 t / N^2): chunks of a tenth of that time
    u = run_to_steady(s, chunk=max(50, int(0.1 * n * n / (NU * np.pi ** 2))), rtol=1e-7, max_steps=40 * n * n)
    ux = u[0]
    assert np.nanmax(np.abs(ux - ux[:1, :, :1])) < 1e-12       # uniform along x and z
    assert np.nanmax(np.abs(u[1:])) < 1e-12
    prof = ux[0, :, 0]
    return float(np.sqrt(np.sum((prof - exact) ** 2) / np.sum(exact ** 2)))


@pytest.mark.parametrize("operator", OPERATORS)
def test_poiseuille_profile_32(operator):
    err = poiseuille_error(32, operator)
    assert err < 1e-3, err


@pytest.mark.parametrize("operator", OPERATORS)
def test_poiseuille_second_order_8_16_32(operator):
    e = [poiseuille_error(n, operator) for n in (8, 16, 32)]
    orders = np.log2(np.array(e[:-1]) / np.array(e[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.2), (e, orders)


@pytest.mark.slow
@pytest.mark.parametrize("operator", OPERATORS)
def test_poiseuille_second_order_16_32_64(operator):
    e = [poiseuille_error(n, operator) for n in (16, 32, 64)]
    orders = np.log2(np.array(e[:-1]) / np.array(e[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.2), (e, orders)


@pytest.mark.parametrize("operator", OPERATORS)
def test_couette_linear_profile(operator):
    """Resting wall at y = 0, wall moving at U at y = N: u_x = U y / N exactly (to round-off)."""
    n, U = 16, 0.02
    fo = BlockForest.uniform((8, n, 8), faces={"y-": Face("wall"), "y+": Face("moving_wall", (U, 0.0, 0.0))})
    s = LBMSolver(fo, tau=TAU, operator=operator, precision="float64", target=jit.cpu)
    y = np.arange(n) + 0.5
    u0 = np.zeros((3, 8, n, 8))
    u0[0] = (U * y / n)[None, :, None]
    s.initialize(u=u0)
    u = run_to_steady(s, chunk=200, rtol=1e-13, max_steps=20000)
    assert np.nanmax(np.abs(u[0] - (U * y / n)[None, :, None])) < 1e-12
    assert np.nanmax(np.abs(u[1:])) < 1e-13


def test_inlet_outlet_channel_carries_the_imposed_flow_rate():
    """Inlet x- at U, anti-bounce-back outlet x+ at rho = 1, walls in y, periodic z.

    In the steady state the mass flux through every cross-section equals the inflow
    rho0 U ny nz; the anti-bounce-back outlet holds the density at the outlet face near 1.
    """
    nx, ny, nz, U = 32, 16, 8, 0.02
    faces = {"x-": Face("velocity_inlet", (U, 0.0, 0.0)), "x+": Face("pressure_outlet", density=1.0),
             "y-": Face("wall"), "y+": Face("wall")}
    fo = BlockForest.uniform((nx, ny, nz), faces=faces)
    s = LBMSolver(fo, tau=1.0, operator="bgk", precision="float64", target=jit.cpu)   # faster to steady
    s.initialize(u=(U, 0.0, 0.0))
    run_to_steady(s, chunk=200, rtol=1e-6, max_steps=20000)
    rho, u = s.macroscopic()
    flux = (rho * u[0]).sum(axis=(1, 2))          # mass flux through each x-section
    imposed = U * ny * nz
    assert np.all(np.abs(flux / imposed - 1) < 1e-4), flux / imposed
    assert np.ptp(flux) / imposed < 1e-4            # steady: the same flux through every section
    assert abs(rho[-1].mean() - 1.0) < 2e-3         # outlet density held at the face value
    assert rho[0].mean() > rho[-1].mean()           # a pressure drop drives the channel flow
