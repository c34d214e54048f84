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
leaves). Back to this rank: :meth:`Grid.level_rows`. Whole levels on the level-0 cells: :meth:`Grid.level0_means`.
To another grid (a regrid): :meth:`Grid.carry_to`; from a checkpoint's leaves: :meth:`Grid.octree_of_leaves`.
"""

from __future__ import annotations

import numpy as np

from iceresist.grid.forest import CELLS
from iceresist.grid.levels import level_views
from iceresist.grid.octree import BlockOctree
from iceresist.grid.regrid import carry_over
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

    def own(self, lv: int, *values):
        """Per-leaf arrays of level ``lv`` (leaves along the last-but-one axis of each, e.g. rho (nleaves, 512),
        u (3, nleaves, 512)) cut to this rank's own leaves; None stays None."""
        if self.decomp is None:
            return values
        n = self.own_leaves(lv)
        return tuple(None if v is None else v[..., :n, :] for v in values)

    def level0_means(self, leaves, shape, everywhere: bool = True):
        """Per-leaf values of every level averaged on the level-0 cells (``shape``): ``leaves`` maps each level to
        (values, (x, y, z)), values a list of (nleaves, 512) arrays of this rank's own leaves and x, y, z their cell
        indices on that level; each level-0 cell the mean of the leaf cells inside it by volume, NaN where none.
        Returns (k, *shape) on every rank, or on rank 0 alone (None on the others) unless ``everywhere``. On one
        level the leaves are the level-0 cells: gathered and laid out, nothing averaged."""
        if len(self.global_views) == 1:
            values = [self.gather_leaves(0, np.asarray(v)) for v in leaves[0][0]]
            dense = None if values[0] is None else self.global_views[0].forest.to_dense(np.stack(values))
            return self.bcast(dense) if everywhere else dense
        acc, weight = None, np.zeros(shape)
        for lv, (values, (x, y, z)) in leaves.items():
            if acc is None:
                acc = np.zeros((len(values), *shape))
            idx = (x.ravel() >> lv, y.ravel() >> lv, z.ravel() >> lv)
            w = 1.0 / 8 ** lv
            np.add.at(weight, idx, w)
            for k, v in enumerate(values):
                np.add.at(acc[k], idx, w * np.asarray(v).ravel())
        self.reduce_arrays(acc, weight)      # every level-0 cell lies in one rank's trees: the others add zeros
        if not (everywhere or self.root):
            return None
        return acc / np.where(weight > 0, weight, np.nan)

    def carry_to(self, new: Grid, old: dict, nq: int):
        """Every level's per-cell values ``old`` ({level: (this rank's blocks, nq, 512)}) carried onto the blocks of
        ``new`` (:func:`~iceresist.grid.regrid.carry_over`, in the precision of ``old``). Returns ({level: the new
        grid's blocks of this rank}, the whole carried levels on rank 0 of several ranks, else None). On several ranks
        the old levels are gathered on rank 0, carried over there and dealt out to the ranks of ``new``."""
        levels = [v.level for v in new.global_views if v is not None]
        dtype = next(iter(old.values())).dtype         # a level may be new: the precision of the old ones
        if self.decomp is None:
            out = {lv: np.zeros((new.views[lv].forest.nblocks, nq, CELLS), dtype) for lv in levels}
            carry_over(self.views, old, new.views, out)
            return out, None
        old = {lv: self.gather(lv, f) for lv, f in old.items()}
        whole = None
        if self.root:
            whole = {lv: np.zeros((new.global_views[lv].forest.nblocks, nq, CELLS), dtype) for lv in levels}
            carry_over(self.global_views, old, new.global_views, whole)
        return {lv: new.decomp.scatter(lv, None if whole is None else whole[lv]) for lv in levels}, whole

    def octree_of_leaves(self, level, coord) -> BlockOctree | None:
        """The octree of the leaves (``level``, ``coord``; a checkpoint's) on this grid's root blocks, periodicity and
        deepest level; None where they do not tile its domain."""
        lev = np.asarray(level, dtype=np.int64)
        coord = np.asarray(coord, dtype=np.int64)
        t = self.octree
        if lev.ndim != 1 or coord.shape != (len(lev), 3) or len(lev) == 0 or lev.max() > t.max_level:
            return None
        volume = (8.0 ** -lev.astype(float)).sum()
        if abs(volume - float(np.prod(t.root))) > 1e-9 or (coord >= (t.root[None, :] << lev[:, None])).any():
            return None
        return BlockOctree.from_leaves(t.root, t.max_level, t.periodic, lev, coord)
