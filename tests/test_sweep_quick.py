"""The quick sweeps of all six cases reproduce the paper's trends (minutes for tier 1, hours for tier 2 on a
2-core CPU: marked slow)."""

import pytest

from iceresist.post.trends import ORDER_OF_MAGNITUDE, fsicr_order, paper_trends
from iceresist.sweep import run_sweep


def assert_paper_trends(t, fsicr_factor=3.0):
    # rises with concentration (Bow A, 1 knot) and with speed (Bow A, 68 %); the steeper Bow B above Bow A
    for check in paper_trends(t):
        assert check.holds, f"{check.name}: {check.values()}"
    # full scale of the order of FSICR R_CH (within fsicr_factor either way)
    ok, lo, hi = fsicr_order(t, fsicr_factor)
    assert ok, f"simulated / FSICR from {lo:.2f} to {hi:.2f}"


@pytest.mark.slow
def test_quick_sweep_trends(tmp_path):
    assert_paper_trends(run_sweep("quick", 1, tmp_path, None, backend="cpu"))


@pytest.mark.slow
def test_quick_tier2_sweep_trends(tmp_path):
    """About 9 h on the 2-core VM (six cases of 1-2.5 h on 2 threads in the 0.9 m tank); minutes on a GPU.

    The FSICR bound is the issue's "same order" (a factor of ten), against the 3 x bound that tier 1 meets (the
    paper: 0.64, 0.93). The concentration, speed and bow trends hold on the quick tier-2 grid, but its 50 % case
    gives 0.06 x FSICR, under the bound, so this test fails there: the grid (3.1 cells per cube) is not
    converged (docs/SHIP.md, "Why the quick tier 2 is low"). It waits for a finer grid at 50 % (block AMR)."""
    assert_paper_trends(run_sweep("quick", 2, tmp_path, None), fsicr_factor=ORDER_OF_MAGNITUDE)
