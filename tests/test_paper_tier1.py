"""Tier 1 against the paper's table 2 (Bow A 188 kN, Bow B 330 kN at 68 %, 1 knot; Watanabe, Hu and Aoki 2023).

The quick preset's 1.39 m channel ends before the force settles (docs/SHIP.md, "Where tier 1 settles"), so the CI
check runs the quick cubes on a 2.78 m channel (about 1 min on a 2-core x86 VM); the paper preset itself (5.56 m
channel, 3 136 cubes, about 18 min a case) is slow."""

import pytest

from iceresist.post.case import analyse_case
from iceresist.sweep import run_case, run_sweep

#: The paper's table 2, full scale [kN].
PAPER_KN = {"A-c68-v1.0": 188.0, "B-c68-v1.0": 330.0}


def test_long_channel_tier1_68_percent_meets_the_papers_188_kN(tmp_path):
    """Quick cubes (2 x 2 x 2 spheres), A-c68-v1.0 on a 2.78 m channel to t = 5.506 s: measured 11.80 +- 2.64 N,
    184 kN (-2 %; the face dashpot, 2-core x86 VM, 2026-12-07; with the sphere-pair dashpot it ran away at t = 4.55 s
    on this VM). Tolerance 30 % of 188 kN: the run's own 95 % interval is +-22 % of its
    mean, and a change of the floating-point order draws another sample of the same chaotic run. Planted: the tier-1
    water drag x4 gives 29.8 +- 7.1 N, 465 kN (fails)."""
    path = run_case("A-c68-v1.0", "quick", 1, tmp_path, backend="cpu",
                    overrides={"ice": {"channel_length_m": 2.78}, "run": {"end_time_s": 5.506}})
    row = analyse_case(path)
    assert row["R_sim_kN"] == pytest.approx(PAPER_KN["A-c68-v1.0"], rel=0.30), row
    assert row["ci95_N"] < 0.3 * row["mean_force_N"]


@pytest.mark.slow   # about 36 min on a 2-core x86 VM
def test_paper_preset_tier1_runs_and_meets_table_2(tmp_path):
    """The paper preset runs to the end (it ran away at t = 3.31 s with the DEM sub-step at 0.2 of the critical
    step; docs/SHIP.md, "Tier 1: the paper preset"). Measured with the face dashpot: A 12.22 +- 0.31 N = 191 kN
    (+2 %), B 23.74 +- 3.08 N = 371 kN (+12 %) (the sphere-pair dashpot gave 199 and 409 kN). Asserted: Bow A within 15 % of 188 kN, Bow B within 30 % of 330 kN, Bow B above Bow A."""
    table = run_sweep("paper", 1, tmp_path, list(PAPER_KN), backend="cpu").set_index("case")
    assert table.loc["A-c68-v1.0", "R_sim_kN"] == pytest.approx(PAPER_KN["A-c68-v1.0"], rel=0.15)
    assert table.loc["B-c68-v1.0", "R_sim_kN"] == pytest.approx(PAPER_KN["B-c68-v1.0"], rel=0.30)
    assert table.loc["B-c68-v1.0", "mean_force_N"] > table.loc["A-c68-v1.0", "mean_force_N"]
