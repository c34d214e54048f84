"""Several processes (MPI, paper section 2.5): the world communicator when launched by ``mpirun`` with more than one
rank, and the block decomposition (:mod:`iceresist.parallel.decomposition`).

The code runs unchanged without MPI: :func:`world` is None unless an MPI launcher started the process (its
environment names the ranks) and mpi4py (the ``mpi`` extra) is installed.
"""

from __future__ import annotations

import os

from iceresist.backends import jit
from iceresist.backends.conf import get_threads, max_threads, set_threads
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
                share_cores(_WORLD)
    return _WORLD


def share_cores(comm) -> int:
    """Give this rank its share of the machine's cores for numba's parallel loops: the cores over the ranks on this
    node (at least one), unless ``NUMBA_NUM_THREADS`` says otherwise; returns the thread count. Ranks that each run
    every core's worth of threads wait on each other (measured 100 x slower on a 2-core machine)."""
    if "NUMBA_NUM_THREADS" in os.environ:
        return get_threads()
    from mpi4py import MPI

    local = comm.Split_type(MPI.COMM_TYPE_SHARED, key=comm.rank)
    n = max(1, min(max_threads(), (os.cpu_count() or 1) // local.size))
    local.Free()
    set_threads(n)
    return n


def abort(comm) -> None:
    """Print this rank's traceback and stop every rank (``MPI_Abort``, exit status 1): an error that one rank alone
    meets would otherwise leave the others waiting in their next collective call until the job's time runs out."""
    import sys
    import time
    import traceback

    # one write, and a moment for mpirun to forward it: under load the abort killed the job between the first line
    # and the traceback
    sys.stderr.write(f"iceresist: rank {comm.rank} of {comm.size} failed; stopping every rank\n"
                     + traceback.format_exc())
    sys.stderr.flush()
    time.sleep(0.5)
    comm.Abort(1)


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


def use_local_gpu(comm) -> int | None:
    """On a node with several GPUs, give each of its ranks its own: local rank modulo the GPUs numba-cuda sees
    (where a launcher already gave each rank one GPU, e.g. ``CUDA_VISIBLE_DEVICES`` per task, there is one to
    see and nothing changes). Returns the device index taken, or None. Call it before any array is on a GPU."""
    n = jit.device_count()
    if n <= 1:
        return None
    from mpi4py import MPI

    local = comm.Split_type(MPI.COMM_TYPE_SHARED, key=comm.rank)
    index = local.rank % n
    local.Free()
    jit.select_device(index)
    return index
