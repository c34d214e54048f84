"""The quick tier-1 sweep of all six cases reproduces the paper's trends (minutes: marked slow)."""

import pytest

from iceresist.sweep import run_sweep


@pytest.mark.slow
def test_quick_sweep_trends(tmp_path):
    t = run_sweep("quick", 1, tmp_path, None, backend="cpu").set_index("case")
    R = t.mean_force_N
    # rises with concentration (Bow A, 1 knot) and with speed (Bow A, 68 %)
    assert R["A-c50-v1.0"] < R["A-c68-v1.0"] < R["A-c88-v1.0"]
    assert R["A-c68-v1.0"] < R["A-c68-v1.5"] < R["A-c68-v2.0"]
    # the steeper bow B above bow A
    assert R["B-c68-v1.0"] > R["A-c68-v1.0"]
    # full scale of the order of FSICR R_CH (within a factor of 3 either way)
    ratio = t.ratio_sim_FSICR
    assert ((ratio > 1 / 3) & (ratio < 3)).all()
