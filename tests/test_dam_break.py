"""Collapse of a water column against Martin and Moyce (1952), n^2 = 2 (iceresist.validate.cases.dam_break)."""

import numba
import numpy as np
import pytest

from iceresist.validate.cases import dam_break as db


@pytest.fixture
def one_thread():
    n = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(n)


def test_measurements_file():
    t, z = db.measurements()
    assert len(t) >= 3 and np.all(np.diff(t) > 0) and np.all(np.diff(z) > 0)
    assert z[0] == pytest.approx(1.217)


def test_front_position_interpolates():
    """Floor edge: phi 0.75 -> 0.25 between the cell centres 9.5 and 10.5 crosses 1/2 at x = 10; the nose one
    layer up (phi = 1/2 at the centre 12.5) lies at 12.5."""
    phi = np.zeros((20, 2, 4))
    phi[:10, :, 0] = 1.0
    phi[9, :, 0], phi[10, :, 0] = 0.75, 0.25
    phi[:12, :, 1] = 1.0
    phi[12, :, 1] = 0.5
    assert db.front_position(phi) == pytest.approx(10.0)
    assert db.front_position(phi, rows=2) == pytest.approx(12.5)


def test_dam_break_front_coarse(one_thread):
    """a = 8 cells, cumulant tau = 0.51, M = 0.01, float32: the floor edge and the nose within 5 % of the
    measurements for T <= 2 (measured -1.5, -3.8, -0.5 % and +1.9, +0.5, +2.3 % at T = 0.83, 1.22, 2.00);
    water volume conserved. The requirement holds at this resolution only: a = 12 and 16 lead by up to
    12 % (docs/VALIDATION.md). The 5 % band is a regression pin around the measured state of the no-slip front at
    a = 8 (the reference check is the free-slip test's 20 %)."""
    r = db.run(dict(cells_per_column=8, t_end=2.1))
    t = np.array(r.extra["T_ref"])
    keep = t <= 2.0
    err = np.array(r.extra["error_at_ref"])[keep]
    assert np.all(err < 0.05)
    nose = np.interp(t, r.extra["T"], r.extra["Z_nose"])
    assert np.all(nose >= np.array(r.extra["Z_sim"]) - 1e-9)
    assert np.all(np.abs(nose / np.array(r.extra["Z_ref"]) - 1.0)[keep] < 0.05)
    v0 = 2 * 8 * 8 * 8                                           # column a x 2a x 8 cells
    assert r.extra["volume"] == pytest.approx(v0, rel=0.02)


@pytest.mark.slow
def test_dam_break_front_finer(one_thread):
    """a = 16 cells: the floor edge within 14 % for T <= 2 (measured +0.7, +12.1, +6.7 %): the 5 % requirement is
    NOT met at T = 1.22; the 14 % band is a regression pin around the measured state, not a reference check
    (docs/VALIDATION.md; the floor edge depends on the film the dry floor starts with, docs/notes/dam-break.md)."""
    r = db.run(dict(cells_per_column=16, t_end=2.1))
    err = np.array(r.extra["error_at_ref"])[np.array(r.extra["T_ref"]) <= 2.0]
    assert np.all(err < 0.14)
    assert err[1] > 0.05


def test_dam_break_on_a_free_slip_floor_converges_and_leads_martin_moyce_within_20_percent(one_thread):
    """Free-slip walls (specular reflection): the contact line is not held, so the floor edge and the nose
    coincide, and the front converges with resolution: Z(T = 2) = 2.564, 2.638, 2.665 at a = 8, 12, 16
    (differences 0.074 then 0.027). The decision of issue 32: the instantaneous release leads Martin and Moyce's
    gate-opened front, so the check against them is every measured point with T <= 3 within 20 % and the offset
    at T = 2 converging (each refinement changes it less than the one before), not a fit. Measured: offsets at
    T = 2 of +11.9, +15.1, +16.3 %. The fronts Z(T = 2) and the offset bands are regression pins around those
    measurements; the reference checks are the 20 % bound and the converging offset."""
    z2, offsets = [], []
    for a in (8, 12, 16):
        r = db.run(dict(cells_per_column=a, walls="slip", t_end=3.05))
        z2.append(r.value)
        offsets.append(r.extra["mm_offset_at_T"])
        assert np.max(np.abs(np.array(r.extra["Z"]) - np.array(r.extra["Z_nose"]))) < 0.01
        assert r.extra["mm_worst_error"] < db.MM_TOLERANCE
        assert r.extra["volume"] == pytest.approx(2 * a * a * 8, rel=0.02)
    assert z2 == pytest.approx([2.564, 2.638, 2.665], abs=0.01)
    assert abs(offsets[2] - offsets[1]) < 0.5 * abs(offsets[1] - offsets[0])
    assert 0.10 < offsets[0] < 0.13 and 0.14 < offsets[2] < 0.19
