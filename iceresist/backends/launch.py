"""Launchers of per-cell device functions over a block forest (DESIGN.md section 3).

A per-cell update ``cell(b, c, *args)`` is written once; the launcher maps it:

* CPU: ``numba.njit(parallel=True)``, ``prange`` over blocks, the 512 cells of a
  block in order (x fastest) inside one thread (or one call of a per-block form
  of the same update, ``per_block=True``);
* CUDA: one thread per cell, grid = nblocks, block = 512 threads (8x8x8 cells).

Launchers are generated with named arguments (numba's CUDA kernels take no
``*args``) and live outside the kernels, so the same cell function serves both.
"""

from __future__ import annotations

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


class CellLauncher:
    """Callable ``launcher(nblocks, *args)`` running ``cell(b, c, *args)`` for every cell of every block."""

    def __init__(self, target, cell, argnames, per_block: bool = False):
        """``cell(b, c, *args)``; with ``per_block`` (CPU only) ``cell(b, *args)`` updates a whole block."""
        self.target = target
        self.cell = cell
        self.argnames = tuple(argnames)
        sig = ", ".join(self.argnames)
        if target.is_cuda:
            from numba import cuda

            src = (f"def launch_cells({sig}):\n"
                   "    b = cuda.blockIdx.x\n"
                   "    c = cuda.threadIdx.x\n"
                   f"    cell(b, c, {sig})\n")
            ns = {"cuda": cuda, "cell": cell}
            exec(compile(src, "<iceresist launcher cuda>", "exec"), ns)
            self._kernel = cuda.jit(ns["launch_cells"])
        else:
            inner = (f"        cell(b, {sig})\n" if per_block else
                     f"        for c in range({CUDA_BLOCK_CELLS}):\n            cell(b, c, {sig})\n")
            src = f"def launch_cells(nblocks, {sig}):\n    for b in prange(nblocks):\n" + inner
            ns = {"prange": numba.prange, "cell": cell}
            exec(compile(src, "<iceresist launcher cpu>", "exec"), ns)
            self._kernel = numba.njit(ns["launch_cells"], parallel=True, fastmath=set(CPU_FASTMATH))
        self.source = src

    def __call__(self, nblocks, *args):
        if nblocks == 0:
            return
        if self.target.is_cuda:
            self._kernel[nblocks, CUDA_BLOCK_CELLS](*args)
        else:
            self._kernel(nblocks, *args)
