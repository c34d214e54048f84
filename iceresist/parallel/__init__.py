"""Several processes (MPI, paper section 2.5): the world communicator when launched by ``mpirun`` with more than one
rank, and the block decomposition (:mod:`iceresist.parallel.decomposition`).

The code runs unchanged without MPI: :func:`world` is None unless an MPI launcher started the process (its
environment names the ranks) and mpi4py (the ``mpi`` extra) is installed.
"""

from __future__ import annotations

import os

from iceresist.errors import InputError

#: Environment variables an MPI launcher sets for its ranks (MPICH's Hydra, Open MPI, Slurm's PMI).
_LAUNCHER_VARS = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS")

_WORLD = False  # not looked up yet


def launched_by_mpi() -> bool:
    return any(v in os.environ for v in _LAUNCHER_VARS)


def world():
    """``mpi4py.MPI.COMM_WORLD`` when this process is one of several MPI ranks, else None."""
    global _WORLD
    if _WORLD is False:
        _WORLD = None
        if launched_by_mpi():
            try:
                from mpi4py import MPI
            except ImportError:
                raise InputError("mpirun: mpi4py is not installed; install the `mpi` extra "
                                 "(pip install -e \".[mpi]\")") from None
            if MPI.COMM_WORLD.size > 1:
                _WORLD = MPI.COMM_WORLD
    return _WORLD


def rank() -> int:
    """This process's rank (0 without MPI)."""
    w = world()
    return 0 if w is None else int(w.rank)


def on_rank0(check, comm=None) -> None:
    """Run ``check()`` (which raises :class:`InputError` on bad input) on rank 0 only and raise its error on every
    rank: checks of the file system, which rank 0 is about to write, agree on all ranks. Without MPI, just
    ``check()``."""
    if comm is None:
        check()
        return
    error = None
    if comm.rank == 0:
        try:
            check()
        except InputError as exc:
            error = str(exc)
    error = comm.bcast(error, root=0)
    if error is not None:
        raise InputError(error)
