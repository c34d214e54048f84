"""The blocks the free surface reaches, reduced on the target: what a regrid of the levels reads of the surface.

A regrid keeps on the finest level every leaf block that holds a cell less liquid than the bulk (phi below
1 - ``PHI_BULK_TOL``, :mod:`iceresist.freesurface.refined`) outside the bodies (a body's cells keep the phi they had
when it covered them). The test is made per block on the target, so a regrid reads one byte per block, not phi and
the bodies' owners of every cell (on a GPU at the paper's finest level: 1.1 GB a regrid, and the host's pass over
1.4e8 cells).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from iceresist.backends.launch import BlockLauncher
from iceresist.freesurface import kernel_key
from iceresist.grid.forest import CELLS


@lru_cache(maxsize=None)
def reach_launcher(target) -> BlockLauncher:
    """``launch(nblocks, phi, owner, covered, bulk, out)``: ``out[b]`` = 1 where a cell c of block b has
    ``phi[b, c] < bulk`` and, with ``covered`` = 1, no body on it (``owner[b, c] < 0``; with ``covered`` = 0
    ``owner`` is not read), else 0."""
    one, zero = np.int8(1), np.int8(0)

    def reach_block(b, phi, owner, covered, bulk, out):
        b = np.int64(b)
        hit = zero
        for c in range(CELLS):
            if phi[b, c] < bulk:
                if covered == 0 or owner[b, c] < 0:
                    hit = one
                    break
        out[b] = hit

    return BlockLauncher(target, target.device(reach_block), ("phi", "owner", "covered", "bulk", "out"),
                         label="surface_reach", cache_key=kernel_key(target, "surface_reach",
                                                                     ("iceresist.freesurface.reach",)))


class SurfaceReach:
    """:meth:`blocks` of one finest level: its first ``n`` blocks the surface reaches, as a bool array on the host."""

    def __init__(self, target, nblocks: int, precision_type):
        self.target = target
        self.nblocks = int(nblocks)
        self._launch = reach_launcher(target)
        self._out = target.to_device(np.zeros(nblocks, np.int8))
        self._no_owner = target.to_device(np.full((1, CELLS), -1, np.int32))
        self._real = precision_type

    def blocks(self, n: int, phi, bulk: float, owner=None) -> np.ndarray:
        """Whether each of the first ``n`` blocks holds a cell with ``phi`` below ``bulk`` (not covered by a body
        where ``owner``, the coupling's owners, is given)."""
        covered = owner is not None
        self._launch(int(n), phi, owner if covered else self._no_owner, np.int64(covered), self._real(bulk),
                     self._out)
        return np.asarray(self.target.to_host(self._out))[:n] != 0
