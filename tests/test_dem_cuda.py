"""The CUDA launchers (the simulator where no GPU is lent) against the CPU ones on a small scene."""

import numpy as np
import pytest

from iceresist.dem import ContactParameters, DEMSystem, Water, box


def _scene(backend):
    ice = ContactParameters(normal_stiffness_N_m=1.0e4, restitution=0.4, friction=0.3)
    ship = ContactParameters(normal_stiffness_N_m=2.0e4, restitution=0.3, friction=0.1)
    s = DEMSystem(backend=backend, ice_ice=ice, ice_ship=ship)
    a = 0.041
    cube = box((a, a, a), 950.0, spheres_per_edge=2)
    s.add_body(cube, (0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.0, 0.0, 3.0))
    s.add_body(cube, (0.0405, 0.004, 0.002), (-0.1, 0.0, 0.0), orientation=(0.98, 0.0, 0.0, 0.199))
    s.add_body(cube, (0.02, 0.0, 0.0395), (0.0, 0.0, -0.2))
    hull = s.add_body(box((0.1, 0.1, 0.05), 500.0, spacing_m=0.02), (-0.0685, 0.0, 0.0), (0.5, 0.0, 0.0),
                      kinematic=True, material="ship")
    s.add_wall((0.0, 0.0, -0.025), (0.0, 0.0, 1.0))
    s.set_water(Water(level_m=0.015))
    return s, hull


def test_cuda_launchers_match_cpu(target):
    if not target.is_cuda:
        pytest.skip("compares the CUDA launchers with the CPU ones")
    out = {}
    for backend in ("cpu", "cuda"):
        s, hull = _scene(backend)
        for _ in range(3):
            s.step(1e-3, substeps=4)
        out[backend] = (s.positions, s.velocities, s.quaternions, s.angular_momenta, s.ice_force_on(hull),
                        s.contact_count())
    cpu, gpu = out["cpu"], out["cuda"]
    assert cpu[5] == gpu[5] and cpu[5] > 0
    assert np.abs(cpu[4]).max() > 0
    for a, b in zip(cpu[:5], gpu[:5]):
        assert np.allclose(a, b, rtol=1e-9, atol=1e-12)


def test_cpu_checkpoint_continues_on_cuda(target):
    """A CPU state loaded into a CUDA system continues like the CPU one (contact history and sub-step mean)."""
    if not target.is_cuda:
        pytest.skip("loads a CPU state into the CUDA launchers")
    cpu, hull = _scene("cpu")
    for _ in range(3):
        cpu.step(1e-3, substeps=4)
    gpu, _ = _scene("cuda")
    gpu.load_state(cpu.state())
    for s in (cpu, gpu):
        s.step(1e-3, substeps=4)
    assert np.abs(cpu.mean_contact_force_on(hull)).max() > 0
    assert np.allclose(gpu.mean_contact_force_on(hull), cpu.mean_contact_force_on(hull), rtol=1e-9, atol=1e-12)
    back = gpu.state()
    for key, value in cpu.state().items():
        if not key.startswith("history_"):  # slots per sphere follow the (atomic, unordered) CUDA bucket order
            assert np.allclose(back[key], value, rtol=1e-9, atol=1e-12), key
