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
    12 % (docs/VALIDATION.md)."""
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
    NOT met at T = 1.22; this guards the measured state (docs/VALIDATION.md; the floor edge depends on the film
    the dry floor starts with, docs/notes/dam-break.md)."""
    r = db.run(dict(cells_per_column=16, t_end=2.1))
    err = np.array(r.extra["error_at_ref"])[np.array(r.extra["T_ref"]) <= 2.0]
    assert np.all(err < 0.14)
    assert err[1] > 0.05


def test_dam_break_on_a_free_slip_floor_converges(one_thread):
    """Free-slip walls (specular reflection): the contact line is not held, so the floor edge and the nose
    coincide, and the front converges with resolution: Z(T = 2) = 2.564, 2.638, 2.665 at a = 8, 12, 16
    (differences 0.074 then 0.027). It converges to about 16 % ahead of Martin and Moyce (+11.7, +16.1 %
    at a = 8, 16), past the no-slip nose (+11 % at a = 16): the measurements lag the simulated
    instantaneous release (docs/VALIDATION.md, "Dam break"). This guards those numbers."""
    z2, err = [], []
    for a in (8, 12, 16):
        r = db.run(dict(cells_per_column=a, walls="slip", t_end=2.05))
        t = np.array(r.extra["T"])
        z2.append(np.interp(2.0, t, r.extra["Z"]))
        assert np.max(np.abs(np.array(r.extra["Z"]) - np.array(r.extra["Z_nose"]))) < 0.01
        err.append(np.array(r.extra["error_at_ref"])[np.array(r.extra["T_ref"]) <= 2.0])
        assert r.extra["volume"] == pytest.approx(2 * a * a * 8, rel=0.02)
    assert abs(z2[2] - z2[1]) < 0.5 * abs(z2[1] - z2[0])
    assert z2[0] < z2[1] < z2[2]
    assert 0.10 < err[0].max() < 0.13 and 0.14 < err[2].max() < 0.19
