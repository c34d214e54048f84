"""The levels of a block octree split over MPI ranks (paper section 2.5): whole level-0 trees per rank, one layer of
blocks of every level around them as halo, every level's halo leaves exchanged after each of its steps.

**Partition.** The octree's leaves lie along the Morton curve at the finest level, so the leaves under one level-0
block (a *tree*) are contiguous on it. :func:`tree_partition` cuts that curve at tree boundaries into shares of equal
weight, a tree weighing the cells times sub-steps of its leaves (512 x 2^level each): the Morton partition of the
blocks of every level (:func:`~iceresist.parallel.decomposition.morton_partition`), with a cut never inside a tree,
so a level interface inside a tree never crosses ranks.

**Region.** On every level a rank holds the blocks of its own trees and the blocks of that level next to them (26
neighbours, wrapped on periodic axes; 8 cells of the level thick): its own leaves first, then the halo's, then the
ghost blocks (:mod:`iceresist.grid.levels`). Beyond that layer nothing is allocated (a missing neighbour block reads
as a resting wall, and the level transfers leave out what they cannot reach there).

**Why this is exact.** A rank steps its own leaves. Every value a step of level l, or a level transfer feeding it,
reads next to an own leaf lies within 2 cells of level l of the rank's trees, or 2 cells of level l - 1 or l + 1
(the transfers reach one coarse cell and its neighbours): inside the layer of 8 cells that level holds. After each
step of level l the halo leaves of level l take their owners' values (whole blocks), so at every step of every level
the leaves a rank reads hold exactly what one process would have: the populations are bit-identical to one
process's.

Ghost blocks and all other blocks of a level belong to the rank that owns their tree; :meth:`gather` and
:meth:`scatter` move whole levels between ranks and rank 0 in the global order of
:func:`~iceresist.grid.levels.level_views`, so checkpoints, fields and regrids see the one-process layout.
"""

from __future__ import annotations

import time

import numpy as np

from iceresist.errors import InputError
from iceresist.grid.forest import BlockForest, morton_key
from iceresist.grid.levels import LevelView
from iceresist.parallel.decomposition import Collectives, SolverHalo, morton_partition, pulled_populations
from iceresist.parallel.messages import Exchanges, Pending, swap_start
from iceresist.parallel.staging import DevicePlan


def tree_of(view: LevelView) -> np.ndarray:
    """The level-0 block (x, y, z) each block of ``view``'s forest lies in."""
    return view.forest.origin >> view.level


def tree_weights(octree) -> np.ndarray:
    """Cells times sub-steps of each level-0 tree's leaves, trees in the order of ``_tree_ids`` (x fastest)."""
    root = octree.root
    tree = octree.coord >> octree.level[:, None]
    ids = tree[:, 0] + root[0] * (tree[:, 1] + root[1] * tree[:, 2])
    return np.bincount(ids, weights=512.0 * 2.0 ** octree.level, minlength=int(np.prod(root)))


def tree_partition(octree, nranks: int) -> np.ndarray:
    """The owner rank of every level-0 tree (ids x + nx (y + ny z)): contiguous shares of the trees in Morton order,
    equal in cells x sub-steps. More ranks than trees is an error naming the cause."""
    root = octree.root
    ntrees = int(np.prod(root))
    if nranks > ntrees and octree.max_level > 0:     # one level: morton_partition names the blocks
        raise InputError(f"mpirun -n {nranks}: the refined scene has {ntrees} level-0 blocks of 8x8x8 cells, fewer "
                         f"than the ranks; run with at most {ntrees} ranks (or a finer level 0)")
    x, y, z = np.unravel_index(np.arange(ntrees), tuple(root), order="F")
    order = np.argsort(morton_key(x, y, z), kind="stable")
    owner = np.empty(ntrees, dtype=np.int64)
    owner[order] = morton_partition(tree_weights(octree)[order], nranks)
    return owner


def near_owners(view: LevelView, tree_owner: np.ndarray, root, periodic) -> np.ndarray:
    """(nblocks, 27): the rank owning the tree of each block of ``view``'s level next to each of its blocks (the
    block itself included; wrapped on periodic axes, -1 beyond a closed face)."""
    root = np.asarray(root, dtype=np.int64)
    n = root << view.level
    c = view.forest.origin
    out = np.full((len(c), 27), -1, dtype=np.int64)
    k = 0
    for ox in (-1, 0, 1):
        for oy in (-1, 0, 1):
            for oz in (-1, 0, 1):
                b = c + np.array([ox, oy, oz])
                ok = np.ones(len(c), dtype=bool)
                for a in range(3):
                    if periodic[a]:
                        b[:, a] %= n[a]
                    else:
                        ok &= (b[:, a] >= 0) & (b[:, a] < n[a])
                t = np.clip(b, 0, n - 1) >> view.level
                out[:, k] = np.where(ok, tree_owner[t[:, 0] + root[0] * (t[:, 1] + root[1] * t[:, 2])], -1)
                k += 1
    return out


class LevelDecomposition(Collectives, Exchanges):
    """The share of every level of ``views`` (the global :func:`~iceresist.grid.levels.level_views` of ``octree``)
    that rank ``comm.rank`` steps (module docstring).

    ``views``: this rank's :class:`LevelView` per level (None where the level has no leaves); ``global_ids[lv]``: the
    global block of each of its blocks; ``nown[lv]``: its own leaves (the first blocks), the ones it steps;
    ``owned_rows[lv]``: the local rows of every block of its trees, leaves and ghosts (what :meth:`gather` takes).
    """

    def __init__(self, octree, views: list, comm):
        self.comm = comm
        self.rank, self.size = int(comm.rank), int(comm.size)
        self.octree = octree
        self.global_views = views
        self.tree_owner = tree_partition(octree, self.size)
        root = octree.root
        periodic = tuple(bool(p) for p in octree.periodic)
        self.views: list[LevelView | None] = []
        self.global_ids, self.nown, self.owned_rows = {}, {}, {}
        self._sends, self._recvs = {}, {}
        owners = {}             # the rank owning each block of a level (global order)
        for v in views:
            if v is None:
                self.views.append(None)
                continue
            lv = v.level
            t = tree_of(v)
            tid = t[:, 0] + root[0] * (t[:, 1] + root[1] * t[:, 2])
            owner = owners[lv] = self.tree_owner[tid]
            near = near_owners(v, self.tree_owner, root, periodic)
            inside = (near == self.rank).any(axis=1)
            is_leaf = np.arange(v.forest.nblocks) < v.nleaves
            own_leaves = np.flatnonzero(is_leaf & (owner == self.rank))
            halo_leaves = np.flatnonzero(is_leaf & inside & (owner != self.rank))
            ghosts = np.flatnonzero(~is_leaf & inside)
            ids = np.concatenate([own_leaves, halo_leaves, ghosts])
            f = v.forest
            forest = BlockForest(f.shape_cells, f.faces, f.levels[ids], f.origin[ids], f.fluid[ids])
            nleaves = len(own_leaves) + len(halo_leaves)
            self.views.append(LevelView(lv, forest, nleaves, v.leaf_index[ids[:nleaves]],
                                        v.ghost_source[ids[nleaves:] - v.nleaves]))
            self.global_ids[lv] = ids
            self.nown[lv] = len(own_leaves)
            self.owned_rows[lv] = np.flatnonzero(owner[ids] == self.rank)
            pos = np.full(f.nblocks, -1, dtype=np.int64)
            pos[ids] = np.arange(len(ids))
            # whole leaf blocks: this rank's leaves in another rank's halo go there, its halo leaves come
            # from their owners, both sides in global order
            self._sends[lv] = [(r, pos[own_leaves[(near[own_leaves] == r).any(axis=1)]])
                               for r in range(self.size) if r != self.rank]
            self._recvs[lv] = [(r, pos[halo_leaves[owner[halo_leaves] == r]])
                               for r in range(self.size) if r != self.rank]
            self._sends[lv] = [(r, rows) for r, rows in self._sends[lv] if len(rows)]
            self._recvs[lv] = [(r, rows) for r, rows in self._recvs[lv] if len(rows)]
        #: On a grid of one level (no level transfers read the halo), the LBM step's swap sends only what the
        #: neighbours' cells pull (:func:`pulled_populations`, as on a uniform forest): (rank, rows, populations,
        #: cells) to send and to receive, in the level's global (block, population, cell) order on both sides
        self._pulled = None
        if sum(v is not None for v in views) == 1:
            lv = next(v.level for v in views if v is not None)
            f = views[lv].forest
            pos = np.full(f.nblocks, -1, dtype=np.int64)
            pos[self.global_ids[lv]] = np.arange(len(self.global_ids[lv]))
            sends, recvs = [], []
            for r in range(self.size):
                if r == self.rank:
                    continue
                for msgs, sender, receiver in ((sends, self.rank, r), (recvs, r, self.rank)):
                    blocks, comps, cells = pulled_populations(f, owners[lv], sender, receiver)
                    if len(blocks):
                        msgs.append((r, pos[blocks], comps, cells))
            self._pulled = (lv, recvs, sends)
        #: Leaf blocks (all levels) each rank steps.
        t = octree.coord >> octree.level[:, None]
        leaf_owner = self.tree_owner[t[:, 0] + root[0] * (t[:, 1] + root[1] * t[:, 2])]
        self.leaves_per_rank = [int(n) for n in np.bincount(leaf_owner, minlength=self.size)]
        #: Totals since construction: halo exchanges, bytes this rank sent, wall seconds inside them.
        self.exchanges, self.bytes_sent, self.exchange_s = 0, 0, 0.0
        #: Device exchanges by (level, shape, dtype) (:class:`~iceresist.parallel.staging.DevicePlan`)
        self._plans = {}

    # -- halo exchange ------------------------------------------------------------------------------
    def exchange(self, lv: int, arr, target=None) -> None:
        """Overwrite the halo leaves of level ``lv`` in ``arr`` (``[block, q, cell]`` over this rank's blocks of the
        level, a host or a device array of ``target``) with their owners' values."""
        self.finish_exchange(self.start_exchange(lv, arr, target))

    def start_exchange(self, lv: int, arr, target=None, pulled: bool = False) -> Pending:
        """Post :meth:`exchange`'s messages (this rank's leaves copied out now, on a device packed there:
        :mod:`iceresist.parallel.staging`) and return without waiting; ``pulled``: on a grid of one level, only the
        populations the neighbours' cells pull (the LBM step's swap)."""
        t0 = time.perf_counter()
        pulled = pulled and self._pulled is not None and self._pulled[0] == lv
        if pulled:
            recvs, sends = self._pulled[1:]
        else:
            recvs = [(r, rows, None, None) for r, rows in self._recvs[lv]]
            sends = [(r, rows, None, None) for r, rows in self._sends[lv]]
        if target is not None and target.is_cuda:
            key = (lv, pulled, tuple(arr.shape), str(arr.dtype))
            if key not in self._plans:
                self._plans[key] = DevicePlan(target, arr.shape, arr.dtype, recvs, sends)
            pending = self._plans[key].start(self.comm, arr, tag=100 + lv)
        else:
            pending = swap_start(self.comm, arr, recvs, sends, tag=100 + lv)
        return self._posted(pending, t0)

    def step_own(self, lv: int, solver, target=None) -> None:
        """Make ``solver`` (an :class:`~iceresist.lbm.solver.LBMSolver` of level ``lv`` on this rank's blocks) step
        this rank's own leaves and swap the level's halo leaves after each step, the leaves no other rank holds
        updated while the messages travel."""
        solver.active_blocks = self.nown[lv]
        sends = self._sends[lv]
        sent = np.unique(np.concatenate([rows for _, rows in sends])) if sends else []
        solver.halo = SolverHalo(target, self.views[lv].forest.nblocks, self.nown[lv], sent,
                                 lambda arr: self.start_exchange(lv, arr, target, pulled=True), self.finish_exchange)

    # -- whole levels on rank 0 ------------------------------------------------------------------------
    def gather(self, lv: int, local: np.ndarray):
        """Level ``lv``'s per-block array (this rank's blocks along axis 0) as the whole level's in global block
        order on rank 0, every block from the rank of its tree; None on the other ranks."""
        rows = self.owned_rows[lv]
        parts = self.comm.gather((self.global_ids[lv][rows], np.asarray(local)[rows]), root=0)
        if self.rank != 0:
            return None
        nblocks = self.global_views[lv].forest.nblocks
        out = np.empty((nblocks,) + parts[0][1].shape[1:], dtype=parts[0][1].dtype)
        for ids, values in parts:
            out[ids] = values
        return out

    def gather_leaves(self, lv: int, own: np.ndarray, axis: int = 0):
        """Per-leaf values of this rank's own leaves of level ``lv`` (along ``axis``) as every leaf's of the level, in
        the global order, on rank 0; None on the other ranks."""
        parts = self.comm.gather((self.global_ids[lv][:self.nown[lv]], np.moveaxis(np.asarray(own), axis, 0)),
                                 root=0)
        if self.rank != 0:
            return None
        nleaves = self.global_views[lv].nleaves
        out = np.empty((nleaves,) + parts[0][1].shape[1:], dtype=parts[0][1].dtype)
        for ids, values in parts:
            out[ids] = values
        return np.moveaxis(out, 0, axis)

    def scatter(self, lv: int, whole) -> np.ndarray:
        """This rank's blocks of level ``lv`` from ``whole`` (the whole level in global order, given on rank 0;
        ignored elsewhere)."""
        ids = self.comm.gather(self.global_ids[lv], root=0)
        parts = None if self.rank != 0 else [whole[i] for i in ids]
        return self.comm.scatter(parts, root=0)

    def describe(self) -> dict:
        trees = np.bincount(self.tree_owner, minlength=self.size)
        w = np.bincount(self.tree_owner, weights=tree_weights(self.octree), minlength=self.size)
        return {"ranks": self.size, "trees_per_rank": [int(n) for n in trees],
                "blocks_per_rank": self.leaves_per_rank,
                "weight_share": [round(float(x / w.sum()), 4) for x in w],
                "partition": "Morton, whole level-0 trees, equal cells x sub-steps"}


class LevelShare(Collectives):
    """One level of a :class:`LevelDecomposition` seen as a :class:`~iceresist.parallel.decomposition.Decomposition`
    of that level's forest (leaves and ghosts): what a
    :class:`~iceresist.freesurface.fluid.FreeSurfaceFluid` on the finest level asks of its ``decomp`` (gathering
    per-block rows on rank 0 in the level's global order, this rank's rows of a whole level, the swap of the halo's
    whole blocks)."""

    def __init__(self, decomp: LevelDecomposition, level: int):
        self.decomp, self.level = decomp, int(level)
        self.comm, self.rank, self.size = decomp.comm, decomp.rank, decomp.size
        #: The level's whole view and forest (leaves and ghosts of every rank), as one process holds them.
        self.view = decomp.global_views[self.level]
        self.forest = self.view.forest
        self.global_ids = decomp.global_ids[self.level]
        self.nowned = decomp.nown[self.level]

    def gather_rows(self, local: np.ndarray, axis: int = 0):
        """The level's per-block array (blocks along ``axis``) in global order on rank 0, each block from the rank
        of its tree; None on the other ranks."""
        whole = self.decomp.gather(self.level, np.moveaxis(np.asarray(local), axis, 0))
        return None if whole is None else np.moveaxis(whole, 0, axis)

    def local_rows(self, whole: np.ndarray, axis: int = 0) -> np.ndarray:
        """This rank's blocks of a per-block array of the whole level."""
        return np.take(np.asarray(whole), self.global_ids, axis=axis)

    def exchange(self, arr, target=None, full: bool = True) -> None:
        """The halo leaves of the level take their owners' values: whole blocks (``full`` is the only way)."""
        self.decomp.exchange(self.level, arr, target)
