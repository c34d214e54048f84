"""Physical <-> lattice units: known numbers from the paper's setup, round trips, refusals."""

import logging
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from iceresist.errors import InputError, StabilityError
from iceresist.units import (Units, check_lattice_velocity, check_tau, dem_critical_step_s,
                             dem_substeps, reference_speed_m_s)

KNOT = 0.514  # m/s, paper section 3


def test_paper_finest_cell_gives_tau_excess_of_order_1e_minus_5():
    # Finest cell 2.72 mm, water nu = 1e-6 m^2/s, 1 knot, depth 1.11 m (paper section 3).
    u = Units.from_physical(2.72e-3, 1e-6, KNOT, depth_m=1.11)
    c = math.sqrt(9.81 * 1.11)  # 3.2999 m/s, the wave speed dominates the ship speed
    assert u.dt_s == pytest.approx(0.1 * 2.72e-3 / c, rel=1e-12)
    assert u.dt_s == pytest.approx(8.2427e-5, rel=1e-4)
    assert u.tau - 0.5 == pytest.approx(3.3424e-5, rel=1e-3)
    assert 1e-5 < u.tau - 0.5 < 1e-4
    assert u.omega == pytest.approx(1.0 / u.tau)
    # the wave speed is exactly at the lattice velocity limit, the ship at 0.1 * 0.514/3.2999
    assert u.velocity_to_lattice(c) == pytest.approx(0.1)
    assert u.velocity_to_lattice(KNOT) == pytest.approx(0.1 * KNOT / c)


def test_without_depth_the_ship_speed_sets_the_step():
    u = Units.from_physical(2.72e-3, 1e-6, KNOT)
    assert u.dt_s == pytest.approx(0.1 * 2.72e-3 / KNOT)
    assert u.tau - 0.5 == pytest.approx(3 * 1e-6 * u.dt_s / 2.72e-3 ** 2)
    assert u.tau - 0.5 == pytest.approx(2.1458e-4, rel=1e-3)
    assert u.velocity_to_lattice(KNOT) == pytest.approx(0.1)


def test_gravity_and_hydrostatic_pressure_in_lattice_units():
    u = Units.from_physical(2.72e-3, 1e-6, KNOT, depth_m=1.11)
    g_lat = u.acceleration_to_lattice(9.81)
    assert g_lat == pytest.approx(9.81 * u.dt_s ** 2 / 2.72e-3)
    # hydrostatic pressure at the bottom: rho g h, lattice: g_lat * h_lat (rho0 = 1)
    p_lat = u.pressure_to_lattice(1000 * 9.81 * 1.11)
    assert p_lat == pytest.approx(g_lat * u.length_to_lattice(1.11), rel=1e-12)
    # weight of a 41 mm ice cube: F = m g, both ways
    m = 950 * 0.041 ** 3
    assert u.force_to_lattice(m * 9.81) == pytest.approx(u.mass_to_lattice(m) * g_lat, rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(dx=st.floats(1e-4, 1.0), nu=st.floats(1e-7, 1e-2), umax=st.floats(1e-3, 10.0),
       x=st.floats(-1e3, 1e3, allow_nan=False))
def test_round_trips(dx, nu, umax, x):
    try:
        u = Units.from_physical(dx, nu, umax)
    except StabilityError:
        return  # very small tau - 1/2 is refused; covered below
    for name in ("length", "time", "velocity", "acceleration", "density", "pressure", "force", "force_density",
                 "viscosity", "mass"):
        there = getattr(u, f"{name}_to_lattice")(x)
        back = getattr(u, f"{name}_to_physical")(there)
        assert back == pytest.approx(x, rel=1e-12, abs=1e-300), name
    assert u.viscosity_to_lattice(nu) == pytest.approx(u.nu_lattice, rel=1e-9)


def test_arrays_convert_elementwise():
    u = Units.from_physical(0.01, 1e-4, 1.0)
    v = np.array([0.0, 0.5, 1.0])
    np.testing.assert_allclose(u.velocity_to_lattice(v), [0.0, 0.05, 0.1])


def test_lattice_units_are_identity():
    u = Units.lattice(tau=0.8)
    assert (u.dx_m, u.dt_s, u.rho0_kg_m3) == (1.0, 1.0, 1.0)
    assert u.nu_lattice == pytest.approx(0.1)
    assert Units.lattice(nu=0.1).tau == pytest.approx(0.8)
    assert u.velocity_to_lattice(0.05) == 0.05
    with pytest.raises(StabilityError):
        Units.lattice(tau=0.8, nu=0.1)


def test_refuses_tau_at_or_below_half():
    with pytest.raises(StabilityError, match="must be > 1/2"):
        Units.from_physical(0.01, 0.0, 1.0)
    with pytest.raises(StabilityError, match="must be > 1/2"):
        Units.lattice(tau=0.5)
    assert issubclass(StabilityError, InputError)


def test_refuses_tau_excess_below_floor_and_names_the_fix():
    # nu = 1e-12 at dx = 1 cm, dt = 1 ms: tau - 1/2 = 3e-11
    with pytest.raises(StabilityError, match="coarser cell"):
        Units.from_physical(0.01, 1e-12, 1.0)
    # a lowered floor lets it through
    u = Units.from_physical(0.01, 1e-12, 1.0, min_tau_excess=1e-14)
    assert u.tau - 0.5 == pytest.approx(3e-11, rel=1e-4)


def test_warns_below_1e_minus_4(caplog):
    with caplog.at_level(logging.WARNING, logger="iceresist.units"):
        check_tau(0.5 + 3e-5)
    assert "cumulant" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="iceresist.units"):
        check_tau(0.6)
    assert caplog.text == ""


def test_refuses_lattice_velocity_above_limit():
    with pytest.raises(StabilityError, match="above the limit 0.1"):
        Units.from_physical(0.01, 1e-6, 1.0, dt_s=0.002)  # u_lat = 0.2
    u = Units.from_physical(0.01, 1e-6, 1.0, dt_s=0.001)  # u_lat = 0.1 exactly: accepted
    assert u.velocity_to_lattice(1.0) == pytest.approx(0.1)
    with pytest.raises(StabilityError, match="reduce the time step"):
        check_lattice_velocity(0.11)
    with pytest.raises(StabilityError, match=r"must be in \(0, 0.3\]"):
        Units.from_physical(0.01, 1e-6, 1.0, mach_lattice=0.5)
    with pytest.raises(StabilityError, match="no speed"):
        Units.from_physical(0.01, 1e-6, 0.0)


def test_reference_speed_counts_shallow_water_waves():
    assert reference_speed_m_s(0.514) == pytest.approx(0.514)
    assert reference_speed_m_s(0.514, depth_m=1.11) == pytest.approx(math.sqrt(9.81 * 1.11))
    assert reference_speed_m_s(5.0, depth_m=1.11) == pytest.approx(5.0)


def test_dem_critical_step():
    m, k = 950 * 0.041 ** 3, 1e4  # one ice cube, 10 kN/m
    crit = 2 * math.sqrt(m / k)
    assert dem_critical_step_s(m, k) == pytest.approx(crit)
    assert dem_substeps(crit, m, k, safety=0.2) == 5
    assert dem_substeps(0.1 * crit, m, k, safety=0.2) == 1
    with pytest.raises(StabilityError):
        dem_critical_step_s(0.0, k)
