"""A scene with ``[[bodies]]`` and ``[refinement]`` (iceresist.models.bodies): the sphere of
tests/test_refined_sphere.py written as a scene runs as the engine-level set-up does, the band around the bodies
refines where they are, a restart is bit for bit, and a body outside the finest level is refused."""

import math

import numpy as np
import pytest

from iceresist.models import BodiesModel, build_model
from iceresist.scene import parse_scene
from tests.test_refined_sphere import U, refined_sphere_drag

from test_run import _one_line_error, main  # noqa: F401  (the CLI fixture)

#: The refined sphere of tests/test_refined_sphere.py (Re 10, 12 x 8 x 8 d, 4 cells per diameter on level 0, the
#: patch 1.5 d up- and sideways and 2.5 d downstream on level 1) as a lattice-unit scene.
SPHERE = """
[scene]
name = "refined_sphere"
units = "lattice"

[domain]
cells = [48, 32, 32]
faces = { x_min = { kind = "velocity_inlet", velocity_m_s = [0.1, 0.0, 0.0] }, x_max = "pressure_outlet", y_min = "periodic", y_max = "periodic", z_min = "periodic", z_max = "periodic" }

[fluid]
operator = "cumulant"
initial_velocity_m_s = [0.1, 0.0, 0.0]

[numerics]
tau = 0.62                      # level 0; level 1: 0.74, nu = U d / Re with d = 8 level-1 cells
precision = "float32"

[run]
steps = 160                     # 4 d / U

[[bodies]]
name = "sphere"
shape = "sphere"
radius_m = 2.0
position_m = [16.0, 16.0, 16.0]
motion = "fixed"

[refinement]
levels = 1

[[refinement.boxes]]
lo_m = [10.0, 10.0, 10.0]
hi_m = [26.0, 22.0, 22.0]
level = 1
"""


def test_a_refined_sphere_scene_runs_as_the_engine_set_up():
    """4 d / U: the drag coefficient of the scene (its sphere and coupling on level 1, stepped at level 1's time
    step) equals the engine-level run's (tests/test_refined_sphere.py) to 1e-6."""
    m = build_model(parse_scene(SPHERE, "refined_sphere.toml"))
    assert isinstance(m, BodiesModel)
    fx = []
    step = m.lbm.steppers[1]

    def recorded():
        step()
        fx.append(m.coupling.force_lattice[0, 0])

    m.lbm.set_stepper(1, recorded)
    m.step(160)
    fx = np.array(fx)
    cd = float(fx[int(0.75 * len(fx)):].mean()) / (0.5 * U ** 2 * math.pi * 4.0 ** 2)
    cd_engine, _, _ = refined_sphere_drag(4.0)
    assert len(fx) == 320
    assert cd == pytest.approx(cd_engine, rel=1e-6)
    d = m.diagnostics()
    assert d["sphere_x_m"] == 16.0 and d["sphere_Fx_N"] > 0


def test_a_band_around_the_bodies_refines_where_they_are_and_a_run_restarts_bit_for_bit():
    """refinement.body_band_m = 4 cells instead of the box: level 1 covers the blocks within 4 cells of the
    sphere's bounding box (x 8-24, y and z 8-24: 2 x 2 x 2 level-0 blocks), level 0 the rest; 10 steps, a
    checkpoint, 10 more equal 20 straight bit for bit."""
    from iceresist.scene.blocks import build_octree

    text = SPHERE.split("[[refinement.boxes]]")[0] + "body_band_m = 4.0\n"
    scene = parse_scene(text, "refined_sphere.toml")
    tree = build_octree(scene)
    fine = {tuple((c >> 1).tolist()) for lv, c in zip(tree.level, tree.coord) if lv == 1}
    assert fine == {(x, y, z) for x in (1, 2) for y in (1, 2) for z in (1, 2)}
    a = build_model(scene)
    a.step(10)
    state = a.state()
    a.step(10)
    b = build_model(scene)
    b.load_state(state)
    b.step(10)
    for lv in a.lbm.levels:
        assert np.array_equal(a.lbm.solvers[lv].populations(), b.lbm.solvers[lv].populations())
    assert a.diagnostics() == b.diagnostics()


def test_a_body_beyond_the_finest_level_is_refused(tmp_path, main):  # noqa: F811
    p = tmp_path / "s.toml"
    p.write_text(SPHERE.replace("lo_m = [10.0, 10.0, 10.0]", "lo_m = [16.0, 10.0, 10.0]"))
    rc, err = main(p, "--output", tmp_path / "out")
    _one_line_error(rc, err, "refinement: body 'sphere' (bodies[0]) reaches beyond the finest level")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
