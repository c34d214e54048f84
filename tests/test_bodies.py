"""Scenes with ``[[bodies]]`` through ``iceresist run`` (:class:`iceresist.models.BodiesModel`): they parse and
build, the time series holds the per-body columns, a pickup from a checkpoint continues bit for bit, bad input is
refused in one line (exit 2, nothing written), and two physics checks: a neutrally buoyant sphere stays put in a
fluid under gravity (the buoyancy the coupling adds balances its weight), and a box held at half submergence in a
free-surface tank feels rho g V_submerged."""

import numpy as np
import pytest

from iceresist import cli
from iceresist.io import RunFile
from iceresist.models import BodiesModel, FloatingBodiesModel, build_model
from iceresist.models.bodies import BODY_COLUMNS
from iceresist.scene.load import parse_scene

#: A fixed sphere in a channel (lattice units): velocity inlet, pressure outlet, periodic sides.
CHANNEL = """
[scene]
name = "channel_sphere"
units = "lattice"

[domain]
cells = [32, 16, 16]
faces = { x_min = { kind = "velocity_inlet", velocity_m_s = [0.05, 0.0, 0.0] }, x_max = "pressure_outlet", y_min = "periodic", y_max = "periodic", z_min = "periodic", z_max = "periodic" }

[fluid]
initial_velocity_m_s = [0.05, 0.0, 0.0]

[numerics]
tau = 0.8
precision = "float32"

[run]
steps = 20

[output]
fields = ["u", "flags"]
timeseries_every_steps = 5
checkpoint_every_steps = 10

[[bodies]]
name = "post"
shape = "sphere"
radius_m = 3.0
position_m = [10.0, 8.0, 8.0]
motion = "fixed"
"""

#: A free box in a closed free-surface tank (physical units), released a little below its floating draft.
TANK = """
[scene]
name = "tank_box"

[domain]
cells = [16, 16, 24]
dx_m = 0.005
faces = { x_min = "wall", x_max = "wall", y_min = "wall", y_max = "wall", z_min = "wall", z_max = "wall" }

[fluid]
nu_m2_s = 5.0e-6
gravity_m_s2 = [0.0, 0.0, -9.81]
operator = "bgk"

[numerics]
dt_s = 0.0007
mach = 0.2
precision = "float64"

[run]
steps = 20

[output]
fields = ["phi"]
timeseries_every_steps = 5
checkpoint_every_steps = 10

[free_surface]
water_depth_m = 0.06
mobility_lattice = 0.05
f_pool_margin = "full"

[[bodies]]
name = "floe"
shape = "box"
size_m = [0.03, 0.03, 0.03]
position_m = [0.04, 0.04, 0.05]
density_kg_m3 = 900.0
"""


@pytest.fixture
def main(capsys):
    def run(*argv):
        try:
            rc = cli.main(["run", *map(str, argv), "--no-progress"])
        except SystemExit as exc:
            rc = exc.code
        return rc, capsys.readouterr().err

    return run


def _one_line_error(rc, err, *needles):
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and ": error: " in lines[0] and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], lines[0]


@pytest.mark.parametrize("text, components", [(CHANNEL, ("fluid", "dem", "coupling")),
                                              (TANK, ("fluid", "free_surface", "dem", "coupling"))])
def test_body_scenes_build_and_their_rows_hold_every_body_column(text, components):
    scene = parse_scene(text, "s.toml")
    model = build_model(scene)
    assert isinstance(model, (BodiesModel, FloatingBodiesModel)) and model.components == components
    model.step(2)
    row = model.diagnostics()
    name = scene.bodies[0].name
    assert all(f"{name}_{c}" in row for c in BODY_COLUMNS)
    assert all(np.isfinite(v) for v in row.values())
    if scene.free_surface is not None:
        assert {"water_volume_m3", "water_volume_drift", "water_level_m"} <= set(row)
        assert row["floe_vz_m_s"] != 0.0                     # the free box moves
    else:
        assert row["post_Fx_N"] > 0.0 and row["post_vx_m_s"] == 0.0   # dragged downstream, held at rest
    assert model.allocated_bytes() > 0 and model.describe()["bodies"][0]["name"] == name


@pytest.mark.parametrize("text", [CHANNEL, TANK], ids=["channel", "tank"])
def test_pickup_from_a_checkpoint_continues_bit_for_bit(tmp_path, main, text):
    """10 steps, then --pickup to 20, against 20 steps straight: every time-series column and the final fields
    equal to the bit (model state(): populations, flags, phase field, coupling owners and forces, DEM)."""
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    assert main(scene, "--output", tmp_path / "a", "--steps", "10")[0] == 0
    rc, err = main(scene, "--output", tmp_path / "a", "--steps", "20", "--pickup")
    assert rc == 0, err
    assert main(scene, "--output", tmp_path / "b", "--steps", "20")[0] == 0
    name = parse_scene(text).scene.name
    with RunFile(tmp_path / "a" / f"{name}.h5") as a, RunFile(tmp_path / "b" / f"{name}.h5") as b:
        ta, tb = a.timeseries(), b.timeseries()
        assert set(ta) == set(tb) and list(ta["iteration"]) == [0, 5, 10, 15, 20]
        for k in ta:
            np.testing.assert_array_equal(ta[k], tb[k], err_msg=k)
        for f in parse_scene(text).output.fields:
            np.testing.assert_array_equal(a.read_field(20, f), b.read_field(20, f))
        assert a.meta["legs"] == 2


BAD = [
    (CHANNEL, ("position_m = [10.0, 8.0, 8.0]", "position_m = [1.0, 8.0, 8.0]"),
     ("bodies[0].position_m", "outside the domain", "position_m = [3, 8, 8]")),
    (CHANNEL, ('motion = "fixed"\n', 'motion = "fixed"\n\n[[bodies]]\nname = "b"\nshape = "box"\n'
                                     'size_m = [2.0, 2.0, 2.0]\nposition_m = [12.0, 8.0, 8.0]\nmotion = "fixed"\n'),
     ("bodies[1].position_m", "overlaps body 'post'", "position_m = [14.05, 8, 8]")),
    (CHANNEL, ('motion = "fixed"', 'motion = "free"'), ("bodies[0].density_kg_m3", "a free body needs its density")),
    (TANK, ('x_max = "wall"', 'x_max = "slip"'), ("domain.faces.x_max", "closed tank", 'x_max = "wall"')),
    (TANK, ("[[bodies]]", "[ship]\nspeed_m_s = 0.1\n\n[ice]\ncount = 1\n\n[[bodies]]"),
     ("bodies: a ship scene takes no extra [[bodies]]",)),
    (CHANNEL, ('motion = "fixed"', 'motion = "fixed"\noscillation = { amplitude_m = [0.0, 0.0, 1.0], period_s = 40.0 }'),
     ("bodies[0].oscillation", 'set motion = "prescribed"')),
]


@pytest.mark.parametrize("text, edit, needles", BAD, ids=["outside", "overlap", "no-density", "open-tank", "ship",
                                                          "oscillating-fixed"])
def test_bad_body_scenes_exit_2_with_one_line_and_write_nothing(tmp_path, main, text, edit, needles):
    assert edit[0] in text
    scene = tmp_path / "s.toml"
    scene.write_text(text.replace(*edit))
    rc, err = main(scene, "--output", tmp_path / "out")
    _one_line_error(rc, err, *needles)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_neutrally_buoyant_sphere_stays_put_and_a_heavy_one_falls_at_the_reduced_gravity():
    """Fluid only, closed box under gravity: the LBM carries no hydrostatic pressure, the coupling adds the
    buoyancy -rho_f V g. A sphere as dense as the fluid stays at rest (weight and buoyancy cancel; the flow it
    meets is none), one twice as dense starts falling at (1 - rho_f / rho_s) g = g / 2: after the first step its
    velocity is -g dt / 2 (the fluid force of a body at rest in fluid at rest is zero). The fluid force column
    holds the buoyancy."""
    text = """
[scene]
name = "neutral"
[domain]
cells = [16, 16, 16]
dx_m = 0.001
[fluid]
nu_m2_s = 1.0e-4
rho_kg_m3 = 1000.0
gravity_m_s2 = [0.0, 0.0, -9.81]
[numerics]
dt_s = 0.001
u_max_m_s = 0.01
precision = "float32"
[run]
steps = 10
[[bodies]]
name = "even"
shape = "sphere"
radius_m = 0.0025
position_m = [0.005, 0.008, 0.008]
density_kg_m3 = 1000.0
[[bodies]]
name = "heavy"
shape = "sphere"
radius_m = 0.0025
position_m = [0.011, 0.008, 0.008]
density_kg_m3 = 2000.0
"""
    model = build_model(parse_scene(text))
    model.step(1)
    row = model.diagnostics()
    g, dt = 9.81, model.dt_s
    buoyancy = 1000.0 * 4.0 / 3.0 * np.pi * 0.0025 ** 3 * g
    assert row["even_Fz_N"] == pytest.approx(buoyancy, rel=1e-6)
    assert row["heavy_vz_m_s"] == pytest.approx(-0.5 * g * dt, rel=1e-3)
    model.step(9)
    row = model.diagnostics()
    # the flow the heavy sphere drives reaches the other (measured 2 % of its speed); a buoyancy of the wrong
    # sign would pull the even one down at 2 g, faster than the heavy one
    assert abs(row["even_vz_m_s"]) < 0.05 * abs(row["heavy_vz_m_s"])
    assert row["heavy_vz_m_s"] < -5 * 0.5 * g * dt          # still falling, faster


def test_a_box_held_at_half_submergence_feels_archimedes():
    """Free surface: a 40 mm cube held fixed with its bottom 20 mm under the still level (faces on cell faces)
    feels rho g V_submerged = 1000 x 9.81 x 0.04 x 0.04 x 0.02 = 0.314 N from the water: the mean of the force
    over steps 20-300 within 3 % (measured +0.7 %; placing the cube starts a slosh of about 7 %, period about
    100 steps, so a single reading is not enough)."""
    text = TANK.replace("cells = [16, 16, 24]", "cells = [24, 24, 24]").replace(
        'size_m = [0.03, 0.03, 0.03]\nposition_m = [0.04, 0.04, 0.05]\ndensity_kg_m3 = 900.0',
        'size_m = [0.04, 0.04, 0.04]\nposition_m = [0.06, 0.06, 0.06]\nmotion = "fixed"')
    model = build_model(parse_scene(text))
    model.step(20)
    fz = []
    for _ in range(28):
        model.step(10)
        fz.append(model.diagnostics()["floe_Fz_N"])
    archimedes = 1000.0 * 9.81 * 0.04 * 0.04 * 0.02
    assert np.mean(fz) == pytest.approx(archimedes, rel=0.03)


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_the_body_examples_of_scenes_md_parse(k):
    from iceresist.scene.docs import BODY_EXAMPLES

    scene = parse_scene(BODY_EXAMPLES[k][1], "example.toml")
    assert scene.bodies and scene.optional_sections()[-1] == "bodies"


def test_the_refined_sphere_example_builds_with_the_sphere_on_level_1():
    """The refined example of docs/SCENES.md: level 1 covers the 27 blocks around the sphere (22 % of the uniform
    1 mm grid's cells, 10 level-1 cells per diameter), and a step runs."""
    from iceresist.models import BodiesModel, build_model
    from iceresist.scene.docs import BODY_EXAMPLES

    model = build_model(parse_scene(BODY_EXAMPLES[2][1], "example.toml"))
    assert isinstance(model, BodiesModel)
    assert model.units_finest.dx_m == pytest.approx(0.001)
    fine_equivalent = 80 * 40 * 40 * 8
    assert model.cells == (250 - 27) * 512 + 27 * 8 * 512 and model.cells < 0.23 * fine_equivalent
    model.step(1)
    assert model.diagnostics()["sphere_Fx_N"] != 0.0


def test_the_settling_sphere_example_regrids_as_the_validation_case():
    """The regridding example of docs/SCENES.md is ten Cate's E1 on two levels as
    iceresist.validate.cases.settling_sphere builds it (tests/test_settling.py, slow): the same octree, and its
    first 10 steps (a regrid at the 10th) give the sphere the same velocity to the bit."""
    from iceresist.models import BodiesModel, build_model
    from iceresist.scene.docs import BODY_EXAMPLES
    from iceresist.validate.cases.settling_sphere import scene as settling

    example = build_model(parse_scene(BODY_EXAMPLES[3][1], "example.toml"))
    case = build_model(settling("E1", 12, t_end_s=2.0, operator="bgk", levels=1))
    assert isinstance(example, BodiesModel) and example.regrid_every == 10
    assert np.array_equal(example.octree.coord, case.octree.coord)
    example.step(10)
    case.step(10)
    assert example.dem.velocities[0, 2] == case.dem.velocities[0, 2] < 0


def test_an_oscillation_is_the_time_derivative_of_its_displacement():
    """bodies[].oscillation: the velocity integrated over time is the displacement r(t) a sin(omega t) (to 1e-6 of
    the amplitude over the ramp and after), zero at the start with a ramp and a omega without one."""
    from iceresist.scene.schema import Oscillation

    osc = Oscillation(amplitude_m=(0.0, 0.5, 2.0), period_s=3.0, ramp_periods=1.5)
    t = np.linspace(0.0, 12.0, 120001)
    v = np.array([osc.velocity_m_s(x) for x in t])
    x = np.concatenate([[np.zeros(3)], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], axis=0)])
    exact = np.array([osc.displacement_m(s) for s in t])
    assert np.abs(x - exact).max() < 1e-6 * 2.0
    assert osc.velocity_m_s(0.0) == (0.0, 0.0, 0.0)
    assert exact[-1, 2] == pytest.approx(2.0 * np.sin(2 * np.pi * 12.0 / 3.0), abs=1e-12)
    jump = Oscillation(amplitude_m=(0.0, 0.0, 2.0), period_s=3.0, ramp_periods=0.0)
    assert jump.velocity_m_s(0.0)[2] == pytest.approx(2.0 * 2 * np.pi / 3.0)


def test_a_prescribed_body_follows_its_oscillation():
    """A prescribed sphere oscillating across the channel of CHANNEL (amplitude 1.5 cells, period 40 steps, ramp
    one period): its centre after 1 to 80 steps lies on position_m + the displacement of the oscillation (the DEM
    moves it at the velocity of each step's middle: measured 1.1e-3 of the amplitude, bound 3e-3; planted, the
    velocity at the step's start leaves it 0.079 of the amplitude off)."""
    text = CHANNEL.replace('motion = "fixed"', 'motion = "prescribed"\noscillation = { amplitude_m = [0.0, 1.5, 0.0], '
                                               'period_s = 40.0 }')
    scene = parse_scene(text, "s.toml")
    model = build_model(scene)
    osc, y0 = scene.bodies[0].oscillation, 8.0
    off = []
    for n in range(1, 81):
        model.step(1)
        off.append(model.dem.positions[0, 1] - (y0 + osc.displacement_m(float(n))[1]))
    assert np.abs(off).max() < 3e-3 * 1.5
