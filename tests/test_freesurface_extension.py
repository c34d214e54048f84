"""Velocity extension into the gas: the phase field's interface velocity (iceresist.freesurface.extension)."""

import numpy as np

from iceresist.backends import jit
from iceresist.freesurface.extension import UNFILLED, extend_velocity, extension_launcher
from iceresist.grid.forest import CELLS, BlockForest, Face


def test_liquid_velocity_extended_three_layers_then_zero():
    fo = BlockForest.uniform((8, 8, 16), {f: Face("wall") for f in ("x-", "x+", "z-", "z+")})
    z = np.arange(16)
    x = np.arange(8)
    phi = fo.from_dense(np.broadcast_to((z < 8).astype(float), (8, 8, 16)).copy())   # liquid z < 8
    u_dense = np.zeros((3, 8, 8, 16))
    u_dense[0] = 0.01 * (1 + x[:, None, None])          # shear along x, varies with x only
    u_dense[2] = 0.02
    u_dense[:, :, :, 8:] = 7.0                           # garbage in the gas: must be overwritten
    u = np.ascontiguousarray(fo.from_dense(u_dense).transpose(1, 0, 2))   # (nblocks, 3, cell)
    dist = np.zeros((fo.nblocks, CELLS), np.int8)
    extend_velocity(extension_launcher(jit.cpu, "float64"), fo.nblocks, phi, u, dist, fo.nbr.astype(np.int64))
    ud = fo.to_dense(u.transpose(1, 0, 2))
    dd = fo.to_dense(dist)
    assert np.array_equal(dd[0, 0], [0] * 8 + [1, 2, 3] + [UNFILLED] * 5)
    # a uniform-in-z liquid velocity is carried unchanged into the three gas layers
    for k in (8, 9, 10):
        assert np.allclose(ud[2, :, :, k], 0.02, atol=1e-15)
    # linear in x: the symmetric mean keeps it, away from the x walls (two cells of bias in the first layer,
    # where the link extrapolation meets the wall, one more per layer)
    for k in (8, 9):
        assert np.allclose(ud[0, 3:5, :, k], u_dense[0, 3:5, :, 0], atol=1e-15)


def test_first_gas_layer_extrapolates_linearly():
    """A liquid velocity linear in z is continued linearly into the first gas layer (the kinematic condition at
    the sub-cell surface), then copied into the next layers."""
    fo = BlockForest.uniform((8, 8, 16), {f: Face("wall") for f in ("z-", "z+")})
    z = np.arange(16)
    phi = fo.from_dense(np.broadcast_to((z < 8).astype(float), (8, 8, 16)).copy())
    u_dense = np.zeros((3, 8, 8, 16))
    u_dense[2] = 0.001 * z                              # w = 0.001 z in the liquid
    u = np.ascontiguousarray(fo.from_dense(u_dense).transpose(1, 0, 2))
    dist = np.zeros((fo.nblocks, CELLS), np.int8)
    extend_velocity(extension_launcher(jit.cpu, "float64"), fo.nblocks, phi, u, dist, fo.nbr.astype(np.int64))
    ud = fo.to_dense(u.transpose(1, 0, 2))
    assert np.allclose(ud[2, :, :, 8], 0.008, atol=1e-15)
    assert np.allclose(ud[2, :, :, 9:11], 0.008, atol=1e-15)
    assert np.all(ud[:, :, :, 11:] == 0.0)
    assert np.array_equal(ud[:, :, :, :8], u_dense[:, :, :, :8])


def test_block_form_gives_the_cell_form():
    """The CPU block form (a padded scratch, one constant offset per direction) against the per-cell form on a
    wavy surface with walls on x and z, periodic in y, a hole in the forest (a solid corner without blocks) and
    the blocks far from the surface skipped (``near``), in both precisions: the same layers, the same velocities
    to round-off (the two forms contract multiply-adds differently)."""
    from iceresist.freesurface.fluid import block_phase_launchers

    faces = {f: Face("wall") for f in ("x-", "x+", "z-", "z+")}
    fo = BlockForest.uniform((24, 16, 48), faces, solid=lambda x, y, z: (x >= 16) & (z >= 40))
    x, y, z = np.meshgrid(np.arange(24), np.arange(16), np.arange(48), indexing="ij")
    surface = 13.3 + 4.0 * np.sin(0.5 * x + 0.3 * y)
    rng = np.random.default_rng(3)
    for precision in ("float32", "float64"):
        real = np.dtype(precision).type
        phi = fo.from_dense((0.5 + 0.5 * np.tanh((surface - z - 0.5) / 1.5)).astype(real))
        u0 = np.ascontiguousarray(fo.from_dense(rng.normal(0, 0.02, (3, 24, 16, 48)).astype(real))
                                  .transpose(1, 0, 2))
        flags = np.zeros((fo.nblocks, CELLS), np.uint8)
        phases, near = np.zeros(fo.nblocks, np.int8), np.zeros(fo.nblocks, np.int8)
        phases_launch, near_launch = block_phase_launchers(jit.cpu, precision)
        nbr = fo.nbr.astype(np.int64)
        phases_launch(fo.nblocks, phi, flags, phases)
        near_launch(fo.nblocks, phases, nbr, near)
        assert 0 < (near == 3).sum() < fo.nblocks
        out = []
        for vector in (True, False):
            u, dist = u0.copy(), np.zeros((fo.nblocks, CELLS), np.int8)
            extend_velocity(extension_launcher(jit.cpu, precision, vector), fo.nblocks, phi, u, dist, nbr,
                            near=near)
            out.append((u, dist))
        assert np.array_equal(out[0][1], out[1][1])
        scale = np.abs(out[1][0]).max()
        assert scale > 0.01
        assert np.abs(out[0][0] - out[1][0]).max() <= 8 * np.finfo(real).eps * scale   # round-off (fused multiply-adds)
        assert {1, 2, 3, UNFILLED} <= set(np.unique(out[0][1]).tolist())
