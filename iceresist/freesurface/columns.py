"""The free surface's height over each column of cells, found on the target (a record reads a map, not phi).

For each column (x, y) one item walks down from the tank's top and stops at the top-most crossing of phi = 1/2:
the cell k with phi(k) >= 1/2 > phi(k + 1); the height is ``(k + 1/2) + (phi(k) - 1/2) / (phi(k) - phi(k + 1))``
cells from the bottom (linear interpolation between the cell centres), NaN where the column has none (all water,
all gas, or no block there), as :func:`iceresist.freesurface.fluid.column_crossing` gives on dense arrays.
``covered`` 1: a cell a body covers (flag GHOST) counts as phi = 1, so the surface runs over a floating body.

A record then copies 8 bytes per column off the target instead of phi and the flags of every cell (16 MB on the
quick tier-2 tank), and no NumPy pass over the cells runs on the host.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from iceresist.backends.launch import ItemLauncher
from iceresist.freesurface import kernel_key
from iceresist.grid import flags as FL
from iceresist.grid.forest import BLOCK


@lru_cache(maxsize=None)
def column_launcher(target) -> ItemLauncher:
    """``launch(ncolumns, nx, nby, nbz, block_of, phi, flags, covered, out)``: ``out[x + nx y]`` the surface height
    (cells) of column (x, y); ``block_of[bx + nbx (by + nby bz)]`` the block at block position (bx, by, bz) or -1."""
    ghost = np.uint8(FL.GHOST)
    f64 = np.float64

    def column_top(i, nx, nby, nbz, block_of, phi, flags, covered, out):
        cx = i % nx
        cy = i // nx
        bx = cx // BLOCK
        by = cy // BLOCK
        nbx = nx // BLOCK
        inner = cx % BLOCK + BLOCK * (cy % BLOCK)
        nz = nbz * BLOCK
        above = math.nan
        height = math.nan
        for step in range(nz):
            z = nz - 1 - step
            b = block_of[bx + nbx * (by + nby * (z // BLOCK))]
            p = math.nan
            if b >= 0:
                c = inner + BLOCK * BLOCK * (z % BLOCK)
                p = f64(phi[b, c])
                if covered != 0 and (flags[b, c] & ghost) != 0:
                    p = 1.0
            if p >= 0.5 and above < 0.5:
                height = (z + 0.5) + (p - 0.5) / (p - above)
                break
            above = p
        out[i] = height

    return ItemLauncher(target, target.device(column_top),
                        ("nx", "nby", "nbz", "block_of", "phi", "flags", "covered", "out"), label="surface_columns",
                        cache_key=kernel_key(target, "columns", ("iceresist.freesurface.columns",)))


class SurfaceColumns:
    """The surface height map of one fluid on its forest (one process): ``height(phi, flags, covered)`` -> (nx, ny)
    cells from the bottom, NaN where a column holds no crossing."""

    def __init__(self, forest, target):
        nbx, nby, nbz = forest.shape_blocks
        block_of = np.full(nbx * nby * nbz, -1, dtype=np.int64)
        o = forest.origin
        block_of[o[:, 0] + nbx * (o[:, 1] + nby * o[:, 2])] = np.arange(forest.nblocks)
        self.shape = (nbx * BLOCK, nby * BLOCK)
        self.target = target
        self._args = (np.int64(nbx * BLOCK), np.int64(nby), np.int64(nbz), target.to_device(block_of))
        self._out = target.to_device(np.zeros(self.shape[0] * self.shape[1], dtype=np.float64))
        self._launch = column_launcher(target)

    def height(self, phi, flags, covered: bool) -> np.ndarray:
        n = self.shape[0] * self.shape[1]
        self._launch(n, *self._args, phi, flags, np.int64(bool(covered)), self._out)
        return self.target.to_host(self._out).reshape(self.shape[1], self.shape[0]).T
