"""``iceresist run``: exit codes and one-line errors, overwrite protection, result files (fake model)."""

import argparse
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from iceresist import cli
from iceresist.errors import InputError
from iceresist.io import RunFile
from iceresist.models.base import Model
from iceresist.run import add_run_arguments
from iceresist.scene import preset_text
from iceresist.units import Units

POISEUILLE = preset_text("poiseuille")


def _parser():
    """The CLI parser with the ``run`` subcommand (as wired in iceresist/cli.py)."""
    p = _original_build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    if "run" not in sub.choices:
        add_run_arguments(sub.add_parser("run", help="run one scene file"))
    return p


_original_build_parser = cli.build_parser


@pytest.fixture
def main(monkeypatch, capsys):
    monkeypatch.setattr(cli, "build_parser", _parser)

    def run(*argv):
        try:
            rc = cli.main(["run", *map(str, argv), "--no-progress"])
        except SystemExit as exc:  # argparse usage errors
            rc = exc.code
        out = capsys.readouterr()
        return rc, out.err

    return run


def _one_line_error(rc, err, *needles):
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("iceresist") and ": error: " in lines[0], err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]


@pytest.mark.parametrize("edit, needle", [
    (("dx_m = 0.001", "dx_m = -1"), "domain.dx_m: must be > 0 (got -1)"),
    (("dx_m = 0.001", "dx_m = 1e-287"), "domain.dx_m: 1e-287 gives about 1e855 cells, beyond any machine"),
    (("dx_m = 0.001", "dx_m = = 1"), "TOML syntax error"),
    (("[fluid]", "[fluid]\nviscosity = 1"), "fluid.viscosity: unknown key"),
    (("nu_m2_s = 1.0e-6", 'nu_m2_s = "water"'), "fluid.nu_m2_s: must be a number"),
    (("nu_m2_s = 1.0e-6", "nu_m2_s = 1.0e-16"), "below the floor"),
    (("size_m = [0.008, 0.008, 0.016]", "size_m = [0.008, 0.008, 0.012]"), "12 cells along z is not a multiple of 8"),
    (("size_m = [0.008, 0.008, 0.016]", "size_m = [0.004, 0.008, 0.016]"), "along x is not a multiple of 8 (blocks of "
                                                                          "8x8x8 cells): use 8 cells"),
    (("nu_m2_s = 1.0e-6", "nu_m2_s = inf"), "fluid.nu_m2_s: input should be a finite number (got inf)"),
    (("nu_m2_s = 1.0e-6", "nu_m2_s = nan"), "fluid.nu_m2_s: input should be a finite number (got nan)"),
    (("[run]", "[ship]\nspeed_m_s = 0.01\n\n[run]"), "[ship] need the free-surface, DEM and coupling engine"),
])
def test_bad_scenes_exit_2_with_one_line(tmp_path, main, edit, needle):
    p = tmp_path / "s.toml"
    p.write_text(POISEUILLE.replace(*edit))
    rc, err = main(p, "--output", tmp_path / "out")
    _one_line_error(rc, err, str(p), needle) if "multiple of 8" not in needle else _one_line_error(rc, err, needle)
    assert not (tmp_path / "out" / "poiseuille.h5").exists()


@pytest.mark.parametrize("edit, needle", [
    (('name = "poiseuille"', 'name = ".."'), "scene.name: must start with a letter, digit or '_'"),
    (('[output]', '[output]\ndirectory = ""'), "output.directory: must not be empty"),
    (('[output]', '[output]\ndirectory = "  "'), "output.directory: must not be blank"),
    (("size_m = [0.008, 0.008, 0.016]", "cells = [4096, 4096, 4096]"), "domain: 4096x4096x4096 cells need at least"),
])
def test_bad_names_folders_and_sizes_exit_2_before_anything_is_built(tmp_path, main, edit, needle, monkeypatch):
    monkeypatch.chdir(tmp_path)
    p = tmp_path / "s.toml"
    p.write_text(POISEUILLE.replace(*edit))
    assert edit[0] in POISEUILLE
    rc, err = main(p)
    _one_line_error(rc, err, needle)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["s.toml"]


def test_memory_check_names_a_size_that_fits():
    from iceresist.limits import check_memory
    from iceresist.scene import load_scene

    scene = load_scene("poiseuille")                      # 8 x 8 x 16 cells: 221 kB of float32 populations
    check_memory(scene, "float32", available=2 ** 20)
    with pytest.raises(InputError, match=r"domain: 8x8x16 cells need at least 0.000206 GiB .* use at most 925 cells \(e.g. 8x8x8"):
        check_memory(scene, "float32", available=200_000)


def test_output_folders_that_cannot_hold_a_result_exit_2_and_keep_what_is_there(tmp_path, main):
    (tmp_path / "f").write_text("keep")
    _one_line_error(*main("poiseuille", "--output", tmp_path / "f"), "--output:", "is a file, not a folder")
    _one_line_error(*main("poiseuille", "--output", tmp_path / "f" / "sub"), "--output:", "which is a file")
    _one_line_error(*main("poiseuille", "--output", ""), "--output: empty")
    _one_line_error(*main("poiseuille", "--output", "/proc/iceresist/out"), "--output:", "cannot be made")
    assert (tmp_path / "f").read_text() == "keep"
    assert not __import__("os").path.exists("/proc/iceresist")


def test_missing_file_and_bad_flags(tmp_path, main):
    _one_line_error(*main(tmp_path / "nope.toml"), "no such scene file", "cavity")
    _one_line_error(*main("poiseuille", "--steps", "-1", "--output", tmp_path), "--steps: must be >= 0")
    _one_line_error(*main("poiseuille", "--precision", "float16"), "invalid choice")
    _one_line_error(*main("poiseuille", "--pickup", "--output", tmp_path), "no result to continue")


class FakeFluid(Model):
    """Stands in for FluidModel: the model contract plus what run.py reads (units, shape, target, precision)."""

    components = ("fluid",)
    iteration = 0

    def __init__(self, scene, backend=None, precision=None):
        self.units = scene.units()
        self.shape_cells = scene.shape_cells()
        self.cells = int(np.prod(self.shape_cells))
        self.precision = precision or scene.numerics.precision
        self.target = argparse.Namespace(name="cpu")
        self.dt_s = self.units.dt_s
        self.iteration = 0
        self.u = np.zeros(self.shape_cells + (3,))

    def step(self, n=1):
        for _ in range(n):
            self.iteration += 1
            self.u[..., 0] += 1e-4 * np.sin(np.pi * (np.arange(self.shape_cells[2]) + 0.5) / self.shape_cells[2])

    def fields(self):
        return {"rho": np.full(self.shape_cells, 1000.0), "u": self.u.copy(), "pressure": np.zeros(self.shape_cells),
                "flags": np.ones(self.shape_cells, np.uint8)}

    @staticmethod
    def field_units(lattice):
        return {"rho": "kg/m^3", "u": "m/s", "pressure": "Pa", "flags": "bits"}

    def diagnostics(self):
        return {"max_speed_m_s": float(np.abs(self.u).max())}

    def state(self):
        return {"u": self.u.copy(), "iteration": np.int64(self.iteration)}

    def load_state(self, d):
        self.u, self.iteration = np.array(d["u"]), int(d["iteration"])

    def describe(self):
        return {"components": ["fluid"], "backend": "cpu", "precision": self.precision}

    def watchdog_probe(self):
        return {"finite": (self.is_finite(), None)}

    def allocation(self):
        return {"u": self.u.nbytes}


@pytest.fixture
def fake_model(monkeypatch):
    import iceresist.run

    monkeypatch.setattr(iceresist.run, "build_model", lambda scene, **kw: FakeFluid(scene, **kw))


def test_run_writes_result_meta_fields_and_xdmf(tmp_path, main, fake_model):
    rc, err = main("poiseuille", "--output", tmp_path, "--steps", "1200")
    assert rc == 0, err
    h5 = tmp_path / "poiseuille.h5"
    with RunFile(h5) as rf:
        m = rf.meta
        assert m["scene_name"] == "poiseuille" and m["scene_toml"] == POISEUILLE
        assert m["steps"] == 1200 and m["iteration"] == 1200 and m["cells"] == 8 * 8 * 16
        assert m["stop_reason"] == "stop iteration 1200 reached" and not m["diverged"] and m["finished"]
        assert m["wall_time_s"] > 0 and m["mlups"] > 0 and m["precision"] == "float32"
        assert '"dt_s": 0.01' in m["units"]
        # fields every 5 s of simulated time = every 500 steps of 0.01 s, and the end
        assert rf.snapshot_iterations() == [0, 500, 1000, 1200]
        assert rf.read_field(1200, "u")[3, 3, 8, 0] == pytest.approx(1200 * 1e-4 * np.sin(np.pi * 8.5 / 16), rel=1e-6)
        assert rf.h5["fields/0000001200/u"].attrs["units"] == "m/s"
        assert rf.timeseries()["iteration"][-1] == 1200
    grids = ET.parse(tmp_path / "poiseuille.xdmf").getroot().findall("Domain/Grid/Grid")
    assert len(grids) == 4
    assert grids[-1].find("Topology").get("Dimensions") == "17 9 9"
    assert (tmp_path / "poiseuille.checkpoint.h5").is_file()


def test_existing_result_is_kept_unless_force(tmp_path, main, fake_model):
    assert main("poiseuille", "--output", tmp_path, "--steps", "10")[0] == 0
    h5 = tmp_path / "poiseuille.h5"
    before = h5.read_bytes()
    _one_line_error(*main("poiseuille", "--output", tmp_path, "--steps", "20"), "already exists", "--force")
    assert h5.read_bytes() == before
    # --force with a start that fails (cells not a multiple of 8 is caught before any file is opened)
    bad = tmp_path / "bad.toml"
    bad.write_text(POISEUILLE.replace("[0.008, 0.008, 0.016]", "[0.008, 0.008, 0.015]"))
    import iceresist.run

    iceresist.run.build_model = _real_build_model  # restored by monkeypatch at teardown
    _one_line_error(*main(bad, "--output", tmp_path, "--force"), "multiple of 8")
    assert h5.read_bytes() == before
    _one_line_error(*main("poiseuille", "--output", tmp_path, "--force", "--pickup"), "exclude each other")


from iceresist.models import build_model as _real_build_model  # noqa: E402


def test_three_legs_are_all_on_record(tmp_path, main, fake_model):
    """Two continuations of one result: legs_json holds every leg, with the iteration each started from."""
    import json

    assert main("poiseuille", "--output", tmp_path, "--steps", "300")[0] == 0
    assert main("poiseuille", "--output", tmp_path, "--steps", "600", "--pickup")[0] == 0
    assert main("poiseuille", "--output", tmp_path, "--steps", "900", "--pickup")[0] == 0
    with RunFile(tmp_path / "poiseuille.h5") as rf:
        m = rf.meta
    assert m["legs"] == 3 and m["steps"] == 900
    assert [(g["leg"], g["from_iteration"]) for g in json.loads(m["legs_json"])] == [(1, 0), (2, 300), (3, 600)]


def test_pickup_continues_a_result(tmp_path, main, fake_model):
    assert main("poiseuille", "--output", tmp_path, "--steps", "700")[0] == 0
    assert main("poiseuille", "--output", tmp_path, "--steps", "1200", "--pickup")[0] == 0
    assert main("poiseuille", "--output", tmp_path / "straight", "--steps", "1200")[0] == 0
    with RunFile(tmp_path / "poiseuille.h5") as a, RunFile(tmp_path / "straight" / "poiseuille.h5") as b:
        assert a.snapshot_iterations() == [0, 500, 700, 1000, 1200]
        assert np.array_equal(a.read_field(1200, "u"), b.read_field(1200, "u"))
        assert a.meta["steps"] == 1200 and a.meta["iteration"] == 1200


def test_a_pickup_where_a_snapshot_was_due_does_not_write_it_again(tmp_path, main, fake_model):
    """Picked up at iteration 1000, where the fields (every 500 steps) were due and written by the leg before: the
    next snapshot is at 1200 (the stop), not at 1001, and the time series has no row twice. Planted: the time
    schedules left as they are at a pickup (a snapshot at 1001) fails."""
    assert main("poiseuille", "--output", tmp_path, "--steps", "1000")[0] == 0
    assert main("poiseuille", "--output", tmp_path, "--steps", "1200", "--pickup")[0] == 0
    with RunFile(tmp_path / "poiseuille.h5") as a:
        assert a.snapshot_iterations() == [0, 500, 1000, 1200]
        its = a.timeseries()["iteration"]
        assert len(its) == len(set(its.tolist()))


@pytest.mark.parametrize("damage", ["truncated", "empty", "random"])
def test_pickup_from_a_bad_checkpoint_leaves_the_result_as_it_was(tmp_path, main, fake_model, damage):
    """A checkpoint that cannot be read is refused in one line before the finished result is opened."""
    assert main("poiseuille", "--output", tmp_path, "--steps", "20")[0] == 0
    h5, chk = tmp_path / "poiseuille.h5", tmp_path / "poiseuille.checkpoint.h5"
    data = chk.read_bytes()
    chk.write_bytes({"truncated": data[: len(data) // 2], "empty": b"",
                     "random": np.random.default_rng(3).bytes(4096)}[damage])
    before = h5.read_bytes()
    _one_line_error(*main("poiseuille", "--output", tmp_path, "--steps", "40", "--pickup"), str(chk))
    assert h5.read_bytes() == before


def test_pickup_after_an_interrupt_reports_the_steps_and_wall_time_it_kept(tmp_path, main, monkeypatch):
    """Interrupted at iteration 650 with a checkpoint at 500, then continued to 1200: the result counts 1200
    steps (not 650 + 700), two legs, and the wall time up to the checkpoint plus the second leg's. It is
    finished only after a leg that reached its stop criterion: not after the interrupt, and not again once a
    third leg towards 1500 is interrupted."""
    import iceresist.run

    class Interrupted(FakeFluid):
        at = 650

        def step(self, n=1):
            if Interrupted.at is not None and self.iteration >= Interrupted.at:
                Interrupted.at = None
                raise KeyboardInterrupt
            super().step(n)

    monkeypatch.setattr(iceresist.run, "build_model", lambda scene, **kw: Interrupted(scene, **kw))
    scene = tmp_path / "poiseuille.toml"
    scene.write_text(POISEUILLE + "checkpoint_every_steps = 500\n")
    rc, err = main(scene, "--output", tmp_path, "--steps", "1200")
    assert rc == 130 and "interrupted" in err
    with RunFile(tmp_path / "poiseuille.h5") as rf:
        m = rf.meta
        assert (m["checkpoint_iteration"], m["steps"], m["stop_reason"]) == (500, 650, "interrupted")
        assert not m["finished"]
        kept_s, first_leg_s = m["checkpoint_wall_s"], m["wall_time_s"]
    assert 0 < kept_s <= first_leg_s
    assert main(scene, "--output", tmp_path, "--steps", "1200", "--pickup")[0] == 0
    with RunFile(tmp_path / "poiseuille.h5") as rf:
        m = rf.meta
        assert (m["steps"], m["iteration"], m["legs"]) == (1200, 1200, 2) and m["finished"]
        assert m["checkpoint_iteration"] == 1200  # the final checkpoint of the second leg
        assert kept_s < m["wall_time_s"] < kept_s + m["checkpoint_wall_s"]
        np.testing.assert_array_equal(rf.timeseries()["iteration"], np.arange(0, 1201, 10))  # 510-650 once
    Interrupted.at = 1300  # continued past its earlier end and stopped short of the new one
    assert main(scene, "--output", tmp_path, "--steps", "1500", "--pickup")[0] == 130
    with RunFile(tmp_path / "poiseuille.h5") as rf:
        assert (rf.meta["stop_reason"], rf.meta["legs"], bool(rf.meta["finished"])) == ("interrupted", 3, False)
        legs = rf.meta_object("legs_json")
    assert [(g["leg"], g["from_iteration"], g["backend"]) for g in legs] == [(1, 0, "cpu"), (2, 500, "cpu"),
                                                                             (3, 1200, "cpu")]


def test_units_of_the_preset_match_the_scene_doc():
    u = Units.from_physical(0.001, 1e-6, 0.01)
    assert (u.dt_s, u.tau) == pytest.approx((0.01, 0.53))


@pytest.mark.parametrize("output, schedule", [({}, ("WallTimeInterval", 600.0)),
                                              ({"checkpoint_wall_s": 30.0}, ("WallTimeInterval", 30.0)),
                                              ({"checkpoint_every_steps": 7}, ("IterationInterval", 7))])
def test_run_checkpoints_every_ten_minutes_unless_the_scene_says(tmp_path, output, schedule):
    """A long run killed without a checkpoint loses all its work (an interrupt skips the final one), so a scene
    that names no checkpoint schedule gets the sweep's 600 s of wall time; one that does keeps its own."""
    from iceresist.driver import DEFAULT_CHECKPOINT_WALL_S
    from iceresist.run import scene_outputs
    from iceresist.scene.load import load_scene

    scene = load_scene("poiseuille")
    scene = scene.model_copy(update={"output": scene.output.model_copy(update=output)})
    chk = scene_outputs(scene)[1].checkpoint
    kind, value = schedule
    assert type(chk).__name__ == kind
    assert (chk.interval_s if kind == "WallTimeInterval" else chk.interval) == value
    assert DEFAULT_CHECKPOINT_WALL_S == 600.0
