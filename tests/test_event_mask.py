"""The block masks that let the redistribution (paper section 2.4, the mass of covered and uncovered cells) skip
the cells with no event in reach (iceresist.coupling.bodystate): ``reach_mask`` names exactly the blocks the 26
neighbours of a cell lie in, and ``near_mask`` exactly the neighbour blocks that had an event."""

import numpy as np
from numba import njit

from iceresist.backends import jit
from iceresist.coupling.bodystate import build_event_mask, build_reach_mask
from iceresist.grid.forest import BlockForest


def _bit(bx, by, bz):
    return 1 << ((bx + 1) + 3 * (by + 1) + 9 * (bz + 1))


def test_reach_mask_names_the_blocks_of_the_26_neighbours_of_every_cell():
    reach = build_reach_mask(jit.cpu)
    masks = njit(lambda: [reach(c) for c in range(512)])()
    for c in range(512):
        x, y, z = c % 8, (c // 8) % 8, c // 64
        want = 0
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    want |= _bit((x + dx) // 8, (y + dy) // 8, (z + dz) // 8)
        assert masks[c] == want, (c, bin(masks[c]), bin(want))
    assert masks[1 + 8 * (1 + 8 * 1)] == _bit(0, 0, 0)           # an inner cell: its own block only
    assert bin(masks[0]).count("1") == 8 and bin(masks[511]).count("1") == 8


def test_near_mask_sets_the_bits_of_the_neighbour_blocks_with_events():
    fo = BlockForest.uniform((32, 24, 16))                         # 4 x 3 x 2 blocks, periodic
    nbr = np.ascontiguousarray(fo.nbr)
    index = {tuple(o): i for i, o in enumerate(fo.origin)}
    evt = np.zeros(fo.nblocks, np.int32)
    evt[index[(1, 1, 0)]] = 1
    evt[index[(3, 2, 1)]] = 1
    near = np.zeros(fo.nblocks, np.int32)
    mask = build_event_mask(jit.cpu)
    run = njit(lambda evt, nbr, near: [mask(b, evt, nbr, near) for b in range(len(near))])
    run(evt, nbr, near)
    shape = np.array([4, 3, 2])
    for b, o in enumerate(fo.origin):
        want = 0
        for bx in (-1, 0, 1):
            for by in (-1, 0, 1):
                for bz in (-1, 0, 1):
                    n = tuple((o + (bx, by, bz)) % shape)
                    if evt[index[n]]:
                        want |= _bit(bx, by, bz)
        assert near[b] == want, (tuple(o), bin(near[b]), bin(want))
    assert near[index[(1, 1, 0)]] & _bit(0, 0, 0) and near[index[(0, 0, 1)]] & _bit(1, 1, 1)
