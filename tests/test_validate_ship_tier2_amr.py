"""The tier-2 ship ladder on refined levels (``ship_tier2_amr`` of ``iceresist validate``): four rungs at 3, 4.5, 6
and 9 cells per cube on the finest level in one tank of whole level-0 blocks, the same record interval on every rung,
counted without building (:meth:`Tier2Model.plan`); the cheapest rung run whole (slow)."""

import math

import numpy as np
import pytest

from iceresist.models.tier2 import Tier2Model
from iceresist.validate.cases import ship_tier2_amr as L
from iceresist.validate.ladder import discover_cases
from iceresist.validate.result import CaseResult


def test_the_full_ladder_refines_the_finest_level_in_one_tank():
    rungs = L.ladder(False)
    assert [p["resolution"] for p in rungs] == [3.0, 4.5, 6.0, 9.0]
    assert L.ladder(True) == []          # a GPU ladder: nothing on the quick one
    tanks, intervals, steps = [], [], []
    for p in rungs:
        scene = L.scene(p)
        assert scene.ice.arrangement == "random" and scene.ice.seed == 0     # each seed of L.SEEDS a run
        cells, dx = scene.domain.shape_cells(), scene.domain.dx_m
        assert all(c % 8 == 0 for c in cells)                              # whole level-0 blocks
        assert L.CUBE_M / (dx / 2 ** scene.refinement.levels) == pytest.approx(p["resolution"], rel=1e-12)
        tanks.append([cells[0] * dx, cells[1] * dx])
        lid = cells[2] * dx
        assert lid >= L.WATER_DEPTH_M + 0.03 > lid - 8 * dx    # the first block face 30 mm above the water
        assert scene.refinement.surface_band_m >= 8 * dx / 2 - 1e-12
        assert scene.refinement.body_band_m >= 2.5 * dx / 2 - 1e-12
        dt = scene.units().dt_s
        n = max(1, int(math.ceil(scene.contact.sample_interval_s / dt - 1e-9)))   # the model's rule
        steps.append(n)
        intervals.append(n * dt)
    np.testing.assert_allclose(tanks, [[128 * L.CUBE_M, 32 * L.CUBE_M]] * 4, rtol=1e-12)
    np.testing.assert_allclose(intervals, intervals[0], rtol=1e-9)
    assert steps == [2, 3, 4, 6]


@pytest.mark.parametrize("index, leaves", [(0, 1.64e6), (1, 4.79e6)])
def test_a_rung_starts_with_the_surface_and_the_bodies_on_the_finest_level(index, leaves):
    """The plan of the two cheapest rungs (a second each): the finest level at the rung's cells per cube; the leaf
    cell counts are regression pins of the measured plans (2-core x86 VM, 2026-11-28; rung 6: 9.03e6, rung 9:
    3.26e7)."""
    p = L.ladder(False)[index]
    plan = Tier2Model.plan(L.scene(p))
    assert plan["cells_per_cube"] == pytest.approx(p["resolution"], rel=1e-12)
    assert sorted(plan["cells_per_level"]) == [0, 1]
    assert sum(plan["cells_per_level"].values()) == pytest.approx(leaves, rel=0.01)


def test_the_case_is_discovered():
    available, missing = discover_cases()
    assert "ship_tier2_amr" in available and "ship_tier2_amr" not in missing


@pytest.mark.slow
def test_the_cheapest_rung_runs_whole():
    """The 3 cells per cube rung (1.6e6 leaf cells, 1548 level-0 steps a run), whole, on the CPU: a run per ice
    seed (five, about 20 min each with two threads on a 2-core x86 VM), the interval from ten batches or more."""
    p = L.ladder(False)[0]
    r = L.run(p, backend="cpu")
    assert isinstance(r, CaseResult) and r.case == "ship_tier2_amr" and r.label == p["label"]
    assert r.steps == 1548 * len(L.SEEDS) and math.isfinite(r.value) and r.value > 0
    assert r.extra["seeds"] == len(L.SEEDS) and r.extra["n_batches"] >= 10 and 0 < r.extra["ci95_N"] < r.value
