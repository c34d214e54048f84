"""Your own ship in your own test matrix (docs/OWN_SHIP.md): the tank,
channel and window sized from the hull (B-063 keeps the presets' numbers, every hull gets the quick window in hull
lengths), the matrix's cases at model scale, refusals in one line, and a CI-sized matrix run to its report."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from iceresist import cli
from iceresist.errors import InputError
from iceresist.ship.cases import (CHANNEL_START_X_M, DOMAIN_M, FIDELITIES, KNOT_M_S, MIN_WINDOW_HULL_LENGTHS,
                                  TIER2, WATER_DEPTH_M, amr_fidelities, reference)
from iceresist.ship.hull import b063_hull
from iceresist.ship.sizing import SLACK_M, lattice_cells, size_case
from tests.test_refusals import _one_line
from validation.hull_forms import FORMS, form


@pytest.fixture(scope="module")
def hulls(tmp_path_factory):
    """The trial hulls of validation/hull_forms.py as STL files at 1:1 of their model."""
    d = tmp_path_factory.mktemp("hulls")
    for name in FORMS:
        form(name, nx=61, nz=12).export(d / f"{name}.stl")
    return d


# -- sizing -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("fidelity", list(FIDELITIES))
def test_b063_sized_by_the_rules_is_the_presets_tank(fidelity):
    """The rules of iceresist/ship/sizing.py give B-063 the numbers of cases.toml exactly: tank, depth, channel,
    tier-2 cells and refined level-0 cells."""
    h = b063_hull("A")
    t1 = size_case(h, reference(fidelity, 1))
    assert t1.tank_m == tuple(DOMAIN_M)
    assert t1.water_depth_m == WATER_DEPTH_M
    assert t1.channel_start_x_m == CHANNEL_START_X_M
    assert t1.channel_length_m == FIDELITIES[fidelity]["channel_length_m"]
    t2 = TIER2[fidelity]
    sized = size_case(h, reference(fidelity, 2))
    assert lattice_cells(sized.tank_m, t2["dx_m"]) == list(t2["cells"])
    assert (sized.water_depth_m, sized.channel_start_x_m) == (t2["water_depth_m"], t2["channel_start_x_m"])
    if fidelity in amr_fidelities():
        a = t2["amr"]
        sized = size_case(h, reference(fidelity, 2, amr=True))
        assert lattice_cells(sized.tank_m, a.get("dx_m") or t2["dx_m"], 8) == list(a["cells"])


def test_b063_windows_are_the_presets_defaults():
    """Quick: the window opens a bow length into the 1.39 m channel (0.784 m = 0.258 waterline lengths, the least
    any hull gets); paper: with the whole waterline in the 5.56 m channel."""
    h = b063_hull("A")
    q = size_case(h, reference("quick"))
    assert q.window_m == pytest.approx((4.0 + h.end_length_m, 5.39))
    assert MIN_WINDOW_HULL_LENGTHS == pytest.approx(0.7838 / 3.0404, rel=1e-4)
    p = size_case(h, reference("paper"))
    assert p.window_m == pytest.approx((4.0 + h.waterline_length_m, 9.56))


@settings(max_examples=200, deadline=None)
@given(length=st.floats(0.5, 12.0), beam_ratio=st.floats(0.05, 0.35), draught_ratio=st.floats(0.15, 1.2),
       end_fraction=st.floats(0.02, 0.5), overhang=st.floats(0.0, 0.15), fidelity=st.sampled_from(list(FIDELITIES)),
       tier=st.sampled_from([1, 2]), width=st.one_of(st.none(), st.floats(0.1, 5.0)))
def test_every_hull_gets_a_tank_that_holds_it_and_the_quick_window(length, beam_ratio, draught_ratio, end_fraction,
                                                                   overhang, fidelity, tier, width):
    """Any hull: the stern at the waterline starts as far inside the tank as B-063's (in waterline lengths), the channel ends before the fore wall, the water is deeper than
    the draught and the window at least MIN_WINDOW_HULL_LENGTHS waterline lengths; depth over draught and the
    blockage are the reference's (a wider channel only lowers the blockage). Planting the depth scaled by the beam
    instead of the draught fails here (B-063, whose ratios are all 1, cannot tell)."""
    lwl = length / (1.0 + overhang)
    hull = SimpleNamespace(length_overall_m=length, waterline_length_m=lwl, beam_m=beam_ratio * length,
                           draught_m=draught_ratio * beam_ratio * length, end_length_m=end_fraction * lwl)
    ref = reference(fidelity, tier)
    s = size_case(hull, ref, channel_width_m=width)
    assert s.start_x_m - lwl >= ref.aft_room_m / ref.waterline_length_m * lwl - SLACK_M
    assert s.end_x_m < s.tank_m[0]
    assert s.water_depth_m / hull.draught_m == pytest.approx(ref.water_depth_m / ref.draught_m, rel=1e-4)
    assert s.water_depth_m < s.tank_m[2]
    blockage = hull.beam_m * hull.draught_m / (s.tank_m[1] * s.water_depth_m)
    assert blockage <= ref.beam_m * ref.draught_m / (ref.tank_m[1] * ref.water_depth_m) * (1 + 1e-4)
    assert s.window_m[1] - s.window_m[0] >= MIN_WINDOW_HULL_LENGTHS * lwl - SLACK_M
    assert s.window_m[0] >= s.channel_start_x_m + hull.end_length_m - SLACK_M
    # the window the model will take by default from this channel (models/ship.py, steady_window_m) is the sized one
    lead_in = lwl if s.channel_length_m > lwl else hull.end_length_m
    assert s.window_m == pytest.approx((s.channel_start_x_m + lead_in, s.end_x_m), abs=SLACK_M)


def test_a_mesh_case_scene_is_sized_around_the_mesh(hulls, tmp_path):
    """The slender hull (3 m, beam 0.3 m, draught 0.19 m) in a [case] scene: a tank 1.39 x 0.3 / 0.7 wide with water
    1.11 x 0.19 / 0.44 deep, and a channel of a bow length (1.5 m) plus 0.258 waterline lengths; the description
    names the mesh."""
    from iceresist.scene.load import load_scene

    p = tmp_path / "slender.toml"
    p.write_text(f'[case]\nname = "A-c68-v1.0"\n[ship]\nhull = "mesh"\nmesh_file = "{hulls / "slender.stl"}"\n'
                 f"draught_m = 0.19\n")
    s = load_scene(p)
    assert s.domain.size_m[1] == pytest.approx(1.39 * 0.3 / 0.7, rel=1e-5)
    assert s.free_surface.water_depth_m == pytest.approx(1.11 * 0.19 / 0.44, rel=1e-5)
    assert s.ice.channel_length_m == pytest.approx(1.5 + MIN_WINDOW_HULL_LENGTHS * 3.0, abs=2e-3)
    assert "slender" in s.scene.description and "B-063" not in s.scene.description


def test_an_empty_default_window_is_refused_before_anything_is_written(hulls, tmp_path, monkeypatch, capsys):
    """The report's trial: the slender hull in the B-063 quick channel (1.39 m, shorter than its 1.5 m bow): its
    window would be empty; refused naming ice.channel_length_m and a length that works, nothing written."""
    monkeypatch.chdir(tmp_path)
    p = tmp_path / "short.toml"
    p.write_text(f'[case]\nname = "A-c68-v1.0"\n[ship]\nhull = "mesh"\nmesh_file = "{hulls / "slender.stl"}"\n'
                 f"draught_m = 0.19\n[ice]\nchannel_length_m = 1.39\n")
    before = {q.name for q in tmp_path.iterdir()}
    rc = cli.main(["run", str(p), "--backend", "cpu", "--no-progress"])
    line = _one_line(rc, capsys.readouterr().err, "ice.channel_length_m", "give ice.channel_length_m = 2.28")
    assert "steady window of -0.11 m" in line
    assert {q.name for q in tmp_path.iterdir()} == before


# -- the matrix ---------------------------------------------------------------------------------------------------
def test_a_matrix_runs_each_case_at_its_model_scale(hulls):
    """Full-scale values to model scale by Froude: 10 kn at 1:100 is 1 model knot, a 2 m piece 20 mm; the stern
    ahead turns the mesh's bow axis; every (end, scale) of the mesh is read once."""
    from iceresist.ship.matrix import HullSpec, matrix_from_flags

    hull = HullSpec(mesh=str(hulls / "slender.stl"), mesh_scale=25, draught_m=0.19)
    m = matrix_from_flags(hull, preset="quick", tier=1, concentration=[0.5, 0.68], speed_knots=[5, 10],
                          scale=[25, 100], ice_size_m=[2.0], ahead=["bow", "stern"])
    cases = m.cases()
    assert len(cases) == 16
    c = cases["c68-v10kn-s100-e2m-stern"]
    assert c.case.knots == pytest.approx(1.0) and c.case.speed_m_s == pytest.approx(KNOT_M_S)
    assert c.case.ice_size_m == pytest.approx(0.02) and c.case.scale == 100
    assert c.hull_keys["mesh_bow"] == "-x" and c.hull_keys["mesh_scale"] == pytest.approx(4.0)
    assert c.hull_keys["draught_m"] == pytest.approx(0.19 / 4)
    assert c.hull.draught_m == pytest.approx(0.0475) and c.hull.waterline_length_m == pytest.approx(0.75, rel=1e-3)
    assert cases["c50-v5kn-e2m"].hull_keys.get("mesh_scale", 1.0) == 1.0
    assert cases["c50-v5kn-e2m"].case.full_scale_knots == pytest.approx(5.0)


@pytest.mark.parametrize("argv, needles", [
    (["--knots", "-3"], ["--knots", "must be > 0"]),
    (["--concentration", "68"], ["--concentration", "a fraction in (0, 1]"]),
    (["--knots", "five"], ["--knots", "not a comma-separated list of numbers"]),
    (["--ahead", "sideways"], ["--ahead"]),
    (["--matrix", "m.toml", "--knots", "5"], ["--matrix", "drop --knots"]),
    (["--matrix", "nothere.toml"], ["--matrix", "cannot read"]),
    (["--matrix", "bad.toml"], ["bad.toml", "matrix.speed_knots", "Field required"]),
    (["--matrix", "typo.toml"], ["typo.toml", "matrix.sped_knots", "Extra inputs are not permitted"]),
    (["--mesh", "slender.stl", "--knots", "5"], ["hull.draught_m: missing"]),
])
def test_bad_matrix_input_is_one_line_and_nothing_is_written(argv, needles, hulls, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "slender.stl").write_bytes((hulls / "slender.stl").read_bytes())
    (tmp_path / "m.toml").write_text("[matrix]\nconcentration = 0.5\nspeed_knots = 5\n")
    (tmp_path / "bad.toml").write_text("[matrix]\nconcentration = 0.5\n")
    (tmp_path / "typo.toml").write_text("[matrix]\nconcentration = 0.5\nspeed_knots = 5\nsped_knots = 5\n")
    before = {q.name for q in tmp_path.iterdir()}
    rc = cli.main(["sweep", *argv, "--output", "out", "--no-progress"])
    _one_line(rc, capsys.readouterr().err, *needles)
    assert {q.name for q in tmp_path.iterdir()} == before


def test_a_ci_sized_matrix_gives_full_scale_fsicr_and_power_and_a_report_naming_the_hull(hulls, tmp_path,
                                                                                        monkeypatch, capsys):
    """The slender hull drawn at 1:25 run as a 1:100 model (0.75 m) at 5 kn, 68 %, with a 3 m propeller, from a
    matrix file: the table's full-scale resistance is the model mean x 100^3, R_CH is FSICR's for the mesh's
    inputs at 1:100, the powers are Ke (R/1000)^1.5 / Dp; a run's closing sentence gives the table's mean; the
    report's title names the hull and the matrix."""
    import fsicr
    from fsicr import formulas
    from iceresist.post.sweeptable import sweep_table
    from iceresist.ship.meshhull import MeshHull

    monkeypatch.chdir(tmp_path)
    (tmp_path / "trial.toml").write_text(
        f'[hull]\nmesh = "{hulls / "slender.stl"}"\nname = "Slender trial"\nmesh_scale = 25\ndraught_m = 0.19\n'
        f'propeller_diameter_m = 3.0\n[matrix]\nscale = 100\nconcentration = 0.68\nspeed_knots = 5\n')
    assert cli.main(["sweep", "--matrix", "trial.toml", "--backend", "cpu", "--output", "m", "--no-progress"]) == 0
    info = json.loads((tmp_path / "m" / "sweep.json").read_text())
    assert info["cases"] == ["c68-v5kn-s100"] and info["axes"]["scale"] == [100.0]
    row = sweep_table(tmp_path / "m").iloc[0]
    assert row.hull == "Slender trial" and row.scale == 100.0 and row.full_scale_knots == pytest.approx(5.0)
    assert row.speed_m_s == pytest.approx(5 * KNOT_M_S / 10, rel=1e-6)
    assert row.R_sim_kN == pytest.approx(row.mean_force_N * 100.0 ** 3 / 1e3, rel=1e-9)
    mesh = MeshHull.from_file(str(hulls / "slender.stl"), 0.0475, scale=4.0)
    r_ch = fsicr.r_ch(fsicr.Ship(name="x", **mesh.fsicr_inputs(100.0)), "IA").r_ch_N / 1e3
    assert row.R_CH_FSICR_kN == pytest.approx(r_ch, rel=1e-9)
    ke = formulas.ke(1, "cp")
    assert row.P_FSICR_kW == pytest.approx(ke * r_ch ** 1.5 / 3.0, rel=1e-9)
    assert row.P_sim_kW == pytest.approx(ke * max(row.R_sim_kN, 0.0) ** 1.5 / 3.0, rel=1e-9)
    assert math.isfinite(row.mean_force_N) and row.mean_force_N > 0
    from iceresist.post.case import window_summary

    said = window_summary(tmp_path / "m" / "cases" / "c68-v5kn-s100.h5")  # what `iceresist run` ends with
    assert f": {row.mean_force_N:.3g} +- {row.ci95_N:.2g} N at model scale" in said, said
    assert cli.main(["report", "m"]) == 0
    html = (tmp_path / "m" / "report.html").read_text()
    assert "<h1>Slender trial in a brash-ice channel: test matrix of 1 case</h1>" in html
    assert "model scale 1:100" in html and "resistance against speed" in html
    assert Path(tmp_path / "m" / "report.pdf").stat().st_size > 10_000
