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
    paper: 0.64, 0.93). In the 0.9 m tank the cases run so far give 0.06 (50 %), 0.16 (68 %), 0.25 (88 %),
    0.78 (2 knots) and 0.19 (Bow B) x FSICR (docs/SHIP.md): the concentration, speed and bow trends hold, but
    the 50 % case is under the bound, so this test fails on the present quick tank. The water there does not
    stay level (at 2 knots it piles up against the fore wall, at 1 knot it sloshes; docs/SHIP.md, "2 knots
    again in the sweep, and the water level"), but in the 1-knot windows the ice drifts towards the bow. The
    short channel is not the cause: on a channel twice as long (validation/scenes/quick_t2_long_channel.toml)
    the 68 % tier-2 force settles 0.5 m into the window at 3-7 N and gives 4.25 N, 0.23 x FSICR, against tier
    1's 12.4 N there (docs/SHIP.md, "The long channel at tier 2"); scaled alike the 50 % case would reach only
    about 0.09 x. The quick tier 2 is not grid-converged at 68 and 88 % (on 2.1 cells per cube instead of 3.1
    the force is 0.3-0.4 x), but the 50 % case is the same on both grids and with the viscosity of water. In the
    paper's depth (1.11 m of water instead of 0.9 m) it is 2.6 x, 0.15 x FSICR, on the coarse grid, but on the
    preset's grid it stays at 0.95 N, 0.05 x (docs/SHIP.md, "The paper's depth on the quick grid"). Nor is it a thin
    sample that another run would lift: with the cubes jittered off their rows the coarse 50 % force falls 2.5-4 x,
    three seeds alike, while tier 1 moves under 3 % ("The ice arrangement at 50 %"). So this test waits for a finer
    grid or a longer channel at 50 % (about 3.2 h each alone on this VM, or a GPU). A partial run on 4 cells per
    cube (validation/scenes/quick_t2_fine_c50.toml, lost at record 531 of 679) gave about 2.1 N, 0.11 x, over the
    first 0.47 m of the window ("The ice arrangement at 50 %")."""
    assert_paper_trends(run_sweep("quick", 2, tmp_path, None), fsicr_factor=ORDER_OF_MAGNITUDE)
