"""The free heave decay of a floating sphere against Kramer et al. (2021): the set-up's geometry, the reduction of a
heave series, the quick rung against its bounds (CI) and the full ladder (slow)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from iceresist.validate.cases import heave_decay as hd


def test_the_sphere_floats_half_submerged_and_the_release_keeps_the_water():
    """7.056 kg in 0.3 m floats with its centre on the water level (Archimedes, to 1e-4 of the mass); the level at
    the release holds the water of the floating state, below the floating level in a tank of 1.2 m and on it in a
    very wide one."""
    half = hd.submerged_volume_m3(0.0)
    assert half == pytest.approx(2.0 / 3.0 * math.pi * hd.RADIUS_M ** 3, rel=1e-12)
    assert hd.RHO_WATER * half == pytest.approx(hd.MASS_KG, rel=1e-4)
    assert hd.DENSITY * 4.0 / 3.0 * math.pi * hd.RADIUS_M ** 3 == pytest.approx(hd.MASS_KG, rel=1e-12)
    width = 1.2
    level = hd.release_level_m(width, hd.DEPTH_M, hd.DROP_M)
    water = width ** 2 * level - hd.submerged_volume_m3(hd.DEPTH_M + hd.DROP_M - level)
    assert water == pytest.approx(width ** 2 * hd.DEPTH_M - half, rel=1e-12)
    assert hd.DEPTH_M - 2e-3 < level < hd.DEPTH_M
    assert hd.release_level_m(100.0, hd.DEPTH_M, hd.DROP_M) == pytest.approx(hd.DEPTH_M, abs=1e-6)


def test_the_reduction_recovers_a_decaying_oscillation():
    """A heave of period 0.79 s, decay rate 0.83 1/s about 1.5 mm, released 29.16 mm high: the fit gives them back
    to 1e-3, and the first trough's ratio is that of the extreme at omega t = pi - atan(sigma / omega)."""
    t = np.arange(0.0, 4 * hd.PERIOD_S, 0.005)
    omega, sigma, z_eq = 2 * math.pi / 0.79, 0.83, 1.5e-3
    z = z_eq + (hd.DROP_M - z_eq) * np.exp(-sigma * t) * np.cos(omega * t)
    r = hd.analyse(t, z)
    assert r["period_s"] == pytest.approx(0.79, rel=1e-3)
    assert r["sigma_1_s"] == pytest.approx(sigma, rel=1e-3)
    assert r["z_eq_m"] == pytest.approx(z_eq, abs=1e-5)
    assert r["damping_ratio"] == pytest.approx(sigma / math.hypot(sigma, omega), rel=1e-3)
    assert r["cycle_ratio"] == pytest.approx(math.exp(-sigma * 0.79), rel=1e-3)
    phi = math.atan(sigma / omega)
    assert r["first_trough_ratio"] == pytest.approx(math.exp(-sigma * (math.pi - phi) / omega) * math.cos(phi),
                                                    rel=1e-3)


# 12 cells per diameter in a tank of eight diameters, four periods: about 6 min in a test process of CI's two on a
# 2-core x86 VM, so slow (CI holds the fit of the decay above and the floating cube of tests/test_floating.py)
@pytest.mark.slow
def test_quick_rung_heaves_near_the_measured_period_and_decay():
    """The quick ladder's finest rung against the measurement (first damped period 0.7869 s, decay rate 0.831 1/s,
    first trough 0.855 of the drop) within what 12 cells per diameter gives (docs/VALIDATION.md, "Heave decay"):
    the period 11 % long today, bound 15 %. Planted: a sphere's mass x 1.5 in the DEM (it then floats deeper and
    its heave never crosses the floating level of the drop) gives no period and fails."""
    r = hd.run(hd.rung(12, 8, 4.0))
    assert r.error < 0.15
    assert r.extra["sigma_1_s"] == pytest.approx(hd.SIGMA_1_S, rel=0.15)
    assert r.extra["first_trough_ratio"] == pytest.approx(0.855, abs=0.05)
    assert abs(r.extra["floating_offset_m"]) < 0.25 * hd.DIAMETER_M / 12      # a quarter of a cell
    assert r.extra["volume_drift"] < 5e-3


# the full ladder (eight rungs in tanks of 4 and 8 diameters, one in 16): about 45 min on a 2-core x86 VM
@pytest.mark.slow
def test_full_ladder_measures_the_tank_and_approaches_the_measured_period():
    """The tank's walls lengthen the period (their reflected wave returns within the first periods): at 16 and
    24 cells per diameter the tank of eight diameters is nearer the measured 0.7869 s than the tank of four, and
    its finest rung lies within 5 % of it (docs/VALIDATION.md, "Heave decay")."""
    rows = {(p["resolution"], p["tank_diameters"]): hd.run(p) for p in hd.ladder(quick=False)}
    for n in (16, 24):
        assert rows[(n, 8)].error < rows[(n, 4)].error
    assert rows[(24, 8)].error < 0.05
    assert rows[(24, 8)].extra["sigma_1_s"] == pytest.approx(hd.SIGMA_1_S, rel=0.15)
