"""Block forest: neighbour table against a dense-index reference, Morton order, memory following fluid."""

from types import SimpleNamespace

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.grid import BlockForest, Face
from iceresist.grid import flags as FL
from iceresist.grid.forest import morton_key
from iceresist.grid.grid import Grid
from iceresist.grid.octree import BlockOctree
from iceresist.lattice import C, Q


def _dense_block_reference(forest):
    """Block index of every dense cell (-1 where unallocated), built without the forest's tables."""
    idx = np.full(forest.shape_cells, -1)
    ids = np.broadcast_to(np.arange(forest.nblocks)[:, None], (forest.nblocks, 512))
    dense = forest.to_dense(ids.astype(float))
    idx[~np.isnan(dense)] = dense[~np.isnan(dense)].astype(int)
    return idx


@pytest.mark.parametrize("faces", [
    None,
    {"y-": Face("wall"), "y+": Face("moving_wall", (0.05, 0, 0))},
    {"x-": Face("velocity_inlet", (0.02, 0, 0)), "x+": Face("pressure_outlet"), "z-": Face("wall"),
     "z+": Face("wall")},
])
def test_neighbour_table_matches_dense_reference(faces):
    fo = BlockForest.uniform((16, 24, 32), faces=faces)
    idx = _dense_block_reference(fo)
    shape = np.array(fo.shape_cells)
    periodic = [fo.faces[a + "-"].kind == "periodic" for a in "xyz"]
    for b in range(fo.nblocks):
        corner = fo.origin[b] * 8
        for q in range(Q):
            p = corner + 8 * C[q]              # the same corner cell one block over in direction q
            outside = False
            for a in range(3):
                if periodic[a]:
                    p[a] %= shape[a]
                elif not 0 <= p[a] < shape[a]:
                    outside = True
            expect = -1 if outside else idx[tuple(p)]
            assert fo.nbr[b, q] == expect, (b, q)


def test_pull_source_is_the_cell_minus_c_q():
    fo = BlockForest.uniform((16, 16, 16), faces={"x-": Face("wall"), "x+": Face("wall")})
    x, y, z = fo.cell_coordinates()
    for q in range(1, Q):
        nb, sc, bc = fo.pull_source(q)
        sx, sy, sz = x - C[q, 0], y - C[q, 1], z - C[q, 2]
        inside = (sx >= 0) & (sx < 16)
        assert np.array_equal(nb >= 0, inside)
        ok = nb >= 0
        gx, gy, gz = fo.cell_coordinates()
        assert np.array_equal(gx[nb[ok], sc[ok]], sx[ok])
        assert np.array_equal(gy[nb[ok], sc[ok]], sy[ok] % 16)
        assert np.array_equal(gz[nb[ok], sc[ok]], sz[ok] % 16)
        # links out of the domain name the crossed face: row 1 = x-, row 2 = x+
        assert set(np.unique(bc[~ok])) <= {1, 2}
        assert np.all(bc[~ok] == np.where(sx[~ok] < 0, 1, 2))


def test_blocks_follow_the_morton_curve():
    fo = BlockForest.uniform((32, 32, 32))
    assert np.all(np.diff(fo.morton.astype(np.int64)) > 0)
    assert tuple(map(tuple, fo.origin[:8].tolist())) == ((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0),
                                             (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1))
    # bit i of x goes to bit 3i, of y to 3i+1, of z to 3i+2
    assert int(morton_key(1, 0, 0)) == 1 and int(morton_key(0, 1, 0)) == 2 and int(morton_key(0, 0, 1)) == 4
    assert int(morton_key(2, 0, 0)) == 8 and int(morton_key(3, 3, 3)) == 63


def test_solid_blocks_are_not_allocated():
    def solid(x, y, z):                      # a wall slab filling the upper half in y
        return y >= 16

    fo = BlockForest.uniform((16, 32, 16), faces={"y-": Face("wall"), "y+": Face("wall")}, solid=solid)
    assert fo.nblocks == 2 * 2 * 2
    assert fo.cells == 16 * 16 * 16
    assert np.all(fo.origin[:, 1] < 2)
    # the blocks below the slab see -1 upwards and bounce back there (row 0: resting wall)
    up = [q for q in range(Q) if C[q, 1] == 1 and C[q, 0] == 0 and C[q, 2] == 0][0]
    top = fo.origin[:, 1] == 1
    assert np.all(fo.nbr[top, up] == -1)
    top_cells = fo.cell_coordinates()[1] == 15
    assert np.all(fo.flags[top_cells] & FL.NEAR_WALL)


def test_partially_solid_block_flags():
    fo = BlockForest.uniform((8, 8, 8), solid=lambda x, y, z: (x == 3) & (y == 3) & (z == 3))
    dense = fo.to_dense(fo.flags.astype(float))
    assert dense[3, 3, 3] == FL.SOLID
    assert dense[4, 4, 4] == FL.FLUID | FL.NEAR_WALL    # corner neighbour of the solid cell
    assert dense[5, 3, 3] == FL.FLUID
    assert fo.cells == 511


def test_dense_round_trip(rng):
    fo = BlockForest.uniform((16, 8, 24), solid=lambda x, y, z: z >= 16)
    a = rng.standard_normal((16, 8, 24))
    back = fo.to_dense(fo.from_dense(a))
    assert np.array_equal(back[:, :, :16], a[:, :, :16])
    assert np.all(np.isnan(back[:, :, 16:]))
    v = rng.standard_normal((3, fo.nblocks, 512))
    assert np.array_equal(fo.from_dense(fo.to_dense(v)), v)
    x, y, z = fo.cell_coordinates()
    assert np.array_equal(fo.to_dense(x.astype(float))[:, :, :16],
                          np.broadcast_to(np.arange(16)[:, None, None], (16, 8, 16)))


@pytest.mark.parametrize("kwargs, words", [
    (dict(shape_cells=(16, 20, 8)), "shape_cells y: 20"),
    (dict(shape_cells=(16, 16)), "3 entries"),
    (dict(shape_cells=(8, 8, 8), faces={"x-": Face("wall")}), "periodic faces must be paired"),
    (dict(shape_cells=(8, 8, 8), faces={"top": Face("wall")}), "unknown key"),
])
def test_input_errors_name_the_field(kwargs, words):
    with pytest.raises(InputError, match=words):
        BlockForest.uniform(**kwargs)


def test_face_kind_is_checked():
    with pytest.raises(InputError, match="face kind 'free_slip' is not one of .*slip"):
        Face("free_slip")


def test_a_grid_on_one_process_gives_each_value_itself():
    """:class:`iceresist.grid.grid.Grid` without ranks: sums, gathers and exchanges are the values themselves, so a
    model asks the grid and never branches on the rank count (the two-rank side: tests/test_mpi.py)."""
    g = Grid.levels(BlockOctree((2, 1, 1), 0), None, comm=SimpleNamespace(size=1))     # one level: uniform
    assert g.comm is None and g.decomp is None and g.root and g.describe() == {}
    assert g.views is g.global_views and g.views[0].forest.nblocks == 2
    rows = np.arange(6.0).reshape(2, 3)
    assert g.gather(0, rows) is rows and g.gather_leaves(0, rows) is rows and g.level_rows(0, rows) is rows
    assert g.sum(2.5) == 2.5 and g.max(3) == 3.0 and g.all(np.True_) is True and g.bcast("x") == "x"
    assert g.first_given(None) is None
    g.reduce_arrays(rows)
    assert rows.sum() == 15.0
    levels = Grid.levels(BlockOctree((2, 1, 1), 1).refine(lambda lo, hi: (lo[:, 0] < 8).astype(int)), None)
    assert [v is not None for v in levels.views] == [True, True]
    assert levels.own_leaves(1) == 8 and levels.own_leaves(0) == 1
    assert levels.gather(1, rows) is rows and levels.level_rows(0, rows) is rows
