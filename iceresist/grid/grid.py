"""The cells a model steps, on one process or split over MPI ranks (docs/ARCHITECTURE.md, "The grid").

A :class:`Grid` is the levels of a block octree (:meth:`Grid.levels`, paper section 2.5; a grid without
``[refinement]`` is the octree of one level) with its split over the ranks behind it: a
:class:`~iceresist.parallel.levels.LevelDecomposition` of whole level-0 trees; on one process there is none and every
operation below is the value itself. So a model asks the grid for a sum over the ranks, a whole-domain gather on
rank 0 or a halo exchange and never branches on how many ranks it runs on (after Oceananigans, where the
architecture is a property of the grid, and waLBerla, whose block forest owns the split and its communication).

Over the ranks, every rank gets the result: :meth:`Grid.sum`, :meth:`Grid.max`, :meth:`Grid.all`,
:meth:`Grid.bcast` (rank 0's value), :meth:`Grid.reduce_arrays` (element-wise sum or maximum, in place). Whole
domain on rank 0 (None on the others): :meth:`Grid.gather` and :meth:`Grid.gather_leaves` (a level's blocks or own
leaves). Back to this rank: :meth:`Grid.level_rows`.
"""

from __future__ import annotations

import numpy as np

from iceresist.grid.levels import level_views
from iceresist.parallel.levels import LevelDecomposition


def several(comm):
    """``comm`` if it spans several ranks, else None (one process)."""
    return comm if comm is not None and comm.size > 1 else None


class Grid:
    """The blocks a model steps and their split over the ranks (module docstring).

    ``comm``: the MPI communicator of a split over several ranks, None on one process. ``decomp``: the split (None
    on one process). ``octree``, ``views`` (this rank's view of each level, None for a level without leaves) and
    ``global_views`` (every rank's)."""

    def __init__(self, comm=None, decomp=None, *, octree=None, global_views=None, views=None):
        self.comm = several(comm)
        self.decomp = decomp
        self.octree, self.global_views, self.views = octree, global_views, views

    # -- construction -----------------------------------------------------------------------------------
    @classmethod
    def levels(cls, octree, faces: dict, comm=None, solid=None) -> Grid:
        """The levels of ``octree`` (:func:`~iceresist.grid.levels.level_views` with ``faces`` and ``solid``), split
        into whole level-0 trees where ``comm`` spans several ranks. A uniform grid is the octree of one level."""
        comm = several(comm)
        views = level_views(octree, faces, solid)
        decomp = None if comm is None else LevelDecomposition(octree, views, comm)
        return cls(comm, decomp, octree=octree, global_views=views, views=views if decomp is None else decomp.views)

    # -- identity ---------------------------------------------------------------------------------------
    @property
    def root(self) -> bool:
        """Whether this process writes the results: rank 0, or the one process."""
        return self.comm is None or self.comm.rank == 0

    def describe(self) -> dict:
        """``{"mpi": ...}`` (the split's description) on several ranks, ``{}`` on one process."""
        return {} if self.decomp is None else {"mpi": self.decomp.describe()}

    # -- over the ranks ---------------------------------------------------------------------------------
    def sum(self, value: float) -> float:
        """The sum of ``value`` over the ranks."""
        return float(value) if self.decomp is None else self.decomp.sum(value)

    def max(self, value: float) -> float:
        """The largest ``value`` of the ranks."""
        return float(value) if self.decomp is None else self.decomp.max(value)

    def all(self, flag: bool) -> bool:
        """Whether ``flag`` holds on every rank."""
        return bool(flag) if self.decomp is None else self.decomp.all(flag)

    def bcast(self, value):
        """Rank 0's ``value`` on every rank."""
        return value if self.decomp is None else self.decomp.bcast(value)

    def first_given(self, value):
        """The value of the lowest rank whose ``value`` is not None (None if no rank has one), on every rank."""
        if self.comm is None:
            return value
        return next((v for v in self.comm.allgather(value) if v is not None), None)

    def reduce_arrays(self, *arrays, op: str = "sum") -> None:
        """Each host array summed (``op="max"``: the largest) element-wise over the ranks, in place."""
        if self.comm is None:
            return
        from mpi4py import MPI  # deferred: mpi4py, the optional [mpi] dependency, only on several ranks

        for a in arrays:
            self.comm.Allreduce(MPI.IN_PLACE, a, op=MPI.MAX if op == "max" else MPI.SUM)

    # -- levels -----------------------------------------------------------------------------------------
    def own_leaves(self, lv: int) -> int:
        """How many leaves of level ``lv`` this rank steps: its first blocks of the level."""
        return self.views[lv].nleaves if self.decomp is None else self.decomp.nown[lv]

    def gather(self, lv: int, values):
        """Level ``lv``'s per-block array (this rank's blocks along axis 0) as the whole level's, in global order, on
        rank 0 (None on the others)."""
        return values if self.decomp is None else self.decomp.gather(lv, values)

    def gather_leaves(self, lv: int, values, axis: int = 0):
        """Per-leaf values of this rank's own leaves of level ``lv`` as every leaf's of the level on rank 0."""
        return values if self.decomp is None else self.decomp.gather_leaves(lv, values, axis=axis)

    def level_rows(self, lv: int, whole):
        """This rank's blocks of level ``lv`` from the whole level's per-block array (given on every rank)."""
        return whole if self.decomp is None else np.asarray(whole)[self.decomp.global_ids[lv]]
