"""DEM checkpoints continue bit for bit (contact history included), and the sub-step mean of the contact force."""

import numpy as np
import pytest

from iceresist.dem import ContactParameters, DEMSystem, Water, box
from iceresist.errors import InputError

CUBE = 0.04
CP = ContactParameters(normal_stiffness_N_m=2.0e4, restitution=0.3, friction=0.35)


def _heap(seed=3):
    """Nine ice cubes dropped into a small walled tank of water, touching each other and the walls."""
    s = DEMSystem(ice_ice=CP, ice_ship=CP)
    cube = box((CUBE,) * 3, 950.0, spheres_per_edge=2)
    rng = np.random.default_rng(seed)
    for i in range(3):
        for j in range(3):
            p = (0.021 + 0.0395 * i, 0.021 + 0.0395 * j, 0.03 + 0.02 * rng.random())
            s.add_body(cube, p, velocity_m_s=0.05 * (rng.random(3) - 0.5), angular_velocity_rad_s=rng.random(3))
    for point, normal in (((0, 0, 0), (1, 0, 0)), ((0.12, 0, 0), (-1, 0, 0)), ((0, 0, 0), (0, 1, 0)),
                          ((0, 0.12, 0), (0, -1, 0)), ((0, 0, 0), (0, 0, 1))):
        s.add_wall(point, normal)
    s.set_water(Water(level_m=0.02))
    return s


def _final(s):
    return {"positions": s.positions, "quaternions": s.quaternions, "velocities": s.velocities,
            "angular_momenta": s.angular_momenta,
            "forces": np.array([s.contact_force_on(b) for b in range(s.n_bodies)]),
            "torques": np.array([s.contact_torque_on(b) for b in range(s.n_bodies)])}


def test_restart_from_state_continues_bit_for_bit():
    dt, n = 0.002, 40
    straight = _heap()
    for _ in range(2 * n):
        straight.step(dt)
    first = _heap()
    for _ in range(n):
        first.step(dt)
    saved = first.state()
    # the checkpoint holds live tangential springs, else the test could not tell a lost history
    used = np.arange(saved["history_partner"].shape[1])[None, :] < saved["history_count"][:, None]
    assert first.contact_count() > 5 and np.abs(saved["history_spring_m"][used]).max() > 0
    second = _heap()
    second.load_state({k: v.copy() for k, v in saved.items()})
    for _ in range(n):
        second.step(dt)
    a, b = _final(straight), _final(second)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert second.time_s == straight.time_s and second.collision_count() == straight.collision_count()

    # the same restart with the springs dropped drifts away: the history is what makes it exact
    lossy = _heap()
    cut = {k: v.copy() for k, v in saved.items()}
    cut["history_count"][:] = 0
    lossy.load_state(cut)
    for _ in range(n):
        lossy.step(dt)
    assert not np.array_equal(lossy.positions, a["positions"])


def test_state_of_another_system_is_refused():
    s = _heap()
    s.step(0.002)
    other = DEMSystem(ice_ice=CP, ice_ship=CP)
    other.add_body(box((CUBE,) * 3, 950.0, spheres_per_edge=2), (0, 0, 0))
    with pytest.raises(InputError, match="shape"):
        other.load_state(s.state())
    with pytest.raises(InputError, match="lacks"):
        other.load_state({"pos": np.zeros((1, 3))})


def test_mean_contact_force_is_the_mean_over_substeps():
    n = 6
    ref = _heap()
    loop = _heap()
    for _ in range(10):
        ref.step(0.002)
        loop.step(0.002)
    h = 0.002 / n
    acc = np.zeros((ref.n_bodies, 3))
    for _ in range(n):
        loop.step(h, substeps=1)
        acc += np.array([loop.contact_force_on(b) for b in range(loop.n_bodies)])
    ref.step(h * n, substeps=n)
    mean = np.array([ref.mean_contact_force_on(b) for b in range(ref.n_bodies)])
    assert np.abs(acc).max() > 0.1  # the cubes press on each other and on the walls
    np.testing.assert_allclose(mean, acc / n, rtol=1e-12, atol=1e-12)
    # one sub-step: the mean is the force after it
    ref.step(h, substeps=1)
    np.testing.assert_array_equal(ref.mean_contact_force_on(0), ref.contact_force_on(0))


def test_thread_count_does_not_change_the_result(monkeypatch):
    import numba

    import iceresist.dem.kernels as kernels

    threads = numba.config.NUMBA_NUM_THREADS
    if threads < 2:
        pytest.skip("one numba thread only")
    monkeypatch.setattr(kernels, "PARALLEL_FROM", dict.fromkeys(kernels.PARALLEL_FROM, 0))
    out = []
    for n in (1, threads):
        numba.set_num_threads(n)
        s = _heap()
        for _ in range(30):
            s.step(0.002)
        out.append(_final(s))
    numba.set_num_threads(threads)
    assert out[0]["forces"].any()
    for name in out[0]:
        np.testing.assert_array_equal(out[0][name], out[1][name], err_msg=name)


def test_external_loads_of_all_bodies_at_once_act_as_per_body_ones():
    """``set_external_all`` (one upload per coupled step) moves the bodies as ``set_external`` body by body did,
    bit for bit, before and after the build; a table of the wrong shape is refused naming the shape."""
    rng = np.random.default_rng(5)
    force0, torque0 = rng.normal(0, 0.05, (9, 3)), rng.normal(0, 1e-3, (9, 3))
    runs = []
    for batched in (False, True):
        s = _heap()
        for step in range(4):
            # loads that change after the build, as the coupling's do every step
            force, torque = (force0, torque0) if step < 2 else (-force0, 2 * torque0)
            if batched:
                s.set_external_all(force, torque)
            else:
                for b in range(9):
                    s.set_external(b, force_N=force[b], torque_N_m=torque[b])
            s.step(2e-3)
        runs.append(_final(s))
    for key in runs[0]:
        assert np.array_equal(runs[0][key], runs[1][key]), key
    free = _heap()
    for _ in range(4):
        free.step(2e-3)
    assert not np.array_equal(runs[1]["positions"], free.positions)  # the loads moved the bodies
    with pytest.raises(InputError, match=r"\(9, 3\)"):
        s.set_external_all(force[:3], torque)
