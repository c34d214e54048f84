"""Halo messages packed and unpacked on the device (CUDA ranks; paper section 2.5: device buffers staged through the
host).

A CUDA rank's halo exchange gathers the values it sends into one contiguous device buffer per neighbouring rank with
a kernel (``halo_pack``) and scatters what arrives with another (``halo_unpack``), so only the messages cross the
PCIe bus, never the whole array (a step of the paper's case holds about 20 MB of halo per rank against 0.5 GB of
populations). The buffers go through host buffers to MPI, as in the paper; with a CUDA-aware MPI (Open MPI or MPICH
built with CUDA) ``ICERESIST_CUDA_AWARE_MPI=1`` hands MPI the device buffers themselves.

A message is a list of entries (local block row, position within the block's trailing values): the cells of a layer
for each of ``K`` leading components (``[block, K, 512]``: the populations, h), or every value of whole blocks. Both
sides list the entries of one message in the same order (:mod:`iceresist.parallel.decomposition`), and the buffer
is ``[K, entries]``: consecutive threads read consecutive cells.
"""

from __future__ import annotations

import os
from functools import lru_cache

import numpy as np

from iceresist.backends.launch import ItemLauncher

#: Set to 1 where the MPI library takes CUDA device buffers (a CUDA-aware build); the package index's MPICH does not.
CUDA_AWARE_ENV = "ICERESIST_CUDA_AWARE_MPI"


def cuda_aware() -> bool:
    """Whether ``ICERESIST_CUDA_AWARE_MPI`` asks for device buffers handed to MPI."""
    return os.environ.get(CUDA_AWARE_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def _pack(i, arr, rows, cells, count, buf):
    k = i // count
    e = i - k * count
    buf[k, e] = arr[rows[e], k, cells[e]]


def _unpack(i, arr, rows, cells, count, buf):
    k = i // count
    e = i - k * count
    arr[rows[e], k, cells[e]] = buf[k, e]


@lru_cache(maxsize=None)
def launchers(target):
    """(pack, unpack): ``pack(K n, arr, rows, cells, n, buf)`` sets ``buf[k, e] = arr[rows[e], k, cells[e]]``,
    ``unpack`` the reverse, for e < n, k < K."""
    names = ("arr", "rows", "cells", "count", "buf")
    return (ItemLauncher(target, target.device(_pack), names, label="halo_pack"),
            ItemLauncher(target, target.device(_unpack), names, label="halo_unpack"))


def entries(rows, cells, width: int):
    """(rows, positions) of a message: ``cells`` per entry, or with ``cells`` None every position < ``width`` of
    each row in ``rows`` (whole blocks), row by row."""
    rows = np.asarray(rows, dtype=np.int64)
    if cells is not None:
        return rows, np.asarray(cells, dtype=np.int64)
    return np.repeat(rows, width), np.tile(np.arange(width, dtype=np.int64), len(rows))


def _mpi_buffer(dbuf):
    """What MPI is handed for a device buffer: the buffer itself (its ``__cuda_array_interface__``); under the CUDA
    simulator, whose device memory is host memory, the NumPy array behind it."""
    if hasattr(dbuf, "__cuda_array_interface__"):
        return dbuf
    return dbuf._ary


class _Route:
    """One message to or from one rank: its entries on the device, its device buffer and (staged) host buffer."""

    def __init__(self, target, rank: int, rows, cells, k: int, dtype, staged: bool):
        self.rank = rank
        self.count = len(rows)
        self.rows, self.cells = target.to_device(rows), target.to_device(cells)
        shape = (k, self.count)
        self.dbuf = target.to_device(np.zeros(shape, dtype=dtype))
        self.hbuf = np.zeros(shape, dtype=dtype) if staged else None
        self.nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize


class DevicePlan:
    """The halo exchange of device arrays of one shape and dtype: ``recvs`` and ``sends`` are ``(rank, rows,
    cells)`` with ``cells`` None for whole blocks; ``layers``: the arrays are ``[block, ..., 512]`` and the
    entries cells of that last axis (each leading component a row of the buffer), else whole blocks of any
    trailing shape."""

    def __init__(self, target, shape, dtype, recvs, sends, layers: bool):
        self.target = target
        shape = tuple(int(n) for n in shape)      # a device array's shape refuses negative indices
        nb = shape[0]
        if layers:
            self.view_shape = (nb, int(np.prod(shape[1:-1], dtype=np.int64)), int(shape[-1]))
        else:
            self.view_shape = (nb, 1, int(np.prod(shape[1:], dtype=np.int64)))
        k, width = self.view_shape[1], self.view_shape[2]
        self.staged = not cuda_aware()

        def route(r, rows, cells):
            return _Route(target, r, *entries(rows, cells, width), k, dtype, self.staged)

        self.recvs = [route(*m) for m in recvs]
        self.sends = [route(*m) for m in sends]
        self.pack, self.unpack = launchers(target)

    def pack_sends(self, arr) -> None:
        """Each send's values of ``arr`` into its device buffer."""
        a3 = arr.reshape(self.view_shape)
        for m in self.sends:
            self.pack(self.view_shape[1] * m.count, a3, m.rows, m.cells, np.int64(m.count), m.dbuf)

    def unpack_recvs(self, arr) -> None:
        """Each receive's device buffer into its values of ``arr``."""
        a3 = arr.reshape(self.view_shape)
        for m in self.recvs:
            self.unpack(self.view_shape[1] * m.count, a3, m.rows, m.cells, np.int64(m.count), m.dbuf)

    def start(self, comm, arr, tag: int):
        """Post the receives, pack and post the sends of ``arr``; returns the
        :class:`~iceresist.parallel.decomposition.Pending` exchange, whose completion unpacks into ``arr``."""
        from iceresist.parallel.decomposition import Pending

        reqs, sent = [], 0
        for m in self.recvs:
            reqs.append(comm.Irecv(m.hbuf if self.staged else _mpi_buffer(m.dbuf), source=m.rank, tag=tag))
        self.pack_sends(arr)
        if not self.staged:
            self.target.synchronize()            # the buffers packed before MPI reads them
        for m in self.sends:
            if self.staged:
                m.dbuf.copy_to_host(m.hbuf)
            reqs.append(comm.Isend(m.hbuf if self.staged else _mpi_buffer(m.dbuf), dest=m.rank, tag=tag))
            sent += m.nbytes

        def complete():
            if self.staged:
                for m in self.recvs:
                    m.dbuf.copy_to_device(m.hbuf)
            self.unpack_recvs(arr)

        return Pending(reqs, sent, complete)
