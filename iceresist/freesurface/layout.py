"""The block layout the free-surface kernels run on, and the neighbour look-up they share.

Layout (docs/ARCHITECTURE.md, :class:`iceresist.grid.BlockForest`): 8x8x8-cell blocks,
cell index ``c = x + 8 * (y + 8 * z)``, arrays ``a[block, component, cell]``, and the
neighbour table ``forest.nbr[block, q]`` giving the block at offset ``lattice.C[q]``
(-1 outside the domain; ``nbr[b, 0] == b``).

:func:`build_neighbour` compiles the cell look-up used by every kernel here:
``neighbour(nbr, b, x, y, z, dx, dy, dz) -> (b2, c2)`` with ``b2 = -1`` outside, and
``neighbour_clamped`` which, where the step leaves the domain through a face,
stays on the boundary cell along that axis (a zero normal gradient: neutral
wetting, contact angle 90 degrees, at walls).
"""

from __future__ import annotations

import numpy as np

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.grid.forest import CELLS  # noqa: F401  (re-exported for the kernels)


#: Bits of a block's phase summary (:func:`iceresist.freesurface.fluid.build_block_phases`): a cell with gas (phi < 1/2
#: or the GAS flag), a cell with liquid (phi >= 1/2).
HAS_GAS, HAS_LIQUID = 1, 2

#: D3Q27 index of the offset (dx, dy, dz), stored at (dx+1) + 3 (dy+1) + 9 (dz+1).
DIR_OF_OFFSET = np.array([L.index_of(dx, dy, dz) for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)],
                         dtype=np.int64)


def build_neighbour(target):
    """Compile ``(neighbour, neighbour_clamped)`` for ``target``; see the module docstring."""
    dir_of = DIR_OF_OFFSET
    # face directions -x,+x,-y,+y,-z,+z in D3Q27 numbering
    fxm, fxp = L.index_of(-1, 0, 0), L.index_of(1, 0, 0)
    fym, fyp = L.index_of(0, -1, 0), L.index_of(0, 1, 0)
    fzm, fzp = L.index_of(0, 0, -1), L.index_of(0, 0, 1)

    def neighbour(nbr, b, x, y, z, dx, dy, dz):
        xs = x + dx
        ys = y + dy
        zs = z + dz
        bx = 0
        by = 0
        bz = 0
        if xs < 0:
            bx = -1
            xs += 8
        elif xs >= 8:
            bx = 1
            xs -= 8
        if ys < 0:
            by = -1
            ys += 8
        elif ys >= 8:
            by = 1
            ys -= 8
        if zs < 0:
            bz = -1
            zs += 8
        elif zs >= 8:
            bz = 1
            zs -= 8
        c2 = xs + 8 * (ys + 8 * zs)
        if bx == 0 and by == 0 and bz == 0:
            return b, c2
        return nbr[b, dir_of[(bx + 1) + 3 * (by + 1) + 9 * (bz + 1)]], c2

    def neighbour_clamped(nbr, b, x, y, z, dx, dy, dz):
        xs = x + dx
        ys = y + dy
        zs = z + dz
        bx = 0
        by = 0
        bz = 0
        if xs < 0:
            if nbr[b, fxm] < 0:
                xs = x
            else:
                bx = -1
                xs += 8
        elif xs >= 8:
            if nbr[b, fxp] < 0:
                xs = x
            else:
                bx = 1
                xs -= 8
        if ys < 0:
            if nbr[b, fym] < 0:
                ys = y
            else:
                by = -1
                ys += 8
        elif ys >= 8:
            if nbr[b, fyp] < 0:
                ys = y
            else:
                by = 1
                ys -= 8
        if zs < 0:
            if nbr[b, fzm] < 0:
                zs = z
            else:
                bz = -1
                zs += 8
        elif zs >= 8:
            if nbr[b, fzp] < 0:
                zs = z
            else:
                bz = 1
                zs -= 8
        c2 = xs + 8 * (ys + 8 * zs)
        if bx == 0 and by == 0 and bz == 0:
            return b, c2
        b2 = nbr[b, dir_of[(bx + 1) + 3 * (by + 1) + 9 * (bz + 1)]]
        if b2 < 0:
            return b, x + 8 * (y + 8 * z)
        return b2, c2

    return target.device(neighbour), target.device(neighbour_clamped)


#: Side of a block's scratch with a halo of one cell (:func:`build_halo_or`).
HALO1_SIDE = 10


def build_halo_or():
    """Compile the CPU function ``halo_or(mask, out)``: ``out[c]`` = the OR of ``mask`` over the 26 neighbours of
    cell c of a block, ``mask`` (int8) holding the block and a halo of one cell, ``HALO1_SIDE``^3 cells, x fastest,
    cell (x, y, z) of the block at (x + 1) + 10 ((y + 1) + 10 (z + 1)). One loop per offset across the 512 cells, which
    LLVM vectorises (the block forms of reflag and of the coupling's redistribution)."""
    side = HALO1_SIDE
    nq = L.Q
    off = np.array([int(L.C[q, 0]) + side * (int(L.C[q, 1]) + side * int(L.C[q, 2])) for q in range(L.Q)], np.int64)
    int8 = np.int8

    def halo_or(mask, out):
        for c in range(CELLS):
            out[c] = int8(0)
        for q in range(1, nq):
            o = off[q]
            for z in range(8):
                for y in range(8):
                    i0 = 1 + side * ((y + 1) + side * (z + 1)) + o
                    c0 = 8 * (y + 8 * z)
                    for x in range(8):
                        out[c0 + x] |= mask[i0 + x]

    return jit.cpu.device(halo_or)
