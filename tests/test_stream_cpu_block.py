"""The CPU block form of the fused update (pull into a block scratch, collision vectorised across
cells) against the dense NumPy reference on a forest where all-fluid blocks, mixed blocks and
boundary links meet: 24^3 cells (3x3x3 blocks), periodic x and z, walls in y (one moving), a solid
bar in the middle block. The kernel is the one ``tests/test_stream.py`` compiles (bgk, float64)."""

import numpy as np

from iceresist.backends import jit
from iceresist.grid import BlockForest, Face
from iceresist.lbm.solver import LBMSolver
from tests.test_stream_reference import step as reference_step


def _solid(x, y, z):
    return (x == 12) & (y >= 10) & (y <= 13) & (z == 11)


def test_block_form_matches_numpy_reference(rng):
    fo = BlockForest.uniform((24, 24, 24), faces={"y-": Face("wall"), "y+": Face("moving_wall", (0.05, 0.0, 0.0))},
                             solid=_solid)
    full = (fo.flags == 1).all(axis=1)
    assert full.any() and not full.all()       # both gather paths are used
    s = LBMSolver(fo, tau=0.7, force=(1e-5, -2e-5, 3e-6), operator="bgk", precision="float64", target=jit.cpu)
    shape = fo.shape_cells
    s.initialize(rho=1 + 0.01 * rng.standard_normal(shape), u=0.02 * rng.standard_normal((3, *shape)))
    f = fo.to_dense(s.populations().transpose(1, 0, 2))
    solid = ~np.nan_to_num(fo.to_dense(fo.fluid.astype(float))).astype(bool)
    f[:, solid] = 0.0
    f0 = f.copy()
    for _ in range(2):
        f = reference_step(f, fo.faces, solid, 1 / s.tau, s.force)
    s.step(2)
    g = fo.to_dense(s.populations().transpose(1, 0, 2))
    assert np.abs(g - f)[:, ~solid].max() < 1e-14
    assert np.abs(g - f0)[:, ~solid].max() > 1e-3   # the update did something
