"""The compiler side of the GPU build check (:mod:`iceresist.validate.gpu_build`): tracing launches with host
stand-ins instead of running them, and compiling a kernel for a real device on any machine.

:func:`tracing`: within it CUDA arrays are host stand-ins (:class:`~iceresist.backends.jit.HostStandIn`) and every
launch (:func:`~iceresist.backends.launch.cuda_launch`, launches of no items too) is recorded instead of run; no GPU
and no CUDA driver are needed. :func:`compile_kernel`: numba-cuda's NVVM to PTX for compute capability :data:`CC`
(numba-cuda asks the current device for it when it compiles a device function; without a GPU this module answers
for it), then ``ptxas -arch=sm_90 -v`` to a cubin, which reports registers, stack and spill bytes. A kernel
launches when registers x threads per block fit the sm_90 register file (:data:`REGISTER_FILE`); a float32 kernel
should hold no float64 arithmetic (:func:`float64_ops` counts it in the PTX).

NVVM and ptxas come from the CUDA 12 packages on the package index (the ``gpu`` extra of ``pyproject.toml``).
Tracing must run in a process of its own with ``NUMBA_ENABLE_CUDASIM=0``: the simulator replaces ``numba.cuda``
when numba is first imported.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from iceresist.backends import jit, launch

#: Compute capability compiled for: sm_90 (H100, H200).
CC = (9, 0)

#: 32-bit registers per SM on sm_90, and the most one thread block may use.
REGISTER_FILE = 65536

#: PTX instructions that compute in float64 (loads and stores of float64 data are not arithmetic).
_F64_OP = re.compile(r"^\s*(?:@!?%p\d+\s+)?(?:add|sub|mul|div|fma|mad|neg|abs|min|max|sqrt|rsqrt|rcp|setp|selp|cvt)"
                     r"(?:\.[a-z0-9]+)*\.f64\b", re.MULTILINE)


def float64_ops(ptx: str) -> int:
    """The number of PTX instructions in ``ptx`` that compute in float64 or convert to or from it."""
    return len(_F64_OP.findall(ptx))


@dataclass
class KernelBuild:
    """What the compilers said of one kernel and one argument signature."""

    name: str
    threads: int
    signature: str
    float32: bool
    ptx_ok: bool = False
    cubin_ok: bool = False
    registers: int = 0
    spill_stores_bytes: int = 0
    spill_loads_bytes: int = 0
    stack_bytes: int = 0
    float64_ops: int = 0
    compile_seconds: float = 0.0
    error: str = ""
    scenes: list = field(default_factory=list)

    @property
    def launchable(self) -> bool:
        """Registers x threads per block within the sm_90 register file."""
        return self.cubin_ok and self.registers * self.threads <= REGISTER_FILE

    def row(self) -> dict:
        d = asdict(self)
        d["launchable"] = self.launchable
        return d


# ---------------------------------------------------------------------------------------------- tools
def toolkit() -> Path:
    """ptxas of the CUDA 12 packages installed beside numba-cuda (which finds their NVVM itself); a missing NVVM
    or ptxas is named with the command that installs it."""
    try:
        import nvidia.cuda_nvcc as nvcc  # noqa: F401 - the CUDA 12 nvcc package carries NVVM and ptxas
    except ImportError:
        raise RuntimeError("the GPU build check needs NVVM and ptxas from the CUDA 12 packages: "
                           "pip install -e '.[gpu]'") from None
    root = Path(list(nvcc.__path__)[0])
    nvvm = next(iter(sorted((root / "nvvm" / "lib64").glob("libnvvm.so*"))), None)
    ptxas = root / "bin" / "ptxas"
    if nvvm is None or not ptxas.is_file():
        raise RuntimeError(f"no libnvvm or ptxas under {root}: pip install -e '.[gpu]'")
    return ptxas


def _simulator_on() -> bool:
    from numba import config

    return bool(config.ENABLE_CUDASIM)


# ---------------------------------------------------------------------------------------------- trace
class _FixedDevice:
    """What numba-cuda reads of the current device while it compiles: its compute capability."""

    compute_capability = CC


@contextlib.contextmanager
def _fixed_compute_capability():
    """Within: numba-cuda compiles device functions for :data:`CC` instead of asking a device for it."""
    from numba.cuda import dispatcher

    saved = dispatcher.get_current_device
    dispatcher.get_current_device = _FixedDevice
    try:
        yield
    finally:
        dispatcher.get_current_device = saved


@contextlib.contextmanager
def tracing():
    """Within: CUDA arrays are host stand-ins and each launch appends ``(kernel, threads, argtypes)`` to the
    yielded list instead of running; device functions compile for :data:`CC`."""
    if _simulator_on():
        raise RuntimeError("the GPU build check needs NUMBA_ENABLE_CUDASIM=0 in its own process")
    from numba import typeof

    launches = []

    def record(kernel, threads, args):
        launches.append((kernel, int(threads), tuple(typeof(a) for a in args)))

    saved = (jit._HOST_STAND_IN, launch._RECORDER)
    jit._HOST_STAND_IN, launch._RECORDER = True, record
    try:
        with _fixed_compute_capability():
            yield launches
    finally:
        jit._HOST_STAND_IN, launch._RECORDER = saved


# ---------------------------------------------------------------------------------------------- compile
_PTXAS = {
    "registers": re.compile(r"Used (\d+) registers"),
    "stack_bytes": re.compile(r"(\d+) bytes stack frame"),
    "spill_stores_bytes": re.compile(r"(\d+) bytes spill stores"),
    "spill_loads_bytes": re.compile(r"(\d+) bytes spill loads"),
}


def _is_float32(argtypes) -> bool:
    """Every float array argument is float32 (and there is one)."""
    from numba import types

    floats = [a.dtype for a in argtypes if isinstance(a, types.Array) and isinstance(a.dtype, types.Float)]
    return bool(floats) and all(d == types.float32 for d in floats)


def compile_kernel(kernel, threads: int, argtypes, ptxas: Path, keep: Path | None = None) -> KernelBuild:
    """Compile one kernel for :data:`CC`: PTX by NVVM, a cubin by ptxas; the figures ptxas reports."""
    from numba import cuda

    name = getattr(kernel, "kernel_name", kernel.py_func.__name__)
    out = KernelBuild(name=name, threads=threads, signature=", ".join(str(a) for a in argtypes),
                      float32=_is_float32(argtypes))
    t0 = time.perf_counter()
    opts = kernel.targetoptions
    try:
        with _fixed_compute_capability():
            ptx, _ = cuda.compile_ptx(kernel.py_func, argtypes, cc=CC, fastmath=bool(opts.get("fastmath")),
                                      opt=True, launch_bounds=opts.get("launch_bounds"))
    except Exception as exc:  # the compiler's own message is the finding
        out.error = f"{type(exc).__name__}: " + " ".join(str(exc).split())[:400]
        out.compile_seconds = time.perf_counter() - t0
        return out
    out.ptx_ok = True
    out.float64_ops = float64_ops(ptx)
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "kernel.ptx"
        src.write_text(ptx)
        res = subprocess.run([str(ptxas), f"-arch=sm_{CC[0]}{CC[1]}", "-v", str(src), "-o", str(src.with_suffix(
            ".cubin"))], capture_output=True, text=True)
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            shutil.copy(src, keep / f"{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}.ptx")
    out.compile_seconds = time.perf_counter() - t0
    if res.returncode != 0:
        out.error = "ptxas: " + " ".join(res.stderr.split())[:400]
        return out
    out.cubin_ok = True
    for key, pat in _PTXAS.items():
        m = pat.search(res.stderr)
        if m:
            setattr(out, key, int(m.group(1)))
    return out
