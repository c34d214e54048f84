"""Halo messages between MPI ranks on the host: a non-blocking exchange posted (:func:`swap_start`) and completed
(:func:`swap_finish`), and the :class:`Pending` exchange between the two, which device exchanges
(:mod:`iceresist.parallel.staging`) return too."""

from __future__ import annotations

import time

import numpy as np


class Pending:
    """A halo exchange under way: its requests, the bytes sent, and ``complete()``, which writes what arrived once
    the requests are done (the receive buffers into a host array, or a device plan's unpack, :mod:`.staging`).
    The send buffers stay referenced here until the sends complete."""

    def __init__(self, reqs, sent: int, complete, keep=()):
        self.reqs, self.sent, self.complete, self.keep = reqs, sent, complete, keep


def swap_start(comm, view: np.ndarray, recvs, sends, tag: int = 7) -> Pending:
    """Post one non-blocking exchange over ``comm``: for each ``(rank, rows, populations, cells)`` of ``sends`` the
    values ``view[rows]`` (populations and cells None: whole rows) or ``view[rows, populations, cells]`` go to that
    rank (copied into send buffers now), for each of ``recvs`` a receive is posted; :func:`swap_finish` waits for
    them and writes what arrived there (that rank's sends to this rank list the same values in the same order). The
    messages of :class:`~iceresist.parallel.staging.DevicePlan` on the host."""
    recvs = [(r, rows if c is None else (rows, p, c)) for r, rows, p, c in recvs]
    sends = [(r, rows if c is None else (rows, p, c)) for r, rows, p, c in sends]
    bufs_in, reqs, outs, sent = [], [], [], 0
    for r, index in recvs:
        buf = np.empty_like(view[index])
        bufs_in.append((index, buf))
        reqs.append(comm.Irecv(buf, source=r, tag=tag))
    for r, index in sends:
        buf = np.ascontiguousarray(view[index])
        outs.append(buf)
        sent += buf.nbytes
        reqs.append(comm.Isend(buf, dest=r, tag=tag))

    def complete():
        for index, buf in bufs_in:
            view[index] = buf

    return Pending(reqs, sent, complete, outs)


def swap_finish(pending: Pending) -> None:
    """Wait for the exchange ``pending`` and write what arrived."""
    from mpi4py import MPI

    MPI.Request.Waitall(pending.reqs)
    pending.complete()


class Exchanges:
    """The bookkeeping of a rank's halo exchanges, shared by the decompositions: totals since construction
    (``exchanges``, ``bytes_sent``, ``exchange_s``, the wall seconds inside posting and waiting) and the
    completion of a posted exchange."""

    exchanges, bytes_sent, exchange_s = 0, 0, 0.0

    def _posted(self, pending: Pending, t0: float) -> Pending:
        self.bytes_sent += pending.sent
        self.exchange_s += time.perf_counter() - t0
        return pending

    def finish_exchange(self, pending: Pending) -> None:
        """Wait for an exchange that ``start_exchange`` posted and write the halo values it brought."""
        t0 = time.perf_counter()
        swap_finish(pending)
        self.exchanges += 1
        self.exchange_s += time.perf_counter() - t0
