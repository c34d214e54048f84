"""Launchers of per-cell device functions over a block forest (DESIGN.md section 3).

A per-cell update ``cell(b, c, *args)`` is written once; the launcher maps it:

* CPU: ``numba.njit(parallel=True)``, ``prange`` over blocks, the 512 cells of a
  block in order (x fastest) inside one thread (or one call of a per-block form
  of the same update, ``per_block=True``);
* CUDA: one thread per cell, grid = nblocks, block = 512 threads (8x8x8 cells).

Launchers are generated with named arguments (numba's CUDA kernels take no
``*args``) and live outside the kernels, so the same cell function serves both.

Every CUDA kernel of the engine is compiled by :func:`cuda_kernel` (which names it) and launched by
:func:`cuda_launch`: the one place a launch happens, so the GPU build check
(:mod:`iceresist.backends.buildcheck`) can record each kernel's argument types, launches of no items
included, instead of running it.

Every launcher has a ``label`` (``"f_update"``, ``"links"``, ``"dem_contact"``, ...), the same on both targets;
within :func:`profiling` each launch is timed under it (the coupled-step benchmark's parts).
"""

from __future__ import annotations

import contextlib
import time
from functools import lru_cache

import numba
import numpy as np

from iceresist.backends.jit import CPU_FASTMATH, CUDA_BLOCK_CELLS
from iceresist.errors import InputError


def copy_into(dst, host):
    """Overwrite a target array (NumPy or CUDA device array) with the host array ``host`` of the same shape
    (a checkpoint being loaded); a shape that does not fit is refused with a message naming both."""
    host = np.ascontiguousarray(host)
    if tuple(dst.shape) != host.shape:
        raise InputError(f"checkpoint array of shape {host.shape} does not fit {tuple(dst.shape)}: "
                         f"it belongs to another scene")
    if hasattr(dst, "copy_to_device"):
        dst.copy_to_device(host)
    else:
        dst[...] = host


#: Set by the GPU build check: ``recorder(kernel, threads, args)`` is called instead of each CUDA launch.
_RECORDER = None


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
    return kern


#: Set by :func:`iceresist.backends.transfers.counting`: ``watch(args)`` sees the arguments of each CUDA launch.
_ARG_WATCH = None


def cuda_launch(kernel, grid: int, threads: int, *args):
    """Launch ``kernel[grid, threads](*args)``; a grid of no blocks launches nothing."""
    if _ARG_WATCH is not None:
        _ARG_WATCH(args)
    if _RECORDER is not None:
        _RECORDER(kernel, threads, args)
    elif grid:
        kernel[grid, threads](*args)


#: Set by :func:`profiling`: ``{label: [seconds, launches]}``, and the device synchronisation after each launch.
_PROFILE = None
_SYNC = None


@contextlib.contextmanager
def profiling(target):
    """Within: every launch made through a launcher (:func:`profiled`) is timed, wall clock, into the yielded
    ``{label: [seconds, launches]}``; on CUDA the device is synchronised after each launch so that the time is the
    kernel's own. Meant for benchmarks: the synchronisation serialises the device."""
    global _PROFILE, _SYNC
    saved = (_PROFILE, _SYNC)
    _PROFILE, _SYNC = {}, (target.synchronize if target.is_cuda else None)
    try:
        yield _PROFILE
    finally:
        _PROFILE, _SYNC = saved


def profiled(label: str, call):
    """``call`` (a launch function) timed under ``label`` within :func:`profiling`; the same call otherwise."""
    def launch(*args):
        if _PROFILE is None:
            return call(*args)
        t0 = time.perf_counter()
        out = call(*args)
        if _SYNC is not None:
            _SYNC()
        entry = _PROFILE.setdefault(label, [0.0, 0])
        entry[0] += time.perf_counter() - t0
        entry[1] += 1
        return out

    launch.label = label
    launch.__name__ = label
    return launch


def device_name(fn) -> str:
    """The Python name of a device function (a numba dispatcher or a plain function)."""
    return getattr(getattr(fn, "py_func", fn), "__name__", "kernel")


def jit_generated(target, src: str, name: str, namespace: dict, label: str | None = None,
                  threads: int = CUDA_BLOCK_CELLS):
    """Compile the generated launcher ``name`` defined by ``src`` (the names it calls in ``namespace``): a CUDA
    kernel named ``label`` (default ``name``) for blocks of at most ``threads`` threads, or a parallel njit with
    the project's fast-math flags on the CPU."""
    if target.is_cuda:
        from numba import cuda

        ns = {"cuda": cuda, **namespace}
        exec(compile(src, f"<iceresist {name} cuda>", "exec"), ns)
        return cuda_kernel(ns[name], label or name, threads)
    ns = {"prange": numba.prange, **namespace}
    exec(compile(src, f"<iceresist {name} cpu>", "exec"), ns)
    return numba.njit(ns[name], parallel=True, fastmath=set(CPU_FASTMATH))


class _GeneratedLauncher:
    """A launcher generated around one device function ``fn``: subclasses give ``name``, the name ``fn`` has in
    the generated source, the source (:meth:`_source`) and the CUDA launch shape (:meth:`_cuda_launch`)."""

    name = ""
    fn_name = ""
    threads = CUDA_BLOCK_CELLS

    def __init__(self, target, fn, argnames, label: str | None = None, **options):
        self.target = target
        self.argnames = tuple(argnames)
        self.label = label or device_name(fn)
        self.source = self._source(target.is_cuda, ", ".join(self.argnames), **options)
        self._kernel = jit_generated(target, self.source, self.name, {self.fn_name: fn}, label=self.label,
                                     threads=self.threads)
        self._call = profiled(self.label, self._launch)

    def __call__(self, n, *args):
        self._call(n, *args)

    def _launch(self, n, *args):
        if self.target.is_cuda:
            grid, threads, lead = self._cuda_launch(n)
            cuda_launch(self._kernel, grid, threads, *lead, *args)
        elif n:
            self._kernel(n, *args)


class CellLauncher(_GeneratedLauncher):
    """Callable ``launcher(nblocks, *args)`` running ``cell(b, c, *args)`` for every cell of every block;
    with ``per_block=True`` (CPU only) ``cell(b, *args)`` updates a whole block."""

    name, fn_name = "launch_cells", "cell"

    def __init__(self, target, cell, argnames, per_block: bool = False, label: str | None = None):
        super().__init__(target, cell, argnames, label=label, per_block=per_block)

    @staticmethod
    def _source(cuda: bool, sig: str, per_block: bool) -> str:
        if cuda:
            return (f"def launch_cells({sig}):\n    b = cuda.blockIdx.x\n    c = cuda.threadIdx.x\n"
                    f"    cell(b, c, {sig})\n")
        inner = (f"        cell(b, {sig})\n" if per_block else
                 f"        for c in range({CUDA_BLOCK_CELLS}):\n            cell(b, c, {sig})\n")
        return f"def launch_cells(nblocks, {sig}):\n    for b in prange(nblocks):\n" + inner

    @staticmethod
    def _cuda_launch(n):
        return n, CUDA_BLOCK_CELLS, ()


#: Threads per CUDA block for one-thread-per-forest-block launches (:class:`BlockLauncher`).
CUDA_BLOCK_THREADS = 128


class BlockLauncher(_GeneratedLauncher):
    """Callable ``launcher(nblocks, *args)`` running ``block(b, *args)`` once per forest block: a reduction
    over the block's cells into ``out[b, ...]`` (diagnostics read on the host from a small array, not a
    copy of the fields).

    * CPU: ``prange`` over blocks;
    * CUDA: one thread per forest block, :data:`CUDA_BLOCK_THREADS` threads per CUDA block.
    """

    name, fn_name = "launch_blocks", "block"
    threads = CUDA_BLOCK_THREADS

    @staticmethod
    def _source(cuda: bool, sig: str) -> str:
        if cuda:
            return (f"def launch_blocks(nblocks, {sig}):\n    b = cuda.grid(1)\n    if b < nblocks:\n"
                    f"        block(b, {sig})\n")
        return f"def launch_blocks(nblocks, {sig}):\n    for b in prange(nblocks):\n        block(b, {sig})\n"

    @staticmethod
    def _cuda_launch(n):
        return (n + CUDA_BLOCK_THREADS - 1) // CUDA_BLOCK_THREADS, CUDA_BLOCK_THREADS, (np.int64(n),)


def _fill_item(i, a, value):
    a[i] = value


@lru_cache(maxsize=None)
def _filler(target):
    return BlockLauncher(target, target.device(_fill_item), ("a", "value"), label="fill")


def fill(target, a, value):
    """Set every element of the contiguous target array ``a`` to ``value`` with a kernel over its elements (a
    reset inside a step that uploads nothing: :meth:`iceresist.backends.jit.Target.fill`)."""
    flat = a.reshape(a.size)
    _filler(target)(int(a.size), flat, a.dtype.type(value))
