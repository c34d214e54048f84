"""Tank blockage and Schijf's limiting speed (iceresist.ship.tank): the closed form against the defining equation
and its limits, and every tier-2 preset case below the limit of its tank. The start wave of an impulsive start:
by hand, against continuity, the hull's source spacing against its measured sections, and the tier-2 presets'
steady windows against it."""

import math

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.ship.hull import b063_hull
from iceresist.scene.case_scenes import TIER2, case_names, case_scene
from iceresist.ship.tank import blockage_ratio, depth_froude, schijf_limit_froude, start_wave, tank_flow
from iceresist.ship.from_scene import hull_geometry, ice_layout, start_wave_of_scene


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


# -- the start wave (linear long waves, iceresist.ship.tank.start_wave) --------------------------------------------

QUICK_TANK = {"midship_area_m2": 0.7 * 0.44, "width_m": 1.39, "depth_m": 0.9}


def test_start_wave_of_the_quick_tank_at_one_knot_by_hand():
    """c = sqrt(9.81 x 0.9) = 2.97136 m/s; eta = 0.514 x 0.308 / (2 x 1.39 x 2.97136) = 19.17 mm;
    u = m U / 2 = 0.2462 x 0.514 / 2 = 63.27 mm/s; t_s = 1.8332 / (2.97136 - 0.514) = 0.7460 s."""
    w = start_wave(**QUICK_TANK, speed_m_s=0.514, source_spacing_m=1.8332)
    assert w.level_m == pytest.approx(0.019165, rel=1e-4)
    assert w.drift_m_s == pytest.approx(0.063273, rel=1e-4)
    assert w.duration_s == pytest.approx(0.74600, rel=1e-4)
    assert w.run_up_m == pytest.approx(0.514 * 0.74600, rel=1e-4)


@pytest.mark.parametrize("speed", [0.514, 0.771, 1.028])
def test_start_wave_carries_half_the_bows_flux(speed):
    """Continuity of the forward wave: the flux it carries, u h W, and the rate its front adds water, eta c W,
    both equal half the bow's displacement flux U A_s / 2."""
    w = start_wave(**QUICK_TANK, speed_m_s=speed, source_spacing_m=1.8)
    half_flux = 0.5 * speed * QUICK_TANK["midship_area_m2"]
    c = math.sqrt(9.81 * QUICK_TANK["depth_m"])
    assert w.drift_m_s * QUICK_TANK["depth_m"] * QUICK_TANK["width_m"] == pytest.approx(half_flux, rel=1e-12)
    assert w.level_m * c * QUICK_TANK["width_m"] == pytest.approx(half_flux, rel=1e-12)


def test_start_wave_window_fraction_and_warning():
    w = start_wave(**QUICK_TANK, speed_m_s=1.028, source_spacing_m=1.8332)  # t_s = 0.944 s
    assert w.window_fraction(0.5, 1.5) == pytest.approx((w.duration_s - 0.5) / 1.0)
    assert w.window_fraction(1.0, 2.0) == 0.0 and w.warning(1.0, 2.0) is None
    assert w.window_fraction(0.1, 0.2) == 1.0
    assert w.window_fraction(math.inf, math.inf) == 0.0  # a ship at rest
    text = w.warning(0.64, 1.40)
    assert "\n" not in text and "0.94 s" in text and "ship.start_x_m" in text and "40 %" in text
    with pytest.raises(InputError, match="source spacing"):
        start_wave(**QUICK_TANK, speed_m_s=0.5, source_spacing_m=0.0)
    assert start_wave(**QUICK_TANK, speed_m_s=3.0, source_spacing_m=1.0).duration_s == math.inf


def test_prismatic_length_is_the_spacing_of_the_hulls_source_and_sink():
    """L_s = V / A_s against the centroids of -dA/dx (bow) and dA/dx (stern) measured on x-slices of the B-063
    hull below the waterline, sampled on a 5 mm grid."""
    from scipy.spatial import ConvexHull

    g = b063_hull("A")
    hull = ConvexHull(g.vertices())
    d = 0.005
    ys = np.arange(-0.5 * g.beam_m + d / 2, 0.5 * g.beam_m, d)
    zs = np.arange(d / 2, g.draught_m, d)
    yy, zz = np.meshgrid(ys, zs, indexing="ij")
    xs = np.arange(g.vertices()[:, 0].min(), g.vertices()[:, 0].max(), d)
    area = np.empty(xs.size)
    for i, x in enumerate(xs):
        p = np.stack([np.full(yy.size, x), yy.ravel(), zz.ravel()], axis=1)
        inside = (p @ hull.equations[:, :3].T + hull.equations[:, 3] <= 1e-12).all(axis=1)
        area[i] = inside.sum() * d * d
    full = area.max()
    assert full == pytest.approx(g.midship_area_m2, rel=0.02)
    da = np.diff(area)
    xm = 0.5 * (xs[1:] + xs[:-1])
    bow, stern = da < 0, da > 0
    x_source = np.sum(xm[bow] * -da[bow]) / np.sum(-da[bow])
    x_sink = np.sum(xm[stern] * da[stern]) / np.sum(da[stern])
    assert g.prismatic_length_m == pytest.approx(1.833, abs=1e-3)
    assert x_source - x_sink == pytest.approx(g.prismatic_length_m, abs=0.01)


@pytest.mark.parametrize("fidelity", sorted(TIER2))
def test_steady_window_of_the_tier2_presets_against_the_start_wave(fidelity):
    """The paper's tank (3.1 m of run-up before the window) clears the start wave in every case; the quick
    tank's 0.66 m clears it at 1 and 1.5 knots, and its 2-knot window begins 0.64 s after the start, 0.30 s
    before the stern's wave reaches the bow (t_s = 0.94 s; docs/SHIP.md)."""
    fractions = {}
    for name in case_names():
        s = case_scene(name, fidelity, 2)
        g = hull_geometry(s)
        width_m = s.shape_cells()[1] * s.domain.dx_m
        layout = ice_layout(s, width_m, 0.5 * width_m, s.free_surface.water_depth_m, s.rho_kg_m3)
        wave, window_s = start_wave_of_scene(s, g, layout)
        fractions[name] = wave.window_fraction(*window_s)
    if fidelity == "paper":
        assert all(f == 0.0 for f in fractions.values()), fractions
    else:
        assert {n: f for n, f in fractions.items() if f > 0} == {"A-c68-v2.0": pytest.approx(0.40, abs=0.02)}
