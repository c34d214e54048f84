"""The only module that imports numba's decorators (cf. PySDM's ``impl_numba/conf.py``).

A kernel is written once as scalar Python inside a ``build_*(target, real)``
factory and compiled for a :class:`Target`:

* ``target.device`` compiles a scalar device function: ``numba.njit(inline="always")``
  on the CPU, ``numba.cuda.jit(device=True)`` on the GPU;
* ``target.name`` tells launchers whether to loop with ``prange`` or launch a grid.

Precision is a value ``real`` (``np.float32`` or ``np.float64``); builders type
their constants with it (``real(0.5)``) so fp32 kernels never compute in fp64.

NUMBA_ENABLE_CUDASIM must be set before numba is first imported for the CUDA
simulator; tests set it in ``tests/conftest.py``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numba
import numpy as np

#: CPU fast-math flags: everything but ``nnan``/``ninf`` so NaN checks survive.
CPU_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

#: Threads per block for one-thread-per-cell CUDA launches (8x8x8 cells = 512).
CUDA_BLOCK_CELLS = 512


def real_type(precision: str):
    """Return the NumPy scalar type of ``'float32'`` or ``'float64'``."""
    try:
        return {"float32": np.float32, "float64": np.float64}[precision]
    except KeyError:
        raise ValueError(f"precision must be 'float32' or 'float64', not {precision!r}") from None


@dataclass(frozen=True)
class Target:
    """A compile target: ``name`` is ``'cpu'`` or ``'cuda'``; ``device`` compiles scalar device functions."""

    name: str
    device: Callable
    simulator: bool = False

    @property
    def is_cuda(self) -> bool:
        return self.name == "cuda"

    def kernel(self, fn=None, **kw):
        """Compile a launcher body: ``njit(parallel=True)`` on the CPU, ``cuda.jit`` on the GPU."""
        if fn is None:
            return lambda f: self.kernel(f, **kw)
        if self.is_cuda:
            from numba import cuda as _cuda

            return _cuda.jit(fn, **kw)
        return numba.njit(fn, parallel=kw.pop("parallel", True), fastmath=set(CPU_FASTMATH), cache=kw.pop("cache", False), **kw)


def _cpu_device(fn):
    return numba.njit(fn, inline="always", fastmath=set(CPU_FASTMATH), cache=False)


def _cuda_device(fn):
    from numba import cuda as _cuda

    return _cuda.jit(fn, device=True)


cpu = Target("cpu", _cpu_device)


@lru_cache(maxsize=1)
def cuda_available() -> bool:
    """True where numba-cuda sees a GPU, or where the CUDA simulator is switched on."""
    try:
        from numba import cuda as _cuda

        return bool(_cuda.is_available())
    except Exception:  # pragma: no cover - depends on the machine
        return False


def cuda() -> Target:
    """The CUDA target (the simulator when NUMBA_ENABLE_CUDASIM=1)."""
    sim = os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1"
    return Target("cuda", _cuda_device, simulator=sim)


def resolve_backend(name: str) -> Target:
    """``auto`` takes CUDA where a GPU is visible (not the simulator), else the CPU."""
    if name == "cpu":
        return cpu
    if name == "cuda":
        if not cuda_available():
            raise RuntimeError("backend 'cuda' asked for but no CUDA GPU is visible; use --backend cpu or auto")
        return cuda()
    if name == "auto":
        sim = os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1"
        return cuda() if (cuda_available() and not sim) else cpu
    raise ValueError(f"backend must be auto, cpu or cuda, not {name!r}")
