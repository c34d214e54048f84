"""The blocks the free surface reaches, reduced on the target (:mod:`iceresist.freesurface.reach`), against NumPy."""

import numpy as np

from iceresist.freesurface.reach import SurfaceReach

BULK = 1.0 - 1e-4


def _fields(seed: int = 3):
    """Six blocks: all bulk; one cell below BULK; below it but covered; below it and a covered one beside; phi
    exactly BULK in float32 (not below); many cells below and some covered."""
    rng = np.random.default_rng(seed)
    phi = np.ones((6, 512), np.float32)
    owner = np.full((6, 512), -1, np.int32)
    phi[1, 100] = 0.3
    phi[2, 7], owner[2, 7] = 0.2, 0
    phi[3, 5], owner[3, 6], phi[3, 6] = 0.9, 1, 0.1
    phi[4, 9] = np.float32(BULK)
    phi[5] = rng.uniform(0.0, 1.0, 512).astype(np.float32)
    owner[5, :256] = 2
    return phi, owner


def test_the_reached_blocks_are_numpys_any_over_their_cells(target):
    """Per block: some cell below the bulk (and, with the owners, not covered): the NumPy reference, with and
    without the owners, over all blocks or the first few (an MPI rank's own). Planted: the owner test dropped
    (block 2 then reached) fails."""
    phi, owner = _fields()
    reach = SurfaceReach(target, 6, np.float32)
    d_phi, d_owner = target.to_device(phi), target.to_device(owner)
    below = phi < np.float32(BULK)
    assert reach.blocks(6, d_phi, BULK).tolist() == below.any(axis=1).tolist() == [False, True, True, True, False,
                                                                                    True]
    assert reach.blocks(6, d_phi, BULK, d_owner).tolist() == (below & (owner < 0)).any(axis=1).tolist() == [
        False, True, False, True, False, True]
    assert reach.blocks(3, d_phi, BULK, d_owner).tolist() == [False, True, False]
