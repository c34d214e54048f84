"""Bad input found by trying the tool as a new user and as an adversarial tester would (robustness, round 3):
each is refused through the command line in one line naming the key, exit status 2, and nothing is written."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from fsicr import cli as fsicr_cli
from iceresist import cli

LONG = "a" * 5000


def _run(argv, capsys, tool=cli):
    rc = tool.main([str(a) for a in argv])
    return rc, capsys.readouterr().err


def _one_line(rc, err, *needles):
    assert rc == 2, err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith(("INFO ", "WARNING "))]
    assert len(lines) == 1 and ": error: " in lines[0] and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    assert len(lines[0]) < 400, lines[0]        # a long input is shortened, not echoed whole
    return lines[0]


def _nothing_written(folder: Path, before: set):
    assert {p.name for p in folder.iterdir()} == before


def _mesh_scene(folder: Path, mesh_file: str, draught_m: float = 0.4, tank: str = "") -> Path:
    p = folder / "hull.toml"
    p.write_text(f'[case]\nname = "A-c68-v1.0"\n[ship]\nhull = "mesh"\nmesh_file = "{mesh_file}"\n'
                 f"draught_m = {draught_m}\n{tank}")
    return p


#: The paper's tank, given in the scene: a case's own tank is sized from the hull (docs/SHIP.md), this one is not.
PAPER_TANK = "[domain]\nsize_m = [11.15, 1.39, 1.39]\n[free_surface]\nwater_depth_m = 1.11\n"


def _box_stl(path: Path, extents, centre=(0.0, 0.0, 0.0)):
    import trimesh

    box = trimesh.creation.box(extents=extents)
    box.apply_translation(centre)
    box.export(path)
    return box


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


# -- paths the file system refuses -----------------------------------------------------------------------------
def test_a_mesh_path_too_long_for_the_file_system_is_one_line_in_fsicr(in_tmp, capsys):
    rc, err = _run(["resistance", "--mesh", LONG + ".stl", "--draught", "0.4"], capsys, fsicr_cli)
    _one_line(rc, err, "--mesh", "(5004 characters)", "File name too long")


def test_a_scene_mesh_path_too_long_for_the_file_system_is_one_line(in_tmp, capsys):
    scene = _mesh_scene(in_tmp, LONG + ".stl")
    rc, err = _run(["run", scene, "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "ship.mesh_file", "File name too long")
    _nothing_written(in_tmp, {"hull.toml"})


@pytest.mark.parametrize("argv, key", [
    (["run", "still_tank", "--output", LONG], "--output"),
    (["run", LONG + ".toml"], LONG[:20]),
    (["report", LONG], "too long"),
    (["validate", "--out", LONG], "--out"),
])
def test_every_path_too_long_for_the_file_system_is_one_line(in_tmp, capsys, argv, key):
    rc, err = _run(argv, capsys)
    _one_line(rc, err, key)
    _nothing_written(in_tmp, set())


# -- output.directory stays below the working folder ----------------------------------------------------------
def test_an_output_directory_that_climbs_out_of_the_working_folder_is_refused(tmp_path, monkeypatch, capsys):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    (work / "s.toml").write_text('[case]\nname = "A-c68-v1.0"\n[output]\ndirectory = "../../escape"\n')
    rc, err = _run(["run", "s.toml", "--steps", "0", "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "output.directory", "climbs out of the working folder", '"runs"')
    assert not (tmp_path / "escape").exists()
    (work / "s.toml").write_text(f'[case]\nname = "A-c68-v1.0"\n[output]\ndirectory = "{tmp_path / "abs"}"\n')
    rc, err = _run(["run", "s.toml", "--steps", "0", "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "output.directory", "not below the working folder", "--output")
    assert not (tmp_path / "abs").exists()


def test_an_output_directory_with_spaces_is_allowed_as_the_scene_docs_say():
    from iceresist.scene.docs import scenes_markdown
    from iceresist.scene.load import parse_scene

    text = (Path(__file__).resolve().parents[1] / "iceresist/scene/presets/still_tank.toml").read_text()
    scene = parse_scene(text.replace('directory = "runs"', 'directory = "my runs/case 1"'))
    assert scene.output.directory == "my runs/case 1"
    row = next(ln for ln in scenes_markdown().splitlines() if ln.startswith("| `output.directory`"))
    assert "not absolute, no `..`" in row and "letters, digits" not in row


# -- hull meshes that do not fit or are not one hull ---------------------------------------------------------
def test_a_mesh_of_two_disjoint_hulls_is_refused(in_tmp, capsys):
    import trimesh

    a = _box_stl(in_tmp / "a.stl", (3.0, 0.5, 0.6), (0.0, -0.4, 0.3))
    b = _box_stl(in_tmp / "b.stl", (3.0, 0.5, 0.6), (0.0, 0.4, 0.3))
    trimesh.util.concatenate([a, b]).export(in_tmp / "two.stl")
    rc, err = _run(["resistance", "--mesh", "two.stl", "--draught", "0.4"], capsys, fsicr_cli)
    _one_line(rc, err, "--mesh", "2 separate closed surfaces")
    rc, err = _run(["run", _mesh_scene(in_tmp, "two.stl"), "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "ship.mesh_file", "2 separate closed surfaces")
    assert not (in_tmp / "runs").exists()


def test_a_hull_wider_than_the_tank_is_refused_with_what_fits(in_tmp, capsys):
    _box_stl(in_tmp / "wide.stl", (3.0, 2.7, 0.6))
    rc, err = _run(["run", _mesh_scene(in_tmp, "wide.stl", tank=PAPER_TANK), "--steps", "0", "--no-progress"],
                   capsys)
    _one_line(rc, err, "ship.mesh_file", "2.7 m wide", "narrower than 1.39 m fits")
    assert not (in_tmp / "runs").exists()


def test_a_hull_drawing_more_than_the_water_depth_is_refused(in_tmp, capsys):
    _box_stl(in_tmp / "deep.stl", (3.0, 0.7, 1.3))
    rc, err = _run(["run", _mesh_scene(in_tmp, "deep.stl", draught_m=1.2, tank=PAPER_TANK), "--steps", "0",
                    "--no-progress"], capsys)
    _one_line(rc, err, "ship.draught_m", "water depth 1.11 m")


# -- a body below the smallest size the coupling resolves ------------------------------------------------------
def test_a_body_far_below_one_cell_is_refused_naming_the_smallest_size(in_tmp, capsys):
    (in_tmp / "dust.toml").write_text("""
[scene]
name = "dust"
[domain]
cells = [16, 16, 16]
dx_m = 0.001
[fluid]
nu_m2_s = 1.0e-4
[numerics]
dt_s = 0.001
u_max_m_s = 0.01
[run]
steps = 10
[[bodies]]
name = "dust"
shape = "sphere"
radius_m = 1e-9
position_m = [0.005, 0.008, 0.008]
density_kg_m3 = 1000.0
""")
    rc, err = _run(["run", "dust.toml", "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "bodies[0].radius_m", "use at least 0.001 m")
    _nothing_written(in_tmp, {"dust.toml"})


# -- a backend the machine lacks writes nothing ----------------------------------------------------------------
def test_validate_on_a_missing_gpu_makes_no_folder(in_tmp, capsys, monkeypatch):
    from iceresist.backends import jit

    monkeypatch.setattr(jit, "cuda_available", lambda: False)      # the tests run with the CUDA simulator on
    for extra in ([], ["--stability"]):
        rc, err = _run(["validate", "--backend", "cuda", "--out", "v", *extra], capsys)
        _one_line(rc, err, "--backend", "no CUDA GPU")
        _nothing_written(in_tmp, set())


# -- broken STL files ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("content, needle", [
    (np.random.default_rng(1).bytes(3000), "is not a whole binary STL"),
    (b"\0" * 80 + struct.pack("<I", 1000) + b"\0" * 500, "announces 1000 triangles (50084 bytes) but the file "
                                                            "holds 584 bytes"),
    (b"\0" * 40, "is not an STL: 40 bytes"),
])
def test_a_garbage_or_truncated_stl_is_named_with_what_is_wrong(in_tmp, capsys, content, needle):
    (in_tmp / "bad.stl").write_bytes(content)
    rc, err = _run(["resistance", "--mesh", "bad.stl", "--draught", "0.4"], capsys, fsicr_cli)
    _one_line(rc, err, "--mesh", "'bad.stl'", needle)
    rc, err = _run(["run", _mesh_scene(in_tmp, "bad.stl"), "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "ship.mesh_file", "'bad.stl'", needle)


def test_the_text_detection_trimesh_needs_is_installed():
    """trimesh reads an STL's first bytes with charset_normalizer, which it does not declare: a bad file then said
    "No module named 'charset_normalizer'" (pyproject.toml declares it)."""
    import importlib.metadata

    import charset_normalizer  # noqa: F401

    assert any(r.startswith("charset-normalizer") for r in importlib.metadata.requires("iceresist"))


# -- a name too long for the schema ----------------------------------------------------------------------------
def test_a_scene_name_too_long_gives_the_real_reason(in_tmp, capsys):
    (in_tmp / "n.toml").write_text(f'[case]\nname = "A-c68-v1.0"\n[scene]\nname = "{"n" * 10000}"\n')
    rc, err = _run(["run", "n.toml", "--steps", "0", "--no-progress"], capsys)
    _one_line(rc, err, "scene.name", "must be at most 100 characters (it has 10000)")
