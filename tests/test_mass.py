"""Mass conservation of the fused kernel over 1000 steps (periodic box, and walls with a moving lid)."""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.grid import BlockForest, Face
from iceresist.lbm.solver import LBMSolver

TOL = {"float32": 1e-6, "float64": 1e-12}


@pytest.mark.parametrize("walls", [False, True])
def test_mass_drift_over_1000_steps(precision, walls, rng):
    faces = {"y-": Face("wall"), "y+": Face("moving_wall", (0.03, 0.0, 0.0))} if walls else None
    fo = BlockForest.uniform((16, 16, 16), faces=faces)
    s = LBMSolver(fo, tau=0.6, force=(1e-6, 0.0, 0.0), operator="bgk", precision=precision, target=jit.cpu)
    shape = fo.shape_cells
    s.initialize(rho=1 + 0.01 * rng.standard_normal(shape), u=0.01 * rng.standard_normal((3, *shape)))
    m0 = s.mass()
    s.step(1000)
    drift = abs(s.mass() - m0) / m0
    assert drift < TOL[precision], drift
    rho, u = s.macroscopic()
    assert np.all(np.isfinite(rho)) and np.abs(u).max() < 0.1
