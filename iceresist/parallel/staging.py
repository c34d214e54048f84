"""Halo messages packed and unpacked on the device (CUDA ranks; paper section 2.5: device buffers staged through the
host).

A CUDA rank's halo exchange gathers the values it sends into one contiguous device buffer per neighbouring rank with
a kernel (``halo_pack``) and scatters what arrives with another (``halo_unpack``), so only the messages cross the
PCIe bus, never the whole array (a step of the paper's case holds about 20 MB of halo per rank against 0.5 GB of
populations). The buffers go through host buffers to MPI, as in the paper; with a CUDA-aware MPI (Open MPI or MPICH
built with CUDA) ``ICERESIST_CUDA_AWARE_MPI=1`` hands MPI the device buffers themselves.

A message is a list of entries (local block row, component, position): a population of a cell
(``[block, q, 512]``), or every value of whole blocks of any trailing shape (component 0 of the array seen as
``[block, 1, values]``). Both sides list the entries of one message in the same order
(:mod:`iceresist.parallel.decomposition`), and the buffer holds them in that order.
"""

from __future__ import annotations

import os
from functools import lru_cache

import numpy as np

from iceresist.backends.launch import ItemLauncher
from iceresist.parallel.messages import Pending

#: Set to 1 where the MPI library takes CUDA device buffers (a CUDA-aware build); the package index's MPICH does not.
CUDA_AWARE_ENV = "ICERESIST_CUDA_AWARE_MPI"


def cuda_aware() -> bool:
    """Whether ``ICERESIST_CUDA_AWARE_MPI`` asks for device buffers handed to MPI."""
    return os.environ.get(CUDA_AWARE_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def _pack(i, arr, rows, comps, cells, width, buf):
    if width > 0:                   # whole blocks: entry i is value i % width of the (i // width)-th row
        b = i // width
        buf[i] = arr[rows[b], 0, i - b * width]
    else:
        buf[i] = arr[rows[i], comps[i], cells[i]]


def _unpack(i, arr, rows, comps, cells, width, buf):
    if width > 0:
        b = i // width
        arr[rows[b], 0, i - b * width] = buf[i]
    else:
        arr[rows[i], comps[i], cells[i]] = buf[i]


@lru_cache(maxsize=None)
def launchers(target):
    """(pack, unpack): ``pack(n, arr, rows, comps, cells, width, buf)`` sets ``buf[e] = arr[rows[e], comps[e],
    cells[e]]`` for e < n, or with ``width`` > 0 (whole blocks) ``buf[e] = arr[rows[e // width], 0, e % width]``;
    ``unpack`` the reverse."""
    names = ("arr", "rows", "comps", "cells", "width", "buf")
    return (ItemLauncher(target, target.device(_pack), names, label="halo_pack"),
            ItemLauncher(target, target.device(_unpack), names, label="halo_unpack"))


def _mpi_buffer(dbuf):
    """What MPI is handed for a device buffer: the buffer itself (its ``__cuda_array_interface__``); under the CUDA
    simulator, whose device memory is host memory, the NumPy array behind it."""
    if hasattr(dbuf, "__cuda_array_interface__"):
        return dbuf
    return dbuf._ary


class _Route:
    """One message to or from one rank: its entries on the device (``cells`` None: whole rows of ``width`` values,
    indexed in the kernel), its device buffer and (staged) host buffer."""

    def __init__(self, target, rank: int, rows, comps, cells, width: int, dtype, staged: bool):
        self.rank = rank
        rows = np.asarray(rows, dtype=np.int64)
        none = np.zeros(0, dtype=np.int64)
        self.width = np.int64(0 if cells is not None else width)
        self.count = len(rows) if cells is not None else len(rows) * width
        self.rows = target.to_device(rows)
        self.comps, self.cells = (target.to_device(none if a is None else np.asarray(a, dtype=np.int64))
                                  for a in (comps, cells))
        self.dbuf = target.to_device(np.zeros(self.count, dtype=dtype))
        self.hbuf = np.zeros(self.count, dtype=dtype) if staged else None
        self.nbytes = self.count * np.dtype(dtype).itemsize


class DevicePlan:
    """The halo exchange of device arrays of one shape and dtype: ``recvs`` and ``sends`` are ``(rank, rows, comps,
    cells)``, the entries of a ``[block, q, 512]`` array, or with ``comps`` and ``cells`` None whole blocks of any
    trailing shape (module docstring)."""

    def __init__(self, target, shape, dtype, recvs, sends):
        self.target = target
        shape = tuple(int(n) for n in shape)      # a device array's shape refuses negative indices
        whole = any(m[3] is None for m in list(recvs) + list(sends))
        if whole:
            self.view_shape = (shape[0], 1, int(np.prod(shape[1:], dtype=np.int64)))
        else:
            self.view_shape = (shape[0], int(np.prod(shape[1:-1], dtype=np.int64)), shape[-1])
        self.staged = not cuda_aware()

        def route(r, rows, comps, cells):
            return _Route(target, r, rows, comps, cells, self.view_shape[2], dtype, self.staged)

        self.recvs = [route(*m) for m in recvs]
        self.sends = [route(*m) for m in sends]
        self.pack, self.unpack = launchers(target)

    def pack_sends(self, arr) -> None:
        """Each send's values of ``arr`` into its device buffer."""
        a3 = arr.reshape(self.view_shape)
        for m in self.sends:
            self.pack(m.count, a3, m.rows, m.comps, m.cells, m.width, m.dbuf)

    def unpack_recvs(self, arr) -> None:
        """Each receive's device buffer into its values of ``arr``."""
        a3 = arr.reshape(self.view_shape)
        for m in self.recvs:
            self.unpack(m.count, a3, m.rows, m.comps, m.cells, m.width, m.dbuf)

    def start(self, comm, arr, tag: int):
        """Post the receives, pack and post the sends of ``arr``; returns the
        :class:`~iceresist.parallel.messages.Pending` exchange, whose completion unpacks into ``arr``."""
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
