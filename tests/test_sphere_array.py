"""Stokes flow through a simple-cubic array of spheres (iceresist.validate.cases.sphere_array) against Zick and
Homsy (1982)."""

from __future__ import annotations

import pytest

from iceresist.validate.cases import sphere_array as S


def test_radius_gives_the_solid_fraction():
    for phi in (0.027, 0.125, 0.343):
        a = S.radius_cells(32, phi)
        assert 4.0 / 3.0 * 3.141592653589793 * a ** 3 / 32 ** 3 == pytest.approx(phi, rel=1e-12)


def test_coarse_rung_balances_the_body_force_and_comes_within_7_percent_of_zick_homsy():
    """L = 16 cells, 9.9 cells per diameter. Settled, the momentum exchange on the sphere equals the body force on
    the fluid (measured 0.999993). K = 4.031 against Zick and Homsy's 4.292 (-6.1 %, the second-order resolution
    error of the ladder 4.031 / 4.188 / 4.234 at 10 / 15 / 20 cells per diameter, docs/VALIDATION.md). Comparing
    the momentum exchange itself with their F, which includes the mean pressure gradient's share G V_sphere, gives
    3.56 (-17 %: the factor 1 - phi of the module docstring) and fails."""
    r = S.run(S.ladder(True)[0])
    assert r.extra["force_balance"] == pytest.approx(1.0, abs=1e-3)
    assert r.extra["reynolds"] < 0.05
    assert r.value == pytest.approx(4.031, rel=0.005)
    assert r.value == pytest.approx(r.reference, rel=0.07) and r.reference == 4.292


@pytest.mark.slow   # about 2 min on a 2-core x86 VM
def test_three_solid_fractions_and_the_ladder_converge_to_zick_homsy():
    """phi = 0.064 / 0.125 / 0.216 at 15.9 / 19.9 / 17.9 cells per diameter: K within 2.5 % of Zick and Homsy
    (measured -0.95 / -1.34 / -2.13 %; the issue's 2 % at 16 cells per diameter holds for 0.064 and falls 0.1-0.2
    points short for 0.125 and 0.216), and the phi = 0.125 ladder converges at second order (observed orders 2.28
    and 2.05 between 10, 15 and 20 cells per diameter; asserted >= 1.7)."""
    import math

    for prm in S.fractions():
        r = S.run(prm)
        assert r.value == pytest.approx(r.reference, rel=0.025), prm["label"]
        assert r.value < r.reference
    errs, res = [], []
    for prm in S.ladder(True):
        r = S.run(prm)
        errs.append(abs(r.value / r.reference - 1))
        res.append(r.resolution)
    for i in range(2):
        assert math.log(errs[i] / errs[i + 1]) / math.log(res[i + 1] / res[i]) >= 1.7


@pytest.mark.slow   # about 1.5 min on a 2-core x86 VM
def test_at_tau_0_8_the_three_fractions_meet_the_issues_2_percent_at_16_to_20_cells_per_diameter():
    """The issue's target, 2 % at 16 cells per diameter, at tau = 0.8 (nu = 0.1): measured +0.31 / -0.15 / +0.20 %
    for phi = 0.064 / 0.125 / 0.216 (2-core x86 VM, 2026-11-29). Where the link bounce-back's wall sits is a matter
    of tau (the next test, and tau = 1 above); the bound is the issue's. Planted: the drag without the pressure
    share V_cell / V_fluid of the module docstring gives -6.4 / -12.4 / -21.7 % and fails."""
    for prm in S.fractions():
        r = S.run({**prm, "tau": 0.8})
        assert r.extra["tau"] == pytest.approx(0.8)
        assert r.value == pytest.approx(r.reference, rel=0.02), prm["label"]


@pytest.mark.slow   # about 4 min on a 2-core x86 VM
def test_the_drag_error_moves_with_tau_from_low_at_tau_1_to_high_at_tau_0_6():
    """The same three fractions at tau = 0.6 (nu = 1/30, nearer the tau - 1/2 of 1e-5 to 0.1 that the ship and the
    validation scenes run at): K is high by 2.01 / 1.39 / 3.38 % (measured), where tau = 1 gives -0.96 / -1.36 /
    -2.15 % and tau = 0.8 +0.31 / -0.15 / +0.20 %: the link bounce-back's wall moves with the viscosity (at
    second order in the resolution), so the issue's 2 % at 16 cells per diameter holds near tau = 0.8 only. The
    bound is 4 %, above the reference."""
    for prm in S.fractions():
        r = S.run({**prm, "tau": 0.6})
        assert r.extra["tau"] == pytest.approx(0.6)
        assert r.reference < r.value < 1.04 * r.reference, prm["label"]
