"""Compile targets, precision and host <-> device transfers: what a kernel module needs of numba.

The JIT flags and the compile calls live in :mod:`iceresist.backends.conf`, the launchers in
:mod:`iceresist.backends.launch`; this module re-exports what kernel modules use of them, so that no kernel
module imports numba itself.

A kernel is written once as scalar Python inside a ``build_*(target, real)``
factory and compiled for a :class:`Target`:

* ``target.device`` compiles a scalar device function: ``numba.njit(inline="always")``
  on the CPU, ``numba.cuda.jit(device=True)`` on the GPU;
* ``target.name`` tells launchers whether to loop with ``prange`` or launch a grid.

Precision is a value ``real`` (``np.float32`` or ``np.float64``); builders type
their constants with it (``real(0.5)``) so fp32 kernels never compute in fp64.

Arrays cross between host and device only through the target (:meth:`Target.to_device`,
:meth:`Target.to_host`), so the GPU build check (:mod:`iceresist.backends.buildcheck`) can stand host arrays
in for device arrays on a machine without a GPU, and a transfer count sees every copy.

NUMBA_ENABLE_CUDASIM must be set before numba is first imported for the CUDA
simulator; tests set it in ``tests/conftest.py``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np

from iceresist.backends import launch
from iceresist.backends.conf import (CPU_FASTMATH, CUDA_BLOCK_CELLS, cpu_jit, cuda_api, cuda_kernel, get_threads,
                                     max_threads, prange, set_threads)
from iceresist.errors import InputError

__all__ = ["CPU_FASTMATH", "CUDA_BLOCK_CELLS", "HostStandIn", "Target", "cpu", "cpu_jit", "cuda", "cuda_api",
           "cuda_available", "cuda_kernel", "get_threads", "is_host_array", "max_threads", "prange", "real_type",
           "resolve_backend", "resolve_target", "set_threads"]


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
        """Compile a launcher body: ``njit(parallel=True)`` on the CPU, ``cuda.jit`` on the GPU for blocks of at
        most ``threads`` threads (named by ``fn.__name__``; :func:`iceresist.backends.conf.cuda_kernel`)."""
        if fn is None:
            return lambda f: self.kernel(f, **kw)
        if self.is_cuda:
            kw.pop("parallel", None)
            kw.pop("error_model", None)
            return cuda_kernel(fn, fn.__name__, kw.pop("threads", CUDA_BLOCK_CELLS), **kw)
        kw.pop("threads", None)
        return cpu_jit(fn, parallel=kw.pop("parallel", True), cache=kw.pop("cache", False), **kw)

    # ------------------------------------------------------------------ host <-> device
    def to_device(self, a):
        """``a`` (a NumPy array) where the target's kernels read it: a device copy on CUDA, ``a`` itself (made
        C-contiguous) on the CPU."""
        a = np.ascontiguousarray(a)
        if not self.is_cuda:
            return a
        if _HOST_STAND_IN:
            return a.copy().view(HostStandIn)
        return cuda_api().to_device(a)

    def to_host(self, a, copy: bool = True) -> np.ndarray:
        """A NumPy array of the target array ``a``: a device-to-host copy on CUDA; on the CPU a copy, or ``a``
        itself with ``copy=False``."""
        if self.is_cuda:
            return a.copy_to_host()
        return np.array(a) if copy else a

    def fill(self, a, value):
        """Set every element of the target array ``a`` to ``value`` where it lives: no host array crosses over (on
        CUDA a kernel, :func:`iceresist.backends.launch.fill`)."""
        if self.is_cuda:
            launch.fill(self, a, value)
        else:
            a[...] = value

    def fill4(self, a, va, b, vb, c, vc, d, vd):
        """:meth:`fill` of four target arrays at once: one launch on CUDA."""
        if self.is_cuda:
            launch.fill4(self, a, va, b, vb, c, vc, d, vd)
        else:
            a[...], b[...], c[...], d[...] = va, vb, vc, vd

    def copy(self, dst, src):
        """Copy the target array ``src`` into ``dst`` (same shape) on the target: device to device on CUDA."""
        if self.is_cuda:
            dst.copy_to_device(src)
        else:
            dst[...] = src

    def synchronize(self):
        """Wait for the device (CUDA); a no-op on the CPU."""
        if self.is_cuda:
            launch.note_sync()
        if self.is_cuda and not _HOST_STAND_IN:
            cuda_api().synchronize()


#: Set by the GPU build check: CUDA "device arrays" are host arrays (:class:`HostStandIn`) and nothing runs.
_HOST_STAND_IN = False


class HostStandIn(np.ndarray):
    """A NumPy array with the two methods of a numba-cuda device array the engine calls, standing in for one
    while the GPU build check traces a step on a machine without a GPU."""

    def copy_to_host(self, ary=None, stream=0):
        if ary is None:
            return np.array(self)
        ary[...] = self
        return ary

    def copy_to_device(self, ary, stream=0):
        self[...] = ary


def is_host_array(a) -> bool:
    """``a`` is a NumPy array in host memory, not a CUDA device array (nor a build-check stand-in for one)."""
    return isinstance(a, np.ndarray) and not isinstance(a, HostStandIn)


def _cpu_device(fn):
    return cpu_jit(fn, inline="always")


def _cuda_device(fn):
    return cuda_api().jit(fn, device=True)


cpu = Target("cpu", _cpu_device)


@lru_cache(maxsize=1)
def cuda_available() -> bool:
    """True where numba-cuda sees a GPU, or where the CUDA simulator is switched on."""
    try:
        return bool(cuda_api().is_available())
    except Exception:  # pragma: no cover - depends on the machine
        return False


def device_count() -> int:
    """GPUs numba-cuda sees (0 without CUDA; 1 in the simulator)."""
    try:
        return len(cuda_api().gpus) if cuda_available() else 0
    except Exception:  # pragma: no cover - depends on the machine
        return 0


def select_device(index: int) -> None:
    """Make GPU ``index`` this process's device (before any array is put on one)."""
    cuda_api().select_device(int(index))


def cuda() -> Target:
    """The CUDA target (the simulator when NUMBA_ENABLE_CUDASIM=1)."""
    sim = os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1"
    return Target("cuda", _cuda_device, simulator=sim)


def resolve_backend(name: str) -> Target:
    """``auto`` takes CUDA where a GPU is visible (not the simulator), else the CPU."""
    if name == "cpu":
        return cpu
    if name == "cuda":
        if not (cuda_available() or _HOST_STAND_IN):
            raise RuntimeError("backend 'cuda' asked for but no CUDA GPU is visible; use --backend cpu or auto")
        return cuda()
    if name == "auto":
        sim = os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1"
        return cuda() if (cuda_available() and not sim) else cpu
    raise ValueError(f"backend must be auto, cpu or cuda, not {name!r}")


def resolve_target(backend: str, key: str = "numerics.backend") -> Target:
    """:func:`resolve_backend` for input: a CUDA request without a GPU, or an unknown name, is an
    :class:`~iceresist.errors.InputError` naming ``key``."""
    try:
        return resolve_backend(backend)
    except (RuntimeError, ValueError) as exc:
        raise InputError(f"{key}: {exc}") from None
