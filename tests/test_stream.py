"""The fused pull stream-collide kernel against a dense NumPy reference, with every boundary kind."""

import numpy as np
import pytest

from iceresist.grid import BlockForest, Face
from iceresist.lbm.solver import LBMSolver
from tests.test_stream_reference import step as reference_step

FACES = {
    "y-": Face("wall"), "y+": Face("moving_wall", (0.05, 0.0, 0.02)),
    "z-": Face("velocity_inlet", (0.01, 0.0, 0.03)), "z+": Face("pressure_outlet", density=1.01),
}


def _solid(x, y, z):
    return (x == 5) & (y == 9) & (z >= 6) & (z <= 9)


def mixed_case(precision, target, rng, operator="bgk"):
    """16^3 cells (2x2x2 blocks): periodic x, walls in y (one moving), inlet/outlet in z, a solid bar."""
    fo = BlockForest.uniform((16, 16, 16), faces=FACES, solid=_solid)
    s = LBMSolver(fo, tau=0.7, force=(1e-5, -2e-5, 3e-6), operator=operator, precision=precision, target=target)
    shape = fo.shape_cells
    rho = 1 + 0.01 * rng.standard_normal(shape)
    u = 0.02 * rng.standard_normal((3, *shape))
    s.initialize(rho=rho, u=u)
    return fo, s


@pytest.mark.parametrize("precision, tol", [("float64", 1e-15), ("float32", 2e-7)])
def test_fused_step_matches_numpy_reference(precision, tol, rng):
    from iceresist.backends import jit

    fo, s = mixed_case(precision, jit.cpu, rng)
    f = fo.to_dense(s.populations().transpose(1, 0, 2))
    solid = ~np.nan_to_num(fo.to_dense(fo.fluid.astype(float))).astype(bool)
    f[:, solid] = 0.0
    for _ in range(3):
        f = reference_step(f, fo.faces, solid, 1 / s.tau, s.force)
    s.step(3)
    g = fo.to_dense(s.populations().transpose(1, 0, 2))
    err = np.abs(g - f)[:, ~solid].max()
    assert err < tol * 10, err
    assert s.iteration == 3


def test_rest_state_stays_at_rest():
    from iceresist.backends import jit

    fo = BlockForest.uniform((8, 16, 8), faces={"y-": Face("wall"), "y+": Face("wall")})
    s = LBMSolver(fo, tau=0.9, operator="bgk", precision="float64", target=jit.cpu)
    s.step(10)
    rho, u = s.macroscopic()
    assert np.abs(rho - 1).max() == 0.0 and np.abs(u).max() == 0.0
