"""The CPU block form of the fused update (pull into a block scratch, collision vectorised across
cells) against the per-cell form, on a forest where all-fluid blocks, mixed blocks and boundary
links meet: 24^3 cells (3x3x3 blocks), periodic x, walls in y, a solid bar in the middle block."""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.backends.launch import CellLauncher
from iceresist.grid import BlockForest, Face
from iceresist.lattice import Q
from iceresist.lbm.collide import build_collide_bgk
from iceresist.lbm.stream import ARGS, build_stream_collide_block


def _solid(x, y, z):
    return (x == 12) & (y >= 10) & (y <= 13) & (z == 11)


@pytest.mark.parametrize("precision, tol", [("float64", 1e-15)])
def test_block_form_matches_per_cell_form(precision, tol):
    real = jit.real_type(precision)
    fo = BlockForest.uniform((24, 24, 24), faces={"y-": Face("wall"), "y+": Face("wall")}, solid=_solid)
    full = (fo.flags == 1).all(axis=1)
    assert full.any() and not full.all()       # both gather paths are used
    collide = build_collide_bgk(jit.cpu, real)
    forms = [CellLauncher(jit.cpu, build_stream_collide_block(jit.cpu, real, collide, vector=v), ARGS,
                          per_block=True) for v in (True, False)]
    rng = np.random.default_rng(3)
    src = (0.01 * rng.standard_normal((fo.nblocks, Q, 512))).astype(real)
    src[np.broadcast_to(~fo.fluid[:, None, :], src.shape)] = 0.0
    tables = (fo.nbr_key.astype(np.int32), fo.link_bc.astype(np.int32), fo.flags.astype(np.uint8),
              fo.bc_kind.astype(np.int32), fo.bc_velocity.astype(real), fo.bc_density.astype(real))
    scalars = (real(1 / 0.7), real(1e-5), real(-2e-5), real(3e-6))
    out = []
    for launch in forms:
        dst = np.zeros_like(src)
        launch(fo.nblocks, src, dst, *tables, *scalars)
        out.append(dst)
    fluid = np.broadcast_to(fo.fluid[:, None, :], src.shape)
    assert np.abs(out[0] - out[1])[fluid].max() <= tol * np.abs(out[1]).max()
    assert np.abs(out[0][fluid] - src[fluid]).max() > 1e-3   # the update did something
