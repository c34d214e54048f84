"""The tier-2 ship case of ``iceresist validate`` follows the case protocol (iceresist/validate/result.py): a ladder
of at least three cell sizes in one physical tank, whole 8x8x8 blocks, the same record interval on every rung, and
one run of the cheapest rung that gives a finite mean ice force with its lattice cells and LBM steps."""

import math

import numpy as np
import pytest

from iceresist.scene.case_scenes import case_scene
from iceresist.validate.cases import ship_tier2
from iceresist.validate.ladder import discover_cases
from iceresist.validate.result import CaseResult


@pytest.mark.parametrize("quick", [True, False])
def test_ladder_refines_the_cell_in_one_tank(quick):
    rungs = ship_tier2.ladder(quick)
    assert len(rungs) >= 3
    assert all(isinstance(p["label"], str) and p["label"] for p in rungs)
    assert len({p["label"] for p in rungs}) == len(rungs)
    res = [p["resolution"] for p in rungs]
    assert np.all(np.diff(res) > 0)  # coarse to fine
    tanks, intervals, steps = [], [], []
    for p in rungs:
        ov = ship_tier2.overrides(p)
        cells, dx = ov["domain"]["cells"], ov["domain"]["dx_m"]
        assert all(c % 8 == 0 for c in cells)
        assert p["resolution"] == pytest.approx(ship_tier2.CUBE_M / dx, rel=1e-12)  # cells per 41 mm cube
        tanks.append([c * dx for c in cells])
        scene = case_scene(ship_tier2.CASE, "quick", 2, **ov)
        lbm_dt = scene.units().dt_s
        n = max(1, int(math.ceil(scene.contact.sample_interval_s / lbm_dt - 1e-9)))  # rule of Tier2Model
        steps.append(n)
        intervals.append(n * lbm_dt)
    np.testing.assert_allclose(tanks, [tanks[0]] * len(tanks), rtol=1e-12)
    np.testing.assert_allclose(intervals, intervals[0], rtol=1e-9)
    first = ship_tier2.STEPS_PER_RECORD_COARSEST[quick]
    assert steps == [round(first * r / res[0]) for r in res]


def test_quick_ladder_is_the_ci_sized_tank():
    from iceresist.sweep import TINY_TIER2_OVERRIDES

    p = ship_tier2.ladder(True)[0]
    assert p["cells"] == TINY_TIER2_OVERRIDES["domain"]["cells"]
    assert p["dx_m"] == pytest.approx(TINY_TIER2_OVERRIDES["domain"]["dx_m"], rel=1e-12)


def test_case_is_discovered():
    available, missing = discover_cases()
    assert "ship_tier2" in available and "ship_tier2" not in missing


def test_cheapest_rung_runs():
    """About 45 s on a 2-core x86 VM, most of it the compilation of the warm-up (less after tests/test_tier2.py)."""
    p = ship_tier2.ladder(True)[0]
    r = ship_tier2.run(p, backend="cpu")
    assert isinstance(r, CaseResult) and r.case == "ship_tier2" and r.label == p["label"]
    assert r.cells == 64 * 16 * 16
    assert r.steps == 13 * 4  # 0.06 s in records of 4 LBM steps
    assert math.isfinite(r.value) and r.value > 0  # the hull meets the middle cube (tests/test_tier2.py)
    assert math.isnan(r.reference) and r.wall_s > 0
    assert math.isfinite(r.extra["mean_fluid_Fx_N"]) and r.extra["mean_fluid_Fx_N"] < 0  # the water resists
    assert r.extra["compile_s"] >= 0 and r.extra["total_s"] >= r.wall_s


def test_a_rung_of_several_ice_seeds_pools_their_windows_and_reads_finished_runs_back(tmp_path, caplog):
    """The cheapest quick rung from two random ice arrangements (seeds 0 and 1, ``run_rung(seeds=...)``, as the
    ladder on levels runs each rung): a run per seed in its own folder, the arrangements differ, the rung's value
    and interval are the pooled batch means of the two windows (:func:`iceresist.post.case.analyse_ensemble`), the
    records and steps of both counted; run again, the finished runs are read back (not run: their files unchanged)
    and give the same result."""
    from iceresist.io.hdf5 import RunFile
    from iceresist.post.case import analyse_ensemble

    p = ship_tier2.ladder(True)[0]
    ov = ship_tier2.overrides(p)
    ov["ice"] = {**ov.get("ice", {}), "arrangement": "random"}
    r = ship_tier2.run_rung("ship_tier2", p, ov, backend="cpu", precision="float32", out_dir=tmp_path, seeds=(0, 1))
    folder = tmp_path / "runs" / "ship_tier2"
    paths = sorted(folder.glob("*/seed-*/cases/A-c68-v1.0.h5"))
    assert [q.parent.parent.name for q in paths] == ["seed-0", "seed-1"]
    starts = []
    for q in paths:
        with RunFile(q, "r") as rf:
            starts.append(np.asarray(rf.h5["bodies/initial_positions_m"]))
    assert starts[0].shape == starts[1].shape and np.abs(starts[0] - starts[1]).max() > 1e-4
    ens = analyse_ensemble(paths)
    assert r.value == ens["mean_force_N"] and r.extra["ci95_N"] == ens["ci95_N"] > 0
    assert r.extra["seeds"] == 2 and r.extra["run_means_N"].split() == [f"{v:.4g}" for v in ens["run_means_N"]]
    assert r.steps == 2 * 13 * 4 and r.extra["records"] == 2 * 13
    stamps = [q.stat().st_mtime_ns for q in paths]
    caplog.set_level("INFO", logger="iceresist.sweep")
    again = ship_tier2.run_rung("ship_tier2", p, ov, backend="cpu", precision="float32", out_dir=tmp_path,
                                seeds=(0, 1))
    assert [q.stat().st_mtime_ns for q in paths] == stamps
    assert sum("read back" in rec.getMessage() for rec in caplog.records) == 2
    assert again.value == r.value and again.extra["ci95_N"] == r.extra["ci95_N"]
