"""Tier-1 hydrodynamics: a floating ice cube finds Archimedes' draft (rho_ice / rho_water of its height)."""

import numpy as np

from iceresist.dem import DEMSystem, Water, box


def test_ice_cube_floats_with_95_percent_submerged():
    a, rho_ice, rho_w = 0.041, 950.0, 1000.0
    z_eq = a / 2 - rho_ice / rho_w * a  # centre height when 95 % of the height is below z = 0
    s = DEMSystem()
    s.add_body(box((a, a, a), rho_ice, spheres_per_edge=2), (0.0, 0.0, z_eq + 1.5e-3))
    s.set_water(Water(level_m=0.0, density_kg_m3=rho_w))
    z = []
    for _ in range(1500):
        s.step(0.002)
        z.append(s.positions[0, 2])
    late = np.array(z[-500:])
    mid = 0.5 * (late.max() + late.min())  # centre of the (linear, lightly damped) heave oscillation
    submerged = (a / 2 - mid) / a
    assert abs(submerged - 0.95) < 0.01 * 0.95
    assert np.ptp(late) < 2 * 1.5e-3  # drag takes energy out of the heave


def test_submerged_volume_and_buoyancy_at_rest():
    a = 0.041
    s = DEMSystem()
    b = s.add_body(box((a, a, a), 950.0, spheres_per_edge=2), (0.0, 0.0, a / 2 - 0.95 * a))
    s.set_water(Water())
    s.prime()
    # buoyancy balances weight exactly at the draft (the sub-box slabs clip the volume exactly)
    assert abs(s._h["force"][b, 2]) < 1e-12 * 9.81 * 950 * a**3


def test_ice_force_time_series_now_and_as_the_substep_mean():
    from iceresist.dem import ContactParameters

    a = 0.041
    s = DEMSystem(gravity_m_s2=(0, 0, 0), ice_ship=ContactParameters(friction=0.0))
    s.add_body(box((a, a, a), 950.0, spheres_per_edge=2), (0.0, 0.0, 0.0))
    ship = s.add_body(box((0.1, 0.1, 0.05), 500.0, spacing_m=0.02), (-0.0705, 0.0, 0.0), (0.5, 0.0, 0.0),
                      kinematic=True, material="ship")
    t, f, fm = [], [], []
    for _ in range(10):
        s.step(1e-3)
        t.append(s.time_s)
        f.append(s.ice_force_on(ship))
        fm.append(s.mean_contact_force_on(ship))
    t, f, fm = np.array(t), np.array(f), np.array(fm)
    assert t.shape == (10,) and f.shape == (10, 3)
    assert np.allclose(t, 1e-3 * np.arange(1, 11))
    assert f[:, 0].min() < 0  # the ice pushes back on the advancing hull
    assert s.last_substeps > 1
    assert fm[:, 0].min() < 0 and not np.allclose(fm, f)
