"""Scene files: schema, one-line errors naming the key, presets, derived units."""

import pytest

from iceresist.errors import InputError, StabilityError
from iceresist.scene import load_scene, parse_scene, preset_names, preset_text
from iceresist.scene.schema import Scene

BASE = preset_text("poiseuille")


def _err(text) -> str:
    with pytest.raises(InputError) as exc:
        parse_scene(text)
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_presets_load_and_give_the_documented_numbers():
    assert {"cavity", "poiseuille"} <= set(preset_names())
    cav = load_scene("cavity")
    assert cav.is_lattice and cav.shape_cells() == (16, 16, 16)
    assert cav.units().tau == pytest.approx(0.8)
    assert cav.domain.faces.z_max.kind == "moving_wall" and cav.domain.faces.z_max.velocity_m_s == (0.05, 0, 0)
    assert cav.optional_sections() == []
    poi = load_scene("poiseuille")
    u = poi.units()
    assert poi.shape_cells() == (8, 8, 16)
    assert u.dt_s == pytest.approx(0.01) and u.tau == pytest.approx(0.53)
    assert poi.rho_kg_m3 == 1000.0
    assert "[scene]" in poi.source_text


def test_load_scene_from_a_file(tmp_path):
    p = tmp_path / "mine.toml"
    p.write_text(BASE)
    s = load_scene(p)
    assert s.scene.name == "poiseuille" and s.source_name == str(p)


@pytest.mark.parametrize("edit, expected", [
    (("dx_m = 0.001", "dx_m = -1"), "scene.toml: domain.dx_m: must be > 0 (got -1)"),
    (("dx_m = 0.001", "dx_m = 0.001\ndxx = 3"), "scene.toml: domain.dxx: unknown key (allowed: size_m, cells, dx_m, faces, pad_to_blocks)"),
    (("[fluid]", "[fluids]"), "scene.toml: fluids: unknown key (allowed: scene, domain, fluid,"),
    (("nu_m2_s = 1.0e-6", 'nu_m2_s = "water"'), 'scene.toml: fluid.nu_m2_s: must be a number (got "water")'),
    (('x_min = "periodic"', 'x_min = "periodc"'), "domain.faces.x_min.kind: must be one of 'periodic', 'wall'"),
    (('x_min = "periodic"', 'x_min = "wall"'), "domain.faces.x_min: periodic faces come in pairs"),
    (("size_m = [0.008, 0.008, 0.016]", "size_m = [0.008, 0.008]"), "domain.size_m: must have 3 items (got [0.008, 0.008])"),
    (("size_m = [0.008, 0.008, 0.016]", "size_m = [0.008, -1, 0.016]"), "domain.size_m[1]: must be > 0 (got -1)"),
    (("end_time_s = 20.0", ""), "run.steps: give steps or end_time_s"),
    (("end_time_s = 20.0", "steps = 2.5"), "run.steps: must be an integer (got 2.5)"),
    (("end_time_s = 20.0", "steps = -3"), "run.steps: must be >= 0 (got -3)"),
    (("[numerics]", "[numerics]\ntau = 0.6"), "numerics.tau: only lattice-unit scenes give tau"),
    (("[numerics]", '[numerics]\nprecision = "float16"'), "numerics.precision: must be one of 'float32' or 'float64'"),
    (("[numerics]", "[numerics]\nmach = 0.5"), "numerics.mach: must be <= 0.3 (got 0.5)"),
    (('name = "poiseuille"', 'name = "a b"'), "scene.name: must start with a letter, digit or '_' and hold only letters"),
    (('z_max = "wall"', 'z_max = { kind = "wall", velocity_m_s = [1, 0, 0] }'),
     "domain.faces.z_max.velocity_m_s: only a moving_wall or velocity_inlet face has a velocity"),
    (('z_max = "wall"', 'z_max = { kind = "moving_wall", velocity_m_s = [0, 0, 0.01] }'),
     "domain.faces.z_max: a moving_wall slides in its own plane: velocity_m_s[2] must be 0"),
    (("fields_every_s = 5.0", 'fields = ["rho", "vorticity"]'), "output.fields[1]: must be one of"),
    (("fields_every_s = 5.0", "fields_every_s = 5.0\nfields_every_steps = 3"),
     "output.fields_every_s: give at most one"),
    (("dx_m = 0.001", ""), "domain.dx_m: size_m needs the cell size dx_m"),
    (("nu_m2_s = 1.0e-6", ""), "fluid.nu_m2_s: a physical scene needs the viscosity"),
    (("dx_m = 0.001", "dx_m = 0.001\ncells = [8, 8, 16]"), "domain.cells: give exactly one of cells and size_m"),
])
def test_every_error_is_one_line_naming_the_key(edit, expected):
    old, new = edit
    assert old in BASE
    assert expected in _err(BASE.replace(old, new, 1))


def test_toml_syntax_error_gives_the_line():
    msg = _err(BASE.replace("dx_m = 0.001", "dx_m = = 0.001"))
    assert msg.startswith("scene.toml: TOML syntax error:") and "line 11" in msg


def test_missing_section_and_file_errors(tmp_path):
    assert _err(BASE.replace("[run]\nend_time_s = 20.0", "")) == "scene.toml: run: required key is missing"
    with pytest.raises(InputError, match="no such scene file"):
        load_scene(tmp_path / "nope.toml")
    with pytest.raises(InputError, match="not a file"):
        load_scene(tmp_path)
    bad = tmp_path / "bin.toml"
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(InputError, match="cannot read"):
        load_scene(bad)


def test_unstable_settings_are_refused_at_load():
    with pytest.raises(StabilityError, match="below the floor"):
        parse_scene(BASE.replace("nu_m2_s = 1.0e-6", "nu_m2_s = 1.0e-16"))
    with pytest.raises(StabilityError, match="above the limit 0.1"):
        parse_scene(BASE.replace("[numerics]", "[numerics]\ndt_s = 0.5"))
    cav = preset_text("cavity")
    with pytest.raises(StabilityError, match=r"domain.faces.z_max.velocity_m_s = 0.2 \(the largest speed in the scene\) is 0.2"):
        parse_scene(cav.replace("velocity_m_s = [0.05, 0.0, 0.0]", "velocity_m_s = [0.2, 0.0, 0.0]"))


def test_lattice_scene_rules():
    cav = preset_text("cavity")
    assert "numerics.tau: a lattice-unit scene gives exactly one" in _err(
        cav.replace('precision = "float32"', 'precision = "float32"\ntau = 0.8'))
    assert "domain.dx_m: a lattice-unit scene has dx_m = 1" in _err(
        cav.replace("cells = [16, 16, 16]", "cells = [16, 16, 16]\ndx_m = 0.01"))
    s = parse_scene(cav.replace("nu_m2_s = 0.1", "").replace('precision = "float32"', 'precision = "float32"\ntau = 0.56'))
    assert s.units().nu_m2_s == pytest.approx(0.02)


FULL = BASE + """
[free_surface]
water_depth_m = 0.012

[ship]
speed_m_s = 0.514
bow_angle_deg = 45

[ice]
concentration = 0.68
seed = 7

[contact]
stiffness_N_m = 2.0e4

[[bodies]]
name = "post"
shape = "box"
size_m = [0.002, 0.002, 0.004]
position_m = [0.004, 0.004, 0.008]
motion = "fixed"
"""


def test_optional_sections_parse_and_default_to_absent():
    plain = parse_scene(BASE)
    assert plain.free_surface is None and plain.ship is None and plain.ice is None and plain.contact is None
    assert plain.bodies == []
    s = parse_scene(FULL.replace("[fluid]", "[fluid]\ngravity_m_s2 = [0.0, 0.0, -9.81]"))
    assert s.optional_sections() == ["free_surface", "ship", "ice", "contact", "bodies"]
    assert s.ship.bow_angle_deg == 45 and s.ice.size_m == 0.041 and s.ice.density_kg_m3 == 950
    assert s.contact.restitution == 0.3 and s.bodies[0].name == "post"
    # the ship (0.514 m/s) is faster than the waves sqrt(g h) = 0.343 m/s and the 0.01 m/s flow: it sets dt
    assert s.units().dt_s == pytest.approx(0.1 * 0.001 / 0.514)


def test_optional_section_rules():
    assert "fluid.gravity_m_s2: a free surface needs gravity" in _err(FULL)
    fs = FULL.replace("[fluid]", "[fluid]\ngravity_m_s2 = [0.0, 0.0, -9.81]")
    assert "ice.concentration: give exactly one of concentration and count" in _err(
        fs.replace("concentration = 0.68", "concentration = 0.68\ncount = 10"))
    assert "ice.concentration: must be <= 1 (got 1.5)" in _err(fs.replace("concentration = 0.68", "concentration = 1.5"))
    assert "ship.speed_m_s: required key is missing" in _err(fs.replace("speed_m_s = 0.514", ""))
    assert "ship.bow_angle_deg: must be < 90 (got 95)" in _err(fs.replace("bow_angle_deg = 45", "bow_angle_deg = 95"))
    assert "bodies[0].radius_m: a sphere needs radius_m" in _err(fs.replace('shape = "box"', 'shape = "sphere"'))
    assert "bodies[0].colour: unknown key" in _err(fs + 'colour = "red"\n')


def schema_keys() -> list[str]:
    """Every key of the schema, dotted (``domain.dx_m``, ``domain.faces.<face>.kind``, ``bodies[].name``)."""
    from iceresist.scene.docs import SECTIONS

    keys = [prefix for _, _, prefix in SECTIONS]
    for _, model, prefix in SECTIONS:
        keys += [f"{prefix}.{name}" for name in model.model_fields]
    return keys


def test_every_schema_key_is_documented():
    from pathlib import Path

    from iceresist.scene.docs import FULL_EXAMPLE, reference_markdown, scenes_markdown

    doc = (Path(__file__).resolve().parents[1] / "docs" / "SCENES.md").read_text()

    for key in schema_keys():
        assert f"`{key}`" in doc, key
    assert len(schema_keys()) > 60
    assert reference_markdown() in doc
    assert doc == scenes_markdown(), "regenerate: python -m iceresist.scene.docs > docs/SCENES.md"
    full = parse_scene(FULL_EXAMPLE)
    assert isinstance(full, Scene) and full.optional_sections() == ["free_surface", "ship", "ice", "contact"]


CASE_SCENE = """
[case]
name = "B-c68-v1.0"
fidelity = "quick"
tier = 2

[scene]
name = "finer"

[domain]
cells = [504, 136, 104]
dx_m = 0.0102

[ice]
channel_length_m = 2.78
"""


def test_case_section_starts_from_a_ship_case_and_changes_only_the_keys_given():
    """A [case] scene is the preset's case with the keys the file names replaced, the others kept: the same
    Scene as case_scene with those overrides."""
    from iceresist.scene.case_scenes import case_scene

    scene = parse_scene(CASE_SCENE)
    ref = case_scene("B-c68-v1.0", "quick", 2, scene={"name": "finer"},
                     domain={"cells": [504, 136, 104], "dx_m": 0.0102}, ice={"channel_length_m": 2.78})
    assert scene.model_dump(exclude={"case"}) == ref.model_dump(exclude={"case"})
    assert (scene.case.name, scene.case.fidelity, scene.case.tier) == ("B-c68-v1.0", "quick", 2)
    assert scene.ship.bow_angle_deg == 45.0 and scene.ice.concentration == 0.68 and scene.ice.channel_length_m == 2.78
    assert scene.domain.faces.x_min.kind == "wall" and scene.free_surface.water_depth_m == 0.9  # kept from the case
    assert scene.scene.description.startswith("B-063 Bow B")
    assert scene.source_text == CASE_SCENE  # the result file keeps what the user wrote
    from textwrap import dedent

    from iceresist.scene.docs import INTRO

    example = parse_scene(dedent(INTRO[INTRO.index("    [case]"):INTRO.index("(`validation/scenes/`")]))
    assert example.domain.cells == (504, 136, 104) and example.ice.concentration == 0.68  # the docs' example


@pytest.mark.parametrize("edit, expected", [
    (('name = "B-c68-v1.0"', 'name = "B-c60-v1.0"'), "case.name: unknown case 'B-c60-v1.0'; known cases: A-c50-v1.0"),
    (("tier = 2", "tier = 3"), "case.tier: must be one of 1 or 2 (got 3)"),
    (('fidelity = "quick"', 'fidelity = "fast"'), "case.fidelity: must be one of 'paper' or 'quick' (got \"fast\")"),
    (("tier = 2", "tier = 2\nbow = \"B\""), "case.bow: unknown key (allowed: name, fidelity, tier, amr)"),
    (('name = "B-c68-v1.0"\n', ""), "case.name: required key is missing"),
    (("[ice]\nchannel_length_m = 2.78", "[ice]\nchannel_length_m = -1"), "ice.channel_length_m: must be > 0 (got -1)"),
])
def test_case_section_errors_are_one_line_naming_the_key(edit, expected):
    assert expected in _err(CASE_SCENE.replace(*edit))


def test_validation_scenes_load():
    """The scene files of validation/scenes (resolution and channel-length studies of the quick tier-2 case)
    still load against the presets they start from."""
    from pathlib import Path

    files = sorted((Path(__file__).resolve().parents[1] / "validation" / "scenes").glob("*.toml"))
    assert len(files) >= 4
    for f in files:
        scene = load_scene(f)
        assert scene.case is not None and scene.case.tier == 2 and scene.ship is not None, f.name


@pytest.mark.parametrize("name", ["cavity", "dam_break", "poiseuille", "still_tank"])
def test_built_in_scenes_round_trip_through_the_writer(name):
    """TOML -> dict -> iceresist.scene.write.to_toml -> the same Scene (and the same dict)."""
    import tomllib

    from iceresist.scene.write import to_toml

    data = tomllib.loads(preset_text(name))
    text = to_toml(data)
    assert tomllib.loads(text) == data
    assert parse_scene(text).model_dump() == load_scene(name).model_dump()


def test_case_scenes_round_trip_through_their_stored_text():
    from iceresist.scene.case_scenes import CASES, case_scene

    for case in CASES:
        for preset in ("paper", "quick"):
            for tier in (1, 2):
                scene = case_scene(case, preset, tier)
                assert parse_scene(scene.source_text).model_dump() == scene.model_dump(), (case, preset, tier)
