"""Tank blockage and Schijf's limiting speed (iceresist.ship.tank): the closed form against the defining equation
and its limits, and every tier-2 preset case below the limit of its tank."""

import math

import pytest

from iceresist.errors import InputError
from iceresist.ship.presets import TIER2, case_names, case_scene
from iceresist.ship.tank import blockage_ratio, depth_froude, schijf_limit_froude, tank_flow
from iceresist.tier1 import hull_geometry


@pytest.mark.parametrize("m", [0.0, 0.05, 0.2, 0.25, 0.4, 0.7, 0.95])
def test_schijf_limit_solves_the_one_dimensional_channel_equation(m):
    """1 - m + F^2/2 - (3/2) F^(2/3) = 0 at F_L, F_L in (0, 1], and F_L falls as the blockage grows."""
    f = schijf_limit_froude(m)
    assert 0.0 < f <= 1.0
    assert 1.0 - m + 0.5 * f * f - 1.5 * f ** (2.0 / 3.0) == pytest.approx(0.0, abs=1e-12)
    assert schijf_limit_froude(m + 0.01) < f


def test_schijf_limit_ends():
    """Open water: the critical speed sqrt(g h) (F = 1); a fully blocked tank: no steady speed."""
    assert schijf_limit_froude(0.0) == pytest.approx(1.0, abs=1e-12)
    assert schijf_limit_froude(1.0) == 0.0
    with pytest.raises(InputError, match="blockage"):
        schijf_limit_froude(-0.1)
    with pytest.raises(InputError, match="water depth"):
        blockage_ratio(0.3, 1.39, 0.0)


def test_papers_tank_is_subcritical_at_two_knots():
    """The paper's tank: m = 0.7 x 0.44 / (1.39 x 1.11) = 0.200, F_h = 1.028 / sqrt(9.81 x 1.11) = 0.312."""
    t = tank_flow(0.7 * 0.44, 1.39, 1.11, 2 * 0.514)
    assert t.blockage == pytest.approx(0.1996, abs=1e-4)
    assert t.depth_froude == pytest.approx(1.028 / math.sqrt(9.81 * 1.11), rel=1e-12)
    assert t.limit_froude == pytest.approx(0.475, abs=2e-3)
    assert t.subcritical and t.fraction_of_limit == pytest.approx(0.657, abs=3e-3)
    assert depth_froude(9.81 ** 0.5, 1.0) == pytest.approx(1.0)


def test_shallow_tank_of_the_first_quick_tier2_preset_was_past_the_limit():
    """0.56 m of water: m = 0.40, F_L = 0.28; 1 knot below it, 1.5 and 2 knots above."""
    flows = [tank_flow(0.7 * 0.44, 1.39, 0.56, k * 0.514) for k in (1.0, 1.5, 2.0)]
    assert flows[0].limit_froude == pytest.approx(0.281, abs=2e-3)
    assert [f.subcritical for f in flows] == [True, False, False]


@pytest.mark.parametrize("fidelity", sorted(TIER2))
def test_every_tier2_preset_case_runs_below_the_tanks_limiting_speed(fidelity):
    """Each case of the tier-2 presets at most 0.85 of Schijf's limit (a steady flow past the hull exists)."""
    for name in case_names():
        s = case_scene(name, fidelity, 2)
        g = hull_geometry(s)
        width_m = s.shape_cells()[1] * s.domain.dx_m
        t = tank_flow(g.midship_area_m2, width_m, s.free_surface.water_depth_m, s.ship.speed_m_s)
        assert t.fraction_of_limit < 0.85, (name, t)
