"""Ship presets as data: the case file, the scene text every case stores, the layering of scene and ship."""

import ast
import copy
import hashlib
import tomllib
from pathlib import Path

import pytest

from iceresist.ship import cases
from iceresist.scene.case_scenes import CASES, FIDELITIES, FIDELITY_NOTES, TIER2, case_scene, get_case, to_toml

ROOT = Path(__file__).resolve().parents[1]

# The CI-sized overrides of the sweep (iceresist.sweep TINY_OVERRIDES and TINY_TIER2_OVERRIDES when the presets
# became data), kept here so that the text they give stays pinned whatever the sweep does with them later.
TINY = {"ice": {"channel_length_m": 0.3}, "run": {"end_time_s": 0.75}, "contact": {"sample_interval_s": 0.002},
        "ship": {"steady_window_m": [4.1, 4.3], "sphere_band_m": 0.03, "sphere_spacing_m": 0.05}}
TINY_TIER2 = {
    "domain": {"cells": [64, 16, 16], "dx_m": 0.041 / 3},
    "free_surface": {"water_depth_m": 0.14},
    "fluid": {"nu_m2_s": 1.0e-5},
    "numerics": {"mach": 0.1, "precision": "float32"},
    "ship": {"length_m": 0.48, "beam_m": 0.08, "draught_m": 0.06, "parallel_length_m": 0.2, "start_x_m": 0.42,
             "sphere_spacing_m": 0.02, "sphere_band_m": 0.03, "steady_window_m": [0.43, 0.45]},
    "ice": {"concentration": None, "count": 4, "channel_length_m": 0.1, "channel_start_x_m": 0.42},
    "contact": {"sample_interval_s": 0.004},
    "run": {"end_time_s": 0.06},
}
OVERRIDES = {"none": {}, "tiny": TINY, "tiny2": TINY_TIER2}

# sha256 (first 32 hex digits) of the six cases' scene texts in CASES order, per (preset, tier, overrides): the
# text the presets wrote while they were Python. A result file stores it and the sweep's "same scene" check
# compares it byte for byte, so a change here turns every stored case into a new scene. The paper rows changed on
# 2026-11-26 with the paper preset's DEM sub-step (contact.dem_safety 0.2 -> 0.1: 0.2 ran away, docs/SHIP.md) and
# again with its dashpot (contact.dashpot = "face": A-c88-v1.0 ran away with the sphere-pair dashpot); the quick
# rows on 2026-12-07 with the same dashpot (A-c68-v1.0 on a 2.78 m channel ran away with the sphere-pair one).
SCENE_TEXT_SHA256 = {
    ("paper", 1, "none"): "3a02de0a2659907046aa1a9badbc3546",
    ("paper", 1, "tiny"): "767c37b145d8a213a602430bc6ba0441",
    ("paper", 2, "none"): "4dc70d7734fdb930f59c5fcfa3ddca64",
    ("paper", 2, "tiny"): "daf7bf1fd15d98578f4e90e379e6ea49",
    ("paper", 2, "tiny2"): "21c0c4dc9b24bf1bfb07788766c96acc",
    ("quick", 1, "none"): "9951c0b024e064db8a84e19b22f4166f",
    ("quick", 1, "tiny"): "56782430eb94e5b63b637006d8ba65ca",
    ("quick", 2, "none"): "6164a52b2723e04153f90b77ca36b1c0",
    ("quick", 2, "tiny"): "37d079fb0abe0d30398d7c01fe34120d",
    ("quick", 2, "tiny2"): "78ccd8a9bc74cfd81be4749cd7050fed",
}

QUICK_T1_A68 = """\
[scene]
name = "ship_quick_t1_A-c68-v1.0"
description = "B-063 Bow A, 68 % brash ice, 1 knots (0.514 m/s), quick fidelity, tier 1"

[domain]
size_m = [11.15, 1.39, 1.39]
dx_m = 0.010875
faces = { x_min = "wall", x_max = "wall", y_min = "wall", y_max = "wall", z_min = "wall", z_max = "wall" }

[fluid]
nu_m2_s = 1e-06
rho_kg_m3 = 1000.0
gravity_m_s2 = [0.0, 0.0, -9.81]

[numerics]
precision = "float64"
backend = "auto"

[run]
end_time_s = 2.801556

[output]
directory = "runs"
fields = []
timeseries_every_steps = 1

[free_surface]
water_depth_m = 1.11

[ship]
hull = "b063"
bow_angle_deg = 30.0
speed_m_s = 0.514
start_x_m = 3.95
tier = 1
sphere_spacing_m = 0.03
sphere_band_m = 0.06

[ice]
concentration = 0.68
channel_length_m = 1.39
channel_start_x_m = 4.0
spheres_per_edge = 2

[contact]
stiffness_N_m = 5000.0
dem_safety = 0.3
dashpot = "face"
sample_interval_s = 0.004
"""


def test_one_case_writes_the_scene_text_it_always_wrote():
    assert case_scene("A-c68-v1.0", "quick", 1).source_text == QUICK_T1_A68


@pytest.mark.parametrize("key", sorted(SCENE_TEXT_SHA256))
def test_every_case_writes_the_scene_text_it_always_wrote(key):
    preset, tier, overrides = key
    h = hashlib.sha256()
    for name in CASES:
        scene = case_scene(name, preset, tier, **copy.deepcopy(OVERRIDES[overrides]))
        assert tomllib.loads(scene.source_text)["scene"]["name"] == f"ship_{preset}_t{tier}_{name}"
        h.update(scene.source_text.encode())
    assert h.hexdigest()[:32] == SCENE_TEXT_SHA256[key]


def test_the_case_file_gives_the_paper_matrix():
    assert list(CASES) == ["A-c50-v1.0", "A-c68-v1.0", "A-c88-v1.0", "A-c68-v1.5", "A-c68-v2.0", "B-c68-v1.0"]
    c = get_case("B-c68-v1.0")
    assert (c.bow, c.concentration, c.knots, c.bow_angle_deg) == ("B", 0.68, 1.0, 45.0)
    assert get_case("A-c68-v2.0").speed_m_s == pytest.approx(2 * 0.514, rel=1e-15)
    assert set(FIDELITIES) == set(TIER2) == {"paper", "quick"}
    assert TIER2["paper"]["cells"] == (4104, 512, 512) and TIER2["paper"]["dx_m"] == 1.39 / 512
    assert TIER2["quick"]["dx_m"] == 1.39 / 104  # the data file's literal is this quotient exactly


def test_each_note_is_one_sentence():
    assert set(FIDELITY_NOTES) == {(p, t) for p in FIDELITIES for t in (1, 2)}
    for key, note in FIDELITY_NOTES.items():
        assert note.endswith(".") and ". " not in note and "\n" not in note, key


def test_a_broken_case_file_is_refused_naming_the_key(monkeypatch, tmp_path):
    text = (ROOT / "iceresist" / "ship" / "cases.toml").read_text(encoding="utf-8")
    bad = text.replace("dem_safety = 0.3", "dem_safety = -0.3")
    assert bad != text
    monkeypatch.setattr(cases, "resources", type("R", (), {"files": staticmethod(lambda _pkg: tmp_path)}))
    (tmp_path / cases.DATA_FILE).write_text(bad, encoding="utf-8")
    with pytest.raises(RuntimeError, match=r"fidelity\.quick\.dem_safety"):
        cases._load()


def test_to_toml_writes_scalars_by_tomli_w_and_reads_back():
    data = {"scene": {"name": "a\"b\\c", "description": "tab\there"},
            "domain": {"cells": [8, 8, 16], "faces": {"x_min": {"kind": "wall"}}, "dx_m": None},
            "run": {"end_time_s": 1e-06, "flag": True}}
    text = to_toml(data)
    assert "dx_m" not in text  # None leaves the key to its default
    back = tomllib.loads(text)
    del data["domain"]["dx_m"]
    assert back == data


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_ship_imports_nothing_from_the_scene_package():
    """The ship package (hull, ice, tank, the cases as data) sits below the scene package: the schema checks case
    names against iceresist.ship.cases, and iceresist.scene.case_scenes builds scenes from the cases on top of the schema.
    No import of the scene package hides in a function of ship (ast.walk sees every import, nested or not), and the
    schema, loader and writer do not import the presets."""
    for f in sorted((ROOT / "iceresist" / "ship").glob("*.py")):
        assert not {m for m in _imports(f) if m.startswith("iceresist.scene")}, f.name
    for name in ("schema.py", "load.py", "write.py", "__init__.py"):
        assert "iceresist.scene.case_scenes" not in _imports(ROOT / "iceresist" / "scene" / name), name
