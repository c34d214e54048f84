"""One block forest split over MPI ranks (paper section 2.5): a Morton partition, halo blocks and their exchange.

The forest's blocks are in Morton order; :func:`morton_partition` cuts that order into contiguous shares of equal
weight (a block weighs its cells times the sub-steps of its level, 2^level), so each rank owns a compact piece of the
domain. A rank steps a :class:`~iceresist.grid.forest.BlockForest` of its own: its blocks first, then its **halo**,
every block of another rank that one of its blocks pulls from (the 26 neighbours). After each step
:meth:`Decomposition.exchange` sends every owned block a neighbour needs and receives the halo (non-blocking
``Isend``/``Irecv`` of packed rows, one message per neighbouring rank and array; device arrays staged through the
host). A rank updates only its own blocks, so its cells see exactly the values one process would give them: the
fluid is bit-identical to a run on one process.

The rank-local forest takes the global flags for its halo blocks (a halo block's outer side has no neighbours on
this rank, which would mark its cells near a wall).

Collective helpers: :meth:`Decomposition.gather_rows` (owned rows of per-block arrays, in global block order on
rank 0), :meth:`Decomposition.sum` / :meth:`Decomposition.max` (all ranks), :meth:`Decomposition.bcast`.
"""

from __future__ import annotations

import numpy as np

from iceresist.errors import InputError


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


class Decomposition:
    """The share of ``forest`` (the global :class:`BlockForest`) that rank ``comm.rank`` steps (module docstring).

    ``owned``: global ids of the rank's blocks; ``halo``: global ids of its halo blocks; ``global_ids``: both, in
    the local forest's order; ``local``: the rank-local forest; ``nowned``: how many of its blocks the rank updates.
    """

    def __init__(self, forest, comm):
        from iceresist.grid.forest import BlockForest

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
        #: (rank, local rows to send) and (rank, local rows to receive), rows in global-id order on both sides
        self.sends = []
        self.recvs = []
        for r in range(self.size):
            if r == self.rank:
                continue
            out = np.intersect1d(self.owned, halos[r])
            if len(out):
                self.sends.append((r, pos[out]))
            inc = self.halo[self.owner[self.halo] == r]
            if len(inc):
                self.recvs.append((r, pos[inc]))
        self.bytes_last_exchange = 0

    # -- halo exchange ------------------------------------------------------------------------------
    def exchange(self, arr, target=None) -> None:
        """Overwrite the halo rows of ``arr`` (local forest's blocks along axis 0, any trailing shape; a host or a
        device array of ``target``) with their owners' rows."""
        from mpi4py import MPI

        on_device = target is not None and target.is_cuda
        host = target.to_host(arr) if on_device else arr
        bufs_in = []
        reqs = []
        sent = 0
        for r, rows in self.recvs:
            buf = np.empty((len(rows),) + host.shape[1:], dtype=host.dtype)
            bufs_in.append((rows, buf))
            reqs.append(self.comm.Irecv(buf, source=r, tag=7))
        outs = []
        for r, rows in self.sends:
            buf = np.ascontiguousarray(host[rows])
            outs.append(buf)
            sent += buf.nbytes
            reqs.append(self.comm.Isend(buf, dest=r, tag=7))
        MPI.Request.Waitall(reqs)
        for rows, buf in bufs_in:
            host[rows] = buf
        if on_device:
            arr.copy_to_device(host)
        self.bytes_last_exchange = sent

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

    def describe(self) -> dict:
        blocks = np.bincount(self.owner, minlength=self.size)
        return {"ranks": self.size, "blocks_per_rank": [int(b) for b in blocks],
                "halo_blocks": int(len(self.halo)), "partition": "Morton, equal cells x sub-steps"}
