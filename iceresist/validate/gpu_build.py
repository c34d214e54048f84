"""GPU build check: every CUDA kernel the engine launches, compiled for a real device on any machine.

The CUDA simulator runs kernels as Python, so it passes code that the GPU compiler refuses (a float64 ``xor``
once stopped the DEM at its first sub-step on a real GPU). This check compiles what a real device would run:

1. **Trace.** A CI-sized scene of each tier, tier 2 on two levels, the built-in dam break, the refined channel, the
   free surface on two levels and the plain LBM step are built and stepped on the ``cuda`` target within
   :func:`iceresist.backends.buildcheck.tracing`: host arrays stand in for device arrays and every launch is
   recorded instead of run.
2. **Compile.** Each kernel, with the argument types of its launches, by
   :func:`iceresist.backends.buildcheck.compile_kernel`: PTX for sm_90 by NVVM, a cubin by ptxas.
3. **Judge.** A kernel builds when both steps succeed; it launches when registers x threads per block fit the
   sm_90 register file; a float32 kernel should hold no float64 arithmetic.

The check builds the models of both tiers, so it sits above them (the compiler side is in the backend layer).
It must run in a process of its own with ``NUMBA_ENABLE_CUDASIM=0``. Run it with
``python -m validation.bench gpu_build``.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from iceresist.backends import jit
from iceresist.backends.buildcheck import KernelBuild, compile_kernel, toolkit, tracing
from iceresist.freesurface.pool import PooledLBM
from iceresist.freesurface.refined import RefinedFreeSurface
from iceresist.grid import BlockForest
from iceresist.grid.forest import Face
from iceresist.grid.octree import BlockOctree
from iceresist.lbm.solver import LBMSolver
from iceresist.models import build_model
from iceresist.parallel.decomposition import SolverHalo
from iceresist.parallel.staging import DevicePlan
from iceresist.scene.case_scenes import case_scene
from iceresist.scene.load import load_scene
from iceresist.sweep import TINY_OVERRIDES, TINY_TIER2_AMR_OVERRIDES, TINY_TIER2_OVERRIDES

def check_scenes():
    """``{label: scene}``: the CI-sized tier-1 and tier-2 cases, tier 2 in both precisions, the built-in dam
    break (a free surface whose population pool follows the water: its wet and fill kernels) and the built-in
    refined channel (two levels: the level transfer kernel) and the smallest ship on two levels (tier 2 on levels:
    the coupling on the finest level, the ghost refill, the probe of the coarse level)."""
    t2 = {k: dict(v) for k, v in TINY_TIER2_OVERRIDES.items()}
    t2_64 = {**t2, "numerics": {**t2["numerics"], "precision": "float64"}}
    return {"tier1": case_scene("A-c68-v1.0", "quick", 1, **TINY_OVERRIDES),
            "tier2-float32": case_scene("A-c68-v1.0", "quick", 2, **t2),
            "tier2-float64": case_scene("A-c68-v1.0", "quick", 2, **t2_64),
            "dam_break": load_scene("dam_break"), "refined_channel": load_scene("refined_channel"),
            "refined_tier2-float32": case_scene("A-c68-v1.0", "quick", 2, **TINY_TIER2_AMR_OVERRIDES)}


def fluid_launches(precision: str):
    """Launches of the plain fused LBM step (the lbm benchmark's kernel) on a 16^3 periodic box, then of the step
    of an MPI rank (the blocks it sends updated before its messages go, the others while they travel; here with
    no messages)."""
    solver = LBMSolver(BlockForest.uniform((16, 16, 16)), tau=0.6, precision=precision, target=jit.cuda())
    solver.initialize()
    solver.step(1)
    n = solver.forest.nblocks
    solver.halo = SolverHalo(jit.cuda(), n, n, [0], start=lambda arr: None, finish=lambda pending: None)
    solver.step(1)
    halo_packing(solver.state, solver.flags)


def halo_packing(*arrays):
    """Launches of an MPI rank's halo packing on the device (:mod:`iceresist.parallel.staging`) for each of
    ``arrays`` (``[block, ..., 512]``): nine populations of one layer of block 1 sent and of block 0 received, then
    whole blocks."""
    for arr in arrays:
        k = min(9, arr.shape[1]) if arr.ndim == 3 else 1
        comps, cells = np.repeat(np.arange(k), 64), np.tile(np.arange(64), k)
        for entries in ((comps, cells), (None, None)):
            n = 1 if entries[0] is None else len(cells)
            plan = DevicePlan(jit.cuda(), arr.shape, arr.dtype, [(1, [0] * n, *entries)], [(1, [1] * n, *entries)])
            plan.pack_sends(arr)
            plan.unpack_recvs(arr)


def refined_surface_launches(precision: str):
    """Launches of one level-0 step of the free surface on two levels (:mod:`iceresist.freesurface.refined`: the
    ghost refill of the finest level, the liquid level's fused update, the level transfers) on a 16 x 16 x 32
    level-1 column."""
    faces = {k: Face("periodic") for k in ("x-", "x+", "y-", "y+")} | {"z-": Face("wall"), "z+": Face("wall")}
    tree = BlockOctree((1, 1, 2), 1, periodic=(True, True, False)).refine(
        lambda lo, hi: np.where(lo[:, 2] >= 8, 1, 0))
    m = RefinedFreeSurface(tree, tau0=0.55, gravity0=2e-4, depth0=12.0, mobility=0.01, width=3.0,
                           precision=precision, faces=faces, target=jit.cuda())
    m.initialize()
    m.step(1)


@contextlib.contextmanager
def _all_blocks_wet():
    """Traced kernels do not run, so no block ever turns wet and a population pool never fills a new row: within,
    the pool's wet-block scan (still traced) reports every block wet, so its fill kernel is traced too."""
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
    seen: dict = {}
    def run(scene, read: bool):
        model = build_model(scene, backend="cuda")
        with _all_blocks_wet():
            model.step(steps)
        if read:  # what the driver reads every record (the dam break's would divide by the untouched volume 0)
            model.diagnostics()
            model.watchdog_probe()

    jobs = [(label, lambda s=scene, r="tier" in label: run(s, r))
            for label, scene in check_scenes().items()]
    jobs += [(f"lbm-{p}", lambda p=p: fluid_launches(p)) for p in ("float32", "float64")]
    jobs += [("refined_surface-float32", lambda: refined_surface_launches("float32"))]
    for label, job in jobs:
        with tracing() as launches:
            job()
        for key in launches:
            seen.setdefault(key, [])
            if label not in seen[key]:
                seen[key].append(label)
    return seen


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
