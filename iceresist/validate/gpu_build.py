"""GPU build check: every CUDA kernel the engine launches, compiled for a real device on any machine.

The CUDA simulator runs kernels as Python, so it passes code that the GPU compiler refuses (a float64 ``xor``
once stopped the DEM at its first sub-step on a real GPU). This check compiles what a real device would run:

1. **Trace.** A CI-sized scene of each tier is built and stepped on the ``cuda`` target with host arrays standing
   in for device arrays (:class:`~iceresist.backends.jit.HostStandIn`) and every launch recorded instead of run
   (:func:`~iceresist.backends.launch.cuda_launch`; launches of no items are recorded too). No GPU and no CUDA
   driver are needed; what the kernels would have computed is never looked at.
2. **Compile.** Each kernel, with the argument types of its launches, goes through numba-cuda's NVVM to PTX for
   compute capability :data:`CC` (numba-cuda asks the current device for it when it compiles a device function;
   without a GPU the check answers for it), then through ``ptxas -arch=sm_90 -v`` to a cubin, which reports
   registers, stack and spill bytes.
3. **Judge.** A kernel builds when both steps succeed; it launches when registers x threads per block fit the
   sm_90 register file (:data:`REGISTER_FILE`); a float32 kernel (every float array it takes is float32) should
   hold no float64 arithmetic (:func:`float64_ops` counts it in the PTX).

NVVM and ptxas come from the CUDA 12 packages on the package index (the ``gpu`` extra of ``pyproject.toml``).
The check must run in a process of its own with ``NUMBA_ENABLE_CUDASIM=0``: the simulator replaces
``numba.cuda`` when numba is first imported. Run it with ``python -m validation.bench gpu_build``.
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

import numpy as np

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


def check_scenes():
    """``{label: scene}``: the CI-sized tier-1 and tier-2 cases, tier 2 in both precisions, and the built-in dam
    break (a free surface whose population pool follows the water: its wet and fill kernels)."""
    from iceresist.scene.load import load_scene
    from iceresist.ship.presets import case_scene
    from iceresist.sweep import TINY_OVERRIDES, TINY_TIER2_OVERRIDES

    t2 = {k: dict(v) for k, v in TINY_TIER2_OVERRIDES.items()}
    t2_64 = {**t2, "numerics": {**t2["numerics"], "precision": "float64"}}
    return {"tier1": case_scene("A-c68-v1.0", "quick", 1, **TINY_OVERRIDES),
            "tier2-float32": case_scene("A-c68-v1.0", "quick", 2, **t2),
            "tier2-float64": case_scene("A-c68-v1.0", "quick", 2, **t2_64),
            "dam_break": load_scene("dam_break")}


def fluid_launches(precision: str):
    """Launches of the plain fused LBM step (the lbm benchmark's kernel) on a 16^3 periodic box."""
    from iceresist.grid import BlockForest
    from iceresist.lbm.solver import LBMSolver

    solver = LBMSolver(BlockForest.uniform((16, 16, 16)), tau=0.6, precision=precision, target=jit.cuda())
    solver.initialize()
    solver.step(1)


@contextlib.contextmanager
def _all_blocks_wet():
    """Traced kernels do not run, so no block ever turns wet and a population pool never fills a new row: within,
    the pool's wet-block scan (still traced) reports every block wet, so its fill kernel is traced too."""
    from iceresist.freesurface.pool import PooledLBM

    scan = PooledLBM.wet_blocks

    def wet_blocks(self, phi):
        return np.ones_like(scan(self, phi))

    PooledLBM.wet_blocks = wet_blocks
    try:
        yield
    finally:
        PooledLBM.wet_blocks = scan


def trace(steps: int = 2) -> dict:
    """``{(kernel, threads, argtypes): [scene labels]}`` over :func:`check_scenes` and the plain LBM step."""
    from iceresist.models import build_model

    seen: dict = {}
    def run(scene, read: bool):
        model = build_model(scene, backend="cuda")
        with _all_blocks_wet():
            model.step(steps)
        if read:  # what the driver reads every record (the dam break's would divide by the untouched volume 0)
            model.diagnostics()
            model.watchdog_probe()

    jobs = [(label, lambda s=scene, r=label.startswith("tier"): run(s, r))
            for label, scene in check_scenes().items()]
    jobs += [(f"lbm-{p}", lambda p=p: fluid_launches(p)) for p in ("float32", "float64")]
    for label, job in jobs:
        with tracing() as launches:
            job()
        for key in launches:
            seen.setdefault(key, [])
            if label not in seen[key]:
                seen[key].append(label)
    return seen


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


def run_check(keep: Path | None = None, progress=None) -> list[KernelBuild]:
    """Trace, then compile every kernel and signature seen; one :class:`KernelBuild` each, in launch order."""
    ptxas = toolkit()
    seen = trace()
    builds = []
    items = list(seen.items())
    for i, ((kernel, threads, argtypes), scenes) in enumerate(items):
        b = compile_kernel(kernel, threads, argtypes, ptxas, keep)
        b.scenes = scenes
        builds.append(b)
        if progress is not None:
            progress(i + 1, len(items), b)
    return builds
