"""The GPU build check (a GPU path that compiles for a real device): every CUDA kernel that tiers 1 and 2
launch, and the plain fused LBM step, compiled by numba-cuda's NVVM to PTX and by ptxas to an sm_90 cubin on
this machine, with no GPU. The CUDA simulator that the other tests use runs kernels as Python and cannot see what
the GPU compiler refuses, so the check runs in a process of its own with the simulator off."""

import json
import os
import subprocess
import sys

import pytest

from iceresist.backends.buildcheck import REGISTER_FILE, float64_ops

#: Kernels that must be in the check: each part of a tier-2 step and of tier 1 (LBM, free surface, coupling, DEM)
#: and the level transfer of block refinement.
EXPECTED = {
    "f_update", "h_stream", "h_collide", "h_init", "velocity", "reflag", "extension", "water_volume", "probe",
    "pool_wet", "pool_fill", "lbm_stream_collide", "block_phases", "block_phases_near",
    "mark", "links", "refill_fs", "redistribute_fs", "body_rows", "row_sums", "fluid_loads",
    "near_events", "fill",
    "dem_drift", "dem_place", "dem_contact", "dem_gather", "scan_buckets", "scatter", "level_transfer", "ghost_phase", "bulk_roles", "bulk_settle", "halo_pack", "halo_unpack",
}


def _real_device() -> bool:
    """A CUDA device this process runs kernels on (the simulator off)."""
    from numba import config, cuda

    return not config.ENABLE_CUDASIM and cuda.is_available()


def _toolkit_here() -> bool:
    """NVVM and ptxas of the `gpu` extra are installed."""
    from iceresist.backends.buildcheck import toolkit

    try:
        toolkit()
    except RuntimeError:
        return False
    return True


#: The build checks skip on a real GPU without the `gpu` extra (a GPU machine's image): the CUDA tests compile every
#: kernel for it instead.
needs_toolkit = pytest.mark.skipif(_real_device() and not _toolkit_here(),
                                reason="no `gpu` extra here, but a real GPU: the CUDA tests compile every kernel")


#: The tests of one build share it: kept in one test process (each process would build it again, 150 s each).
pytestmark = pytest.mark.xdist_group("gpu_build")


@pytest.fixture(scope="session")
def builds():
    """One run of ``python -m validation.bench gpu_build --json`` (about 3 min on a 2-core x86 VM), once per test
    process: a module's fixture is built again wherever the process runs another module's tests between this
    module's (pytest-xdist's groups keep the tests in one process, not in one run of them)."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    res = subprocess.run([sys.executable, "-m", "validation.bench", "gpu_build", "--json"], capture_output=True,
                         text=True, env=env, timeout=1200)
    rows = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    assert rows, res.stderr[-3000:]
    return rows, res.returncode


@needs_toolkit
def test_every_kernel_is_traced(builds):
    rows, _ = builds
    names = {r["name"] for r in rows}
    assert EXPECTED <= names, sorted(EXPECTED - names)
    scenes = {s for r in rows for s in r["scenes"].split(",")}
    assert {"tier1", "tier2-float32", "tier2-float64", "lbm-float32", "lbm-float64", "refined_channel",
            "refined_surface-float32", "refined_tier2-float32"} <= scenes


@needs_toolkit
def test_every_kernel_compiles_for_sm90_and_launches(builds):
    rows, status = builds
    bad = [(r["name"], r["scenes"], r["error"] or f"{r['registers']} registers x {r['threads']} threads")
           for r in rows if not r["launchable"]]
    assert not bad, bad
    assert status == 0
    for r in rows:
        assert 0 < r["registers"] <= 255 and r["registers"] * r["threads"] <= REGISTER_FILE


@needs_toolkit
def test_float32_kernels_compute_in_float32(builds):
    """A bare int64 lattice constant times a float32 value promotes the product to float64 (half-rate or worse on
    a GPU): the float32 kernels of the tier-2 step hold no float64 instruction."""
    rows, _ = builds
    f64 = [(r["name"], r["float64_ops"]) for r in rows if r["float32"] and r["float64_ops"]]
    assert not f64, f64


@needs_toolkit
def test_fused_f_update_does_not_spill(builds):
    rows, _ = builds
    fused = [r for r in rows if r["name"] == "f_update"]
    assert {s for r in fused for s in r["scenes"].split(",")} >= {"tier2-float32", "tier2-float64"}
    assert all(r["spill_stores_bytes"] == 0 and r["spill_loads_bytes"] == 0 for r in fused), fused


def test_float64_ops_counts_arithmetic_not_data_movement():
    ptx = """
    ld.global.f64 %fd1, [%rd1];
    st.global.f64 [%rd2], %fd1;
    add.rn.f32 %f1, %f2, %f3;
    fma.rn.f64 %fd2, %fd1, %fd1, %fd1;
    cvt.f64.f32 %fd3, %f1;
    cvt.rn.f32.f64 %f4, %fd3;
    @%p1 mul.f64 %fd4, %fd2, %fd3;
    setp.lt.f64 %p2, %fd4, %fd1;
    """
    assert float64_ops(ptx) == 5


#: Copies between host and device over two records (the model's step: several coupled LBM steps and the mean loads
#: on the hull) of the CI-sized tier-2 case on the ``cuda`` target, traced (kernels recorded, not run; the first
#: record, with the set-up, is not counted); prints ``{"records", "lbm_steps", "counts", "sites"}`` as JSON.
RECORD_TRANSFERS = """
import json
from iceresist.backends import transfers
from iceresist.backends.buildcheck import tracing
from iceresist.validate.gpu_build import check_scenes
from iceresist.models import build_model

records = 2
with tracing():
    model = build_model(check_scenes()["tier2-float32"], backend="cuda")
    model.step(1)
    with transfers.counting() as tally:
        model.step(records)
print(json.dumps({"records": records, "lbm_steps": records * model.lbm_steps_per_record,
                  "counts": dict(tally.counts), "sites": str(tally)}))
"""


def test_a_tier2_record_reads_its_mean_loads_and_copies_nothing_else():
    """Two records (4 coupled LBM steps each) of the CI-sized tier-2 case on the cuda target, traced in a process of
    its own: no upload and no host array handed to a kernel; per record at most three small reads (the mean ice
    and fluid loads summed on the device, and the ice force at the end of the model's step), none per LBM step."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    res = subprocess.run([sys.executable, "-c", RECORD_TRANSFERS], capture_output=True, text=True, env=env,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["lbm_steps"] >= 2 * out["records"]
    assert set(out["counts"]) <= {"download"}, out["sites"]
    assert out["counts"].get("download", 0) <= 3 * out["records"], out["sites"]


#: The same over two records of the smallest ship on two levels (``NAME = "refined_tier2"``), each record with its
#: diagnostics and a regrid check (``refinement.regrid_every_steps`` 4 of its 6 level-0 steps), or of the built-in
#: free surface on two levels (``"refined_tank"``); prints also the bytes of one float32 field of the finest level.
REFINED_RECORD_TRANSFERS = """
import json
from iceresist.backends import transfers
from iceresist.backends.buildcheck import tracing
from iceresist.validate.gpu_build import check_scenes
from iceresist.models import build_model
from iceresist.scene.load import load_scene

SCENE = {"refined_tier2": check_scenes()["refined_tier2-float32"], "refined_tank": load_scene("refined_tank")}[NAME]
records = 2
with tracing():
    model = build_model(SCENE, backend="cuda")
    model.step(1)
    model.diagnostics()
    checks, regrid = [], model.regrid
    model.regrid = lambda: checks.append(1) or regrid()
    with transfers.counting() as tally:
        for _ in range(records):
            model.step(1)
            model.diagnostics()
print(json.dumps({"records": records, "checks": len(checks), "counts": dict(tally.counts),
                  "largest": dict(tally.largest), "field_bytes": int(model.fs.surface.phase.phi.nbytes),
                  "sites": str(tally)}))
"""


@pytest.mark.parametrize("name", ["refined_tier2", "refined_tank"])
def test_a_record_on_levels_reads_no_whole_field(name):
    """Two records of tier 2 on two levels (the smallest ship) and two steps of the built-in free surface on two
    levels, on the cuda target, traced in a process of its own, each with its diagnostics (the ship's with a regrid
    check): no upload and no host array handed to a kernel; what is read is per body or per block (the mean loads,
    the probe's rows, the surface map, the blocks the surface reaches, the volume per block), never a field of the
    finest level's cells. Planted: the regrid reading phi of every leaf cell again (the host's test of the reach)
    fails the ship; the records of the tank from the leaf fields (as before) fail the tank."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    res = subprocess.run([sys.executable, "-c", f"NAME = {name!r}\n" + REFINED_RECORD_TRANSFERS], capture_output=True,
                         text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["checks"] >= (out["records"] if name == "refined_tier2" else 0)
    assert set(out["counts"]) <= {"download"}, out["sites"]
    assert out["largest"]["download"] < out["field_bytes"] // 4, out["sites"]
