"""JIT flags and the compile calls of the backend layer (cf. PySDM's ``impl_numba/conf.py``).

The lowest module of :mod:`iceresist.backends`: it imports numba and nothing of the engine but its errors, so
that :mod:`~iceresist.backends.jit` (targets, host <-> device), :mod:`~iceresist.backends.launch` (launchers)
and :mod:`~iceresist.backends.cache` (the kernel cache) all build on it. Kernel modules take what they need
from those three and import no numba themselves.
"""

from __future__ import annotations

import itertools
import os
import weakref

import numba
from numba.core import bytecode

from iceresist.errors import InputError

#: CPU fast-math flags: everything but ``nnan``/``ninf`` (so NaN checks survive), ``nsz`` and ``arcp``. Each of the
#: two made a kernel compiled in the process and the same kernel loaded from the on-disk cache give different bits:
#: ``nsz`` beside ``reassoc`` in a tier-1 case (9.954 against 9.799 N), ``arcp`` alone in the velocity extension of
#: the free surface (1 ulp in 3 175 of 92 160 velocity components, so a tier-2 run depended on whether its kernels were
#: compiled or loaded); measured flag by flag (tests/test_cache_determinism.py).
CPU_FASTMATH = {"contract", "afn", "reassoc"}


def _distinct_function_ids():
    """Number this process's compiled functions from a random start instead of 1.

    numba names a compiled function by module, qualified name, argument types and a counter of the process
    (``FunctionIdentity.unique_id``). Two processes that build the same closure with different constants in the
    same order (the fused LBM step of BGK and of the cumulant operator: both ``<dynamic>.stream_collide_block``,
    both number 9) write libraries with one symbol name for two bodies to the on-disk kernel cache; a third process
    that loads both links every call to the first one loaded. Measured: the Poiseuille rung ran with BGK
    (relative error 1.11e-2 against 4.27e-3) once a BGK kernel of float32 had been loaded in the same process
    (numba issue 10486). A random 48-bit start makes the counters of two processes overlap with negligible
    chance; tests/test_kernel_cache.py guards it."""
    bytecode.FunctionIdentity._unique_ids = itertools.count(int.from_bytes(os.urandom(6), "little") << 16)


_distinct_function_ids()

#: Threads per block for one-thread-per-cell CUDA launches (8x8x8 cells = 512).
CUDA_BLOCK_CELLS = 512

#: The parallel loop of generated CPU launchers.
prange = numba.prange


#: Every kernel made in this process (numba dispatchers, weakly; not the inlined device functions): those without
#: code yet are the ones a first run still compiles (:mod:`iceresist.backends.compilelog`).
KERNELS: weakref.WeakSet = weakref.WeakSet()


def made(kernel):
    """Count ``kernel`` among the :data:`KERNELS` of this process; returns it."""
    try:
        KERNELS.add(kernel)
    except TypeError:       # not weakly referable: not counted
        pass
    return kernel


def cpu_jit(fn, parallel: bool = False, cache: bool = False, **options):
    """``numba.njit`` of ``fn`` with the project's fast-math flags (:data:`CPU_FASTMATH`); a kernel (not an inlined
    device function) is counted for the compile progress lines (:mod:`iceresist.backends.compilelog`)."""
    kern = numba.njit(fn, parallel=parallel, fastmath=set(CPU_FASTMATH), cache=cache, **options)
    return kern if options.get("inline") == "always" else made(kern)


def cuda_api():
    """The ``numba.cuda`` module (the simulator's where NUMBA_ENABLE_CUDASIM=1). A CUDA kernel that calls
    ``cuda.grid``, ``cuda.atomic``, ... must find it as a module global: the simulator swaps that global for a
    per-thread stand-in while the kernel runs."""
    from numba import cuda

    return cuda


def cuda_kernel(fn, name: str, threads: int, **options):
    """``numba.cuda.jit(fn, launch_bounds=threads, **options)``, tagged ``kernel_name = name`` (what the build
    check and docs/PERFORMANCE.md call it) and ``kernel_threads = threads``.

    The launch bound tells ptxas the largest block the kernel is launched with, so it keeps registers x threads
    within the register file (spilling if it must) and the kernel always launches; without it ptxas assumes
    1024 threads or none and may hand out more registers than a 512-thread block can hold."""
    from numba import config, cuda

    if not config.ENABLE_CUDASIM:  # the simulator takes no launch bounds
        options["launch_bounds"] = threads
    kern = cuda.jit(fn, **options)
    kern.kernel_name = name
    kern.kernel_threads = threads
    return made(kern)


def max_threads() -> int:
    """The most CPU threads numba's parallel loops may use in this process."""
    return numba.config.NUMBA_NUM_THREADS


def get_threads() -> int:
    """The CPU threads numba's parallel loops use now."""
    return numba.get_num_threads()


def set_threads(n: int | None, option: str = "--threads"):
    """Run numba's parallel loops on ``n`` CPU threads (None: leave as is); a count outside 1..max is refused
    naming ``option``."""
    if n is None:
        return
    if not 1 <= n <= max_threads():
        raise InputError(f"{option}: must lie in 1..{max_threads()} (got {n})")
    numba.set_num_threads(n)
