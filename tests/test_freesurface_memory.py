"""Free-surface memory (paper section 2.2): populations only in the blocks at the water, results unchanged.

Blocks wholly in the gas and not next to the water hold no LBM populations (:mod:`iceresist.freesurface.pool`).
The CI cases use BGK in float64, the variant ``tests/test_freesurface_fluid.py`` compiles as well.
"""

import math

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.errors import InputError
from iceresist.freesurface.fluid import FreeSurfaceFluid
from iceresist.freesurface.pool import FPool, needed_blocks
from iceresist.grid import flags as FL
from iceresist.grid.forest import BlockForest, Face
from iceresist.lbm.stream import pooled_source, stream_collide_source

WALLS = {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}
F_BYTES_PER_BLOCK = 2 * 27 * 8 * 512   # two float64 buffers of 27 populations x 512 cells


def _fluid(forest, margin, target=jit.cpu, g=1e-4, depth=10.0):
    return FreeSurfaceFluid(forest, tau=0.8, gravity_lattice=g, depth_cells=depth, operator="bgk",
                            precision="float64", target=target, f_pool_margin=margin)


@pytest.mark.parametrize("depth, wet_layers", [(16.0, 2), (32.0, 4)])
def test_f_bytes_follow_the_wet_blocks(depth, wet_layers):
    """A 16 x 16 x 64 tank (2 x 2 x 8 blocks). 1/4 full: 8 wet blocks + 4 above them hold rows (37.5 % of the
    blocks), with the 25 % margin 14 rows = 43.8 % of the full box's f bytes; 1/2 full: 16 + 4 + 4 = 24 rows
    (75 %). The phase field (h of D3Q15, phi) stays in every block."""
    fo = BlockForest.uniform((16, 16, 64), WALLS)
    full = _fluid(fo, None, depth=depth)
    pooled = _fluid(fo, 0.25, depth=depth)
    for fs in (full, pooled):
        fs.initialize()
    wet, halo = 4 * wet_layers, 4
    assert pooled.fluid.pool.rows_in_use == wet + halo
    assert pooled.fluid.pool.capacity == wet + halo + math.ceil(0.25 * wet)
    nb = fo.nblocks
    assert full.allocated_bytes()["f"] == nb * F_BYTES_PER_BLOCK + 4 * nb
    assert pooled.allocated_bytes()["f"] == pooled.fluid.pool.capacity * F_BYTES_PER_BLOCK + 4 * nb
    assert pooled.allocated_bytes()["phase"] == full.allocated_bytes()["phase"]
    if wet_layers == 2:
        assert (wet + halo) / nb <= 0.40
        assert pooled.allocated_bytes()["f"] / full.allocated_bytes()["f"] == pytest.approx(14 / 32, rel=1e-3)
    # the liquid state is the same: the rows hold exactly the full box's populations of those blocks
    blocks, rows = pooled.fluid.rows()
    assert np.array_equal(rows, full.fluid.rows()[1][blocks])
    assert np.array_equal(np.asarray(pooled.fluid.flags), np.asarray(full.fluid.flags))


def test_pool_releases_reuses_and_grows():
    """Host book-keeping on a 4 x 1 x 1 row of blocks: water moving from block 0 to block 3 releases the rows
    behind it and reuses them; a pool too small for the blocks the water now needs grows (by the needed
    blocks plus 1/4 of the wet ones) and keeps the rows it had."""
    fo = BlockForest.uniform((32, 8, 8), WALLS)
    pool = FPool(fo.nbr, margin=0.0)
    wet = np.array([1, 0, 0, 0], bool)
    pool.start(wet)
    assert pool.capacity == 2 and list(pool.fslot) == [0, 1, -1, -1]
    assert list(needed_blocks(np.array([0, 1, 0, 0], bool), fo.nbr)) == [True, True, True, False]
    assert list(pool.update(np.array([0, 1, 0, 0], bool))) == [2]
    assert pool.capacity == 3 + 1 and pool.grown == 1
    assert list(pool.fslot[:2]) == [0, 1] and pool.fslot[2] in (2, 3)
    big = FPool(fo.nbr, margin=1.0)
    big.start(wet)
    assert big.capacity == 3
    assert list(big.update(np.array([0, 1, 0, 0], bool))) == [2]
    assert list(big.fslot) == [0, 1, 2, -1]
    acquired = big.update(np.array([0, 0, 0, 1], bool))   # blocks 0, 1 released, block 3 takes a freed row
    assert list(acquired) == [3] and list(big.fslot) == [-1, -1, 2, 1]
    assert big.rows_in_use == 2


def test_pooled_kernel_source_reads_f_only_through_the_map():
    src = pooled_source(stream_collide_source(loop_cells=True, free_surface=True))
    lines = [ln for ln in src.splitlines() if "src[" in ln or "dst[" in ln]
    assert lines and all("src[sb, " in ln or "src[fslot[" in ln or "dst[sb, " in ln for ln in lines)
    assert src.startswith("def stream_collide_block(b, src, dst,") and src.splitlines()[0].endswith("fslot):")


def _dam_break(target, margin, steps, shape=(48, 8, 16), column=8, depth=12.0, g=5e-4, u0=0.02, toe=-4.5):
    """Column of water over x < ``column`` cells in a closed flume moving at ``u0`` along +x; the column next
    to it holds water up to ``toe`` cells, the rest of the floor is dry."""
    fo = BlockForest.uniform(shape, WALLS)
    fs = _fluid(fo, margin, target=target, g=g, depth=depth)
    zs = np.full(shape[:2], -4.5)
    zs[:column] = depth
    zs[column] = toe
    fs.initialize(surface=zs, u=(u0, 0.0, 0.0))
    fs.step(steps)
    return fs


def _compare(a, b):
    fa, fb = a.fluid.populations(), b.fluid.populations()
    flags = np.asarray(a._host(a.fluid.flags))
    assert np.array_equal(flags, np.asarray(b._host(b.fluid.flags)))
    liquid = (flags & FL.FLUID) != 0
    return (np.abs(fa.transpose(1, 0, 2)[:, liquid] - fb.transpose(1, 0, 2)[:, liquid]).max(),
            np.abs(a.phase.phi_host() - b.phase.phi_host()).max())


def test_dam_break_pooled_equals_full_box_bit_for_bit():
    """48 x 8 x 16 flume (6 x 1 x 2 blocks), column 8 cells long and 12 high, g = 5e-4: the pool starts with
    4 rows in use (x-blocks 0 and 1) of 6; by step 60 the front has crossed into x-block 1 and both blocks of
    x-block 2 took a row (measured: at step 41-50). The run matches the full-box run bit for bit
    (populations of every liquid cell, phi, flags, volume)."""
    pooled = _dam_break(jit.cpu, 0.75, 60)
    full = _dam_break(jit.cpu, None, 60)
    pool = pooled.fluid.pool
    assert pool.capacity == 4 + math.ceil(0.75 * 2) == 6 < pooled.nblocks
    assert pool.rows_in_use == 6
    assert pool.fslot[pooled.forest.index[(0, 2, 0, 0)]] >= 0 and pool.fslot[pooled.forest.index[(0, 3, 0, 0)]] < 0
    df, dphi = _compare(pooled, full)
    assert df == 0.0 and dphi == 0.0
    assert pooled.volume() == full.volume()


def test_dam_break_pool_grows_and_still_equals_full_box():
    """With no margin the pool of the same dam break must grow (6 blocks needed, 4 rows at the start); the
    grown run still matches the full-box run bit for bit."""
    grown = _dam_break(jit.cpu, 0.0, 60)
    full = _dam_break(jit.cpu, None, 60)
    assert grown.fluid.pool.grown >= 1 and grown.fluid.pool.capacity >= 6
    df, dphi = _compare(grown, full)
    assert df == 0.0 and dphi == 0.0


def test_pool_margin_must_be_non_negative():
    fo = BlockForest.uniform((32, 8, 8), WALLS)
    with pytest.raises(InputError, match=r"free_surface\.f_pool_margin must be >= 0"):
        FPool(fo.nbr, margin=-0.5)


def test_cuda_pooled_matches_cpu_full_box():
    """CUDA simulator, 24 x 8 x 8 (3 blocks), water moving at 0.1 along +x with its toe at x = 8: block 1 gets
    wet and block 2 takes a row at step 2 (filled on the device); after 3 steps the pooled CUDA run equals
    the full-box CPU run to 1e-12."""
    kw = dict(shape=(24, 8, 8), column=8, depth=5.0, g=1e-4, u0=0.1, toe=0.45)
    gpu = _dam_break(jit.cuda(), 1.0, 0, **kw)
    cpu = _dam_break(jit.cpu, None, 0, **kw)
    assert gpu.fluid.pool.capacity == 3 and gpu.fluid.pool.rows_in_use == 2
    for fs in (gpu, cpu):
        fs.step(3)
    assert gpu.fluid.pool.rows_in_use == 3
    df, dphi = _compare(gpu, cpu)
    assert df < 1e-12 and dphi < 1e-12


@pytest.mark.parametrize("operator", ["bgk", "cumulant"])
def test_block_form_of_the_pooled_update_equals_the_per_cell_form(operator):
    """The CPU f update takes all-liquid blocks in the vectorised block form (line gather, collision across the
    cells with the force rho g of each cell) and the blocks at the surface cell by cell; the per-cell form over
    every block (what CUDA runs) gives the same flow: a sloshing 48 x 24 x 48 tank (its 12 inner blocks under the
    surface away from the walls are all liquid) over 12 steps agrees to round-off (float64; fast-math may order the
    sums differently)."""
    from iceresist.backends.launch import CellLauncher
    from iceresist.lbm.codegen import compile_source
    from iceresist.lbm.solver import collide_builder
    from iceresist.lbm.stream import POOL_ARGS, cell_device, stream_namespace

    fo = BlockForest.uniform((48, 24, 48), WALLS)
    runs = []
    for form in ("block", "cell"):
        fs = FreeSurfaceFluid(fo, tau=0.6, gravity_lattice=5e-4, depth_cells=36.4, operator=operator,
                              precision="float64", target=jit.cpu, f_pool_margin=None)
        if form == "cell":
            collide = collide_builder(operator)(jit.cpu, np.float64)
            fn = compile_source(pooled_source(stream_collide_source(loop_cells=True, free_surface=True)),
                                "stream_collide_block", stream_namespace(jit.cpu, np.float64, collide),
                                cell_device(jit.cpu))
            fs.fluid._launch = CellLauncher(jit.cpu, fn, POOL_ARGS, per_block=True, label="f_update")
        zs = 36.4 + 3.0 * np.cos(np.pi * (np.arange(48) + 0.5) / 48)[:, None] * np.ones((1, 24))
        fs.initialize(surface=zs, u=(0.01, -0.005, 0.0))
        fs.step(12)
        runs.append(fs)
    flags = np.asarray(runs[0]._host(runs[0].fluid.flags))
    full = (flags == FL.FLUID).all(axis=1)
    assert full.sum() >= 12                                 # the block path ran on the inner blocks
    df, dphi = _compare(*runs)
    assert df < 1e-13 and dphi < 1e-13
    f = runs[0].fluid.populations()
    assert np.abs(f).max() > 1e-3                           # the flow moves (not two zero fields agreeing)
