"""Launchers over all cells of a block forest from one cell function: prange over blocks on the
CPU, one CUDA thread per cell (a CUDA block per forest block) on the GPU (DESIGN.md section 3).

``cell_fn(b, c, *args)`` is a device function that updates cell ``c`` of block ``b``
and returns nothing; the launcher takes the number of blocks first.
"""

from __future__ import annotations

import numpy as np

from iceresist.backends.jit import CUDA_BLOCK_CELLS
from iceresist.freesurface.layout import CELLS


def build_launcher(target, cell_fn, nargs: int):
    """Return ``launch(nblocks, *args)`` running ``cell_fn`` on every cell of ``nblocks`` blocks."""
    args = ", ".join(f"a{i}" for i in range(nargs))
    if target.is_cuda:
        from numba import cuda

        src = (f"def kernel(nblocks, {args}):\n"
               "    b = cuda.blockIdx.x\n"
               "    c = cuda.threadIdx.x\n"
               "    if b < nblocks:\n"
               f"        cell_fn(b, c, {args})\n")
        ns = {"cuda": cuda, "cell_fn": cell_fn}
        exec(compile(src, "<iceresist launcher>", "exec"), ns)
        kern = target.kernel(ns["kernel"])
        assert CUDA_BLOCK_CELLS == CELLS

        def launch(nblocks, *a):
            if nblocks > 0:
                kern[nblocks, CELLS](nblocks, *a)

        return launch
    import numba

    src = (f"def kernel(nblocks, {args}):\n"
           "    for bu in prange(nblocks):\n"
           "        b = int64(bu)\n"
           f"        for c in range({CELLS}):\n"
           f"            cell_fn(b, c, {args})\n")
    # the parfor index may be unsigned; uint64 mixed with int64 block ids would type as float64
    ns = {"prange": numba.prange, "cell_fn": cell_fn, "int64": np.int64}
    exec(compile(src, "<iceresist launcher>", "exec"), ns)
    kern = target.kernel(ns["kernel"])

    def launch(nblocks, *a):
        kern(nblocks, *a)

    return launch
