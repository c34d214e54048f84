"""One block forest split over MPI ranks (paper section 2.5): a Morton partition, halo blocks and their exchange.

The forest's blocks are in Morton order; :func:`morton_partition` cuts that order into contiguous shares of equal
weight (a block weighs its cells times the sub-steps of its level, 2^level), so each rank owns a compact piece of the
domain. A rank steps a :class:`~iceresist.grid.forest.BlockForest` of its own: its blocks first, then its **halo**,
every block of another rank that one of its blocks pulls from (the 26 neighbours). After each step
:meth:`Decomposition.exchange` sends the populations of its blocks that a neighbouring rank's blocks pull (of the one
layer of cells facing them, 64 of a block's 512 across a face, the populations streaming towards them, 9 of 27
across a face) and receives its own halo's (non-blocking ``Isend``/``Irecv``, one message per neighbouring rank and
array; device arrays packed on the device, :mod:`iceresist.parallel.staging`). A rank updates only its own blocks,
so its cells see exactly the values one process would give them: the fluid is bit-identical to a run on one
process.

The rank-local forest takes the global flags for its halo blocks (a halo block's outer side has no neighbours on
this rank, which would mark its cells near a wall).

Collective helpers: :meth:`Decomposition.gather_rows` (owned rows of per-block arrays, in global block order on
rank 0), :meth:`Decomposition.sum` / :meth:`Decomposition.max` (all ranks), :meth:`Decomposition.bcast`.
"""

from __future__ import annotations

import time

import numpy as np

from iceresist.errors import InputError
from iceresist.grid.forest import BlockForest, LX, LY, LZ
from iceresist.lattice import C
from iceresist.parallel.messages import Exchanges, Pending, swap_start
from iceresist.parallel.staging import DevicePlan


def morton_partition(weights: np.ndarray, nranks: int) -> np.ndarray:
    """The owner rank of each block (blocks in Morton order, ``weights`` per block): contiguous shares whose
    weight is as close to equal as the blocks allow (each share ends where the running weight passes k/n of the
    total). Every rank gets at least one block; more ranks than blocks is an error naming the cause."""
    w = np.asarray(weights, dtype=np.float64)
    n = len(w)
    if nranks > n:
        raise InputError(f"mpirun -n {nranks}: the scene has {n} blocks of 8x8x8 cells, fewer than the ranks; run "
                         f"with at most {n} ranks (or a finer domain)")
    cum = np.cumsum(w) - 0.5 * w                          # the weight up to each block's middle
    owner = np.minimum((cum / w.sum() * nranks).astype(np.int64), nranks - 1)
    if len(np.unique(owner)) < nranks:                    # a share came out empty: equal block counts instead
        owner = (np.arange(n) * nranks) // n
    return owner.astype(np.int64)


def block_weights(forest) -> np.ndarray:
    """Cells times sub-steps (2^level) per block: the work of one step of the coarsest level."""
    return forest.fluid.sum(axis=1).astype(np.float64) * 2.0 ** forest.levels


def pulled_populations(forest, owner, sender: int, receiver: int):
    """(global blocks, populations, cells) of ``sender``'s blocks of ``forest`` (``owner``: the rank of each block)
    that ``receiver``'s blocks pull: for a block h next to a receiving block o, the cells of h on its side facing o
    (one layer; an edge or a corner for diagonal neighbours) and of them the populations that stream from h into o
    (9 across a face, 3 across an edge, 1 across a corner), sorted by block, population, cell."""
    nbr = forest.nbr
    local = (LX, LY, LZ)
    mine = np.flatnonzero(owner == receiver)
    mask: dict[int, np.ndarray] = {}
    for q in range(1, C.shape[0]):
        h = nbr[mine, q]
        h = np.unique(h[(h >= 0) & (owner[np.maximum(h, 0)] == sender)])
        if not len(h):
            continue
        m = np.ones(512, dtype=bool)
        for a in range(3):            # h lies at +C[q] from o: o is at -C[q] from h
            if C[q, a] == 1:
                m &= local[a] == 0
            elif C[q, a] == -1:
                m &= local[a] == 7
        axes = C[q] != 0              # a cell x of o pulls f_p from x - c_p: in h where c_p = -C[q] on these axes
        pops = np.flatnonzero((C[:, axes] == -C[q, axes]).all(axis=1))
        for b in h.tolist():
            if b not in mask:
                mask[b] = np.zeros((C.shape[0], 512), dtype=bool)
            mask[b][pops] |= m
    if not mask:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = sorted(mask)
    pairs = [np.nonzero(mask[b]) for b in order]
    blocks = np.concatenate([np.full(len(p), b, np.int64) for b, (p, _) in zip(order, pairs)])
    comps = np.concatenate([p for p, _ in pairs]).astype(np.int64)
    cells = np.concatenate([c for _, c in pairs]).astype(np.int64)
    return blocks, comps, cells


class SolverHalo:
    """What :meth:`~iceresist.lbm.solver.LBMSolver.step` asks of a rank's halo exchange so that it can update its
    interior while the messages travel: ``sent`` (a flag per local block on the target: the own blocks whose cells
    another rank pulls, updated first), ``inner`` (the rest of the own blocks, updated while the messages travel),
    ``start(arr)`` (the exchange of the updated ``arr`` posted, a :class:`Pending` back) and ``finish(pending)``.
    ``overlap = False`` updates every own block and then exchanges, as before the split (for benchmarks)."""

    def __init__(self, target, nblocks: int, nowned: int, sent_rows, start, finish):
        sent = np.zeros(nblocks, dtype=np.uint8)
        sent[np.asarray(sent_rows, dtype=np.int64)] = 1
        inner = np.zeros(nblocks, dtype=np.uint8)
        inner[:nowned] = 1 - sent[:nowned]
        self.nsent, self.ninner = int(sent.sum()), int(inner.sum())
        self.sent = sent if target is None else target.to_device(sent)
        self.inner = inner if target is None else target.to_device(inner)
        self.start, self.finish = start, finish
        self.overlap = True


class Collectives:
    """Reductions over the ranks of ``self.comm``, every rank getting the result."""

    def sum(self, value: float) -> float:
        from mpi4py import MPI

        return float(self.comm.allreduce(float(value), op=MPI.SUM))

    def max(self, value: float) -> float:
        from mpi4py import MPI

        return float(self.comm.allreduce(float(value), op=MPI.MAX))

    def all(self, flag: bool) -> bool:
        from mpi4py import MPI

        return bool(self.comm.allreduce(bool(flag), op=MPI.LAND))

    def bcast(self, value):
        return self.comm.bcast(value, root=0)


class Decomposition(Collectives, Exchanges):
    """The share of ``forest`` (the global :class:`BlockForest`) that rank ``comm.rank`` steps (module docstring).

    ``owned``: global ids of the rank's blocks; ``halo``: global ids of its halo blocks; ``global_ids``: both, in
    the local forest's order; ``local``: the rank-local forest; ``nowned``: how many of its blocks the rank updates.
    """

    def __init__(self, forest, comm):
        self.comm = comm
        self.rank, self.size = int(comm.rank), int(comm.size)
        self.forest = forest
        self.owner = morton_partition(block_weights(forest), self.size)
        nbr = forest.nbr
        halos = []
        for r in range(self.size):
            mine = np.flatnonzero(self.owner == r)
            near = np.unique(nbr[mine].ravel())
            near = near[near >= 0]
            halos.append(near[self.owner[near] != r])
        self.owned = np.flatnonzero(self.owner == self.rank)
        self.halo = halos[self.rank]
        self.nowned = len(self.owned)
        self.global_ids = np.concatenate([self.owned, self.halo])
        ids = self.global_ids
        self.local = BlockForest(forest.shape_cells, forest.faces, forest.levels[ids], forest.origin[ids],
                                 forest.fluid[ids])
        self.local.flags[self.nowned:] = forest.flags[self.halo]
        pos = np.full(forest.nblocks, -1, dtype=np.int64)
        pos[ids] = np.arange(len(ids))
        #: (rank, local rows, populations, cells) to send and to receive: the populations of the cells of each halo
        #: block that the receiving rank's blocks pull (the layer facing them, the populations crossing towards
        #: them), in (global block, population, cell) order on both sides
        self.sends = []
        self.recvs = []
        #: (rank, local rows) of whole blocks to send and to receive (:meth:`exchange` with ``full``)
        self.sends_full = []
        self.recvs_full = []
        for r in range(self.size):
            if r == self.rank:
                continue
            blocks, comps, cells = pulled_populations(forest, self.owner, sender=self.rank, receiver=r)
            if len(blocks):
                self.sends.append((r, pos[blocks], comps, cells))
                self.sends_full.append((r, pos[np.intersect1d(self.owned, halos[r])]))
            blocks, comps, cells = pulled_populations(forest, self.owner, sender=r, receiver=self.rank)
            if len(blocks):
                self.recvs.append((r, pos[blocks], comps, cells))
                self.recvs_full.append((r, pos[self.halo[self.owner[self.halo] == r]]))
        #: Totals since construction: halo exchanges, bytes this rank sent, wall seconds inside them.
        self.exchanges, self.bytes_sent, self.exchange_s = 0, 0, 0.0
        #: Device exchanges by (full, shape, dtype) (:class:`~iceresist.parallel.staging.DevicePlan`)
        self._plans = {}

    # -- halo exchange ------------------------------------------------------------------------------
    def exchange(self, arr, target=None, full: bool = False) -> None:
        """Overwrite the halo populations this rank's blocks pull in ``arr`` (``[block, q, cell]`` over the local
        forest's blocks, a host or a device array of ``target``) with their owners' values; ``full``: every value of
        the halo blocks, of any trailing shape (a
        step of several passes that each reach one cell further into the halo stays exact next to this rank's
        blocks for up to 7 of them: the free surface)."""
        self.finish_exchange(self.start_exchange(arr, target, full))

    def start_exchange(self, arr, target=None, full: bool = False) -> Pending:
        """Post :meth:`exchange`'s messages (this rank's values copied out now) and return without waiting; a device
        array's messages are packed on the device (:mod:`iceresist.parallel.staging`)."""
        t0 = time.perf_counter()
        if full:
            recvs = [(r, rows, None, None) for r, rows in self.recvs_full]
            sends = [(r, rows, None, None) for r, rows in self.sends_full]
        else:
            recvs, sends = self.recvs, self.sends
        if target is not None and target.is_cuda:
            key = (bool(full), tuple(arr.shape), str(arr.dtype))
            if key not in self._plans:
                self._plans[key] = DevicePlan(target, arr.shape, arr.dtype, recvs, sends)
            pending = self._plans[key].start(self.comm, arr, tag=7)
        else:
            pending = swap_start(self.comm, arr, recvs, sends)
        return self._posted(pending, t0)

    def solver_halo(self, target=None) -> SolverHalo:
        """The exchange after each step of an :class:`~iceresist.lbm.solver.LBMSolver` on the local forest, split so
        that the blocks no other rank pulls from are updated while the messages travel."""
        sent = np.unique(np.concatenate([rows for _, rows, _, _ in self.sends])) if self.sends else []
        return SolverHalo(target, self.local.nblocks, self.nowned, sent,
                          lambda arr: self.start_exchange(arr, target), self.finish_exchange)

    # -- collectives -------------------------------------------------------------------------------------
    def gather_rows(self, local: np.ndarray, axis: int = 0):
        """The owned rows of a per-block array (local forest order along ``axis``) of every rank, as one array in
        global block order along that axis on rank 0; None on the other ranks."""
        mine = np.take(np.asarray(local), np.arange(self.nowned), axis=axis)
        parts = self.comm.gather(mine, root=0)
        if self.rank != 0:
            return None
        shape = list(mine.shape)
        shape[axis] = self.forest.nblocks
        out = np.empty(shape, dtype=mine.dtype)
        for r, part in enumerate(parts):
            idx = [slice(None)] * out.ndim
            idx[axis] = np.flatnonzero(self.owner == r)
            out[tuple(idx)] = part
        return out

    def local_rows(self, global_array: np.ndarray, axis: int = 0) -> np.ndarray:
        """This rank's rows (owned, then halo) of a per-block array in global order."""
        return np.take(np.asarray(global_array), self.global_ids, axis=axis)

    def describe(self) -> dict:
        blocks = np.bincount(self.owner, minlength=self.size)
        return {"ranks": self.size, "blocks_per_rank": [int(b) for b in blocks],
                "halo_blocks": int(len(self.halo)), "partition": "Morton, equal cells x sub-steps"}
