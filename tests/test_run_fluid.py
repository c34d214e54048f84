"""End to end on the real LBM solver: the default cavity scene through ``cmd_run`` to an HDF5 result and back."""

import argparse
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

pytest.importorskip("iceresist.lbm.solver")

from iceresist.io import RunFile  # noqa: E402
from iceresist.lbm.solver import operator_available  # noqa: E402
from iceresist.models import FluidModel, build_model  # noqa: E402
from iceresist.run import add_run_arguments, cmd_run  # noqa: E402
from iceresist.scene import parse_scene, preset_text  # noqa: E402

OPERATOR = "cumulant" if operator_available("cumulant") else "bgk"


@pytest.fixture(scope="module")
def cavity_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("scene") / "cavity.toml"
    p.write_text(preset_text("cavity").replace('operator = "cumulant"', f'operator = "{OPERATOR}"')
                 .replace("fields_every_steps = 100", "fields_every_steps = 20"))
    return p


def _run(*argv) -> int:
    args = add_run_arguments(argparse.ArgumentParser()).parse_args([str(a) for a in argv] + ["--no-progress"])
    return args.func(args)


def test_fluid_only_scene_allocates_only_the_fluid(cavity_file):
    model = build_model(parse_scene(cavity_file.read_text()), backend="cpu")
    assert isinstance(model, FluidModel) and model.components == ("fluid",)
    assert model.cells == 16 ** 3
    assert model.allocated_bytes() == 2 * 27 * 4 * 16 ** 3  # two float32 population buffers, nothing else
    assert not any(k in vars(model) for k in ("phase_field", "dem", "bodies", "coupling", "h"))


def test_default_scene_runs_end_to_end_and_restarts_bitwise(tmp_path, cavity_file):
    assert cmd_run is _run.__globals__["add_run_arguments"](argparse.ArgumentParser()).get_default("func")
    assert _run(cavity_file, "--output", tmp_path / "a", "--steps", "40", "--backend", "cpu") == 0
    h5 = tmp_path / "a" / "cavity.h5"
    with RunFile(h5) as rf:
        m = rf.meta
        assert m["cells"] == 4096 and m["steps"] == 40 and m["backend"] == "cpu" and m["precision"] == "float32"
        assert m["mlups"] > 0 and "[scene]" in m["scene_toml"] and m["git_revision"]
        assert rf.snapshot_iterations() == [0, 20, 40]
        rho, u, flags = rf.read_field(40, "rho"), rf.read_field(40, "u"), rf.read_field(40, "flags")
        assert rho.shape == (16, 16, 16) and u.shape == (16, 16, 16, 3) and flags.dtype == np.uint8
        # the lid (z_max, +x at 0.05) drags the top layer along +x; speed falls off below the lid
        assert 0.01 < u[8, 8, 15, 0] < 0.05
        assert u[8, 8, 15, 0] > u[8, 8, 14, 0] > u[8, 8, 13, 0]
        assert np.argmax(u[:, 8, 15, 0]) in range(5, 11)  # fastest mid-lid, slowed by the side walls
        ts = rf.timeseries()
        # walls are mass-tight: total mass constant to float32 round-off
        assert np.ptp(ts["mass_kg"]) / ts["mass_kg"][0] < 1e-5
        assert ts["max_lattice_speed"].max() < 0.06
    root = ET.parse(tmp_path / "a" / "cavity.xdmf").getroot()
    with h5py.File(h5) as f:
        for item in root.iter("DataItem"):
            if item.get("Format") == "HDF":
                ds = f[item.text.split(":")[1]]
                assert tuple(int(n) for n in item.get("Dimensions").split()) == ds.shape

    # two legs (20 + pickup to 40) give the same populations as the straight run
    assert _run(cavity_file, "--output", tmp_path / "b", "--steps", "20", "--backend", "cpu") == 0
    assert _run(cavity_file, "--output", tmp_path / "b", "--steps", "40", "--backend", "cpu", "--pickup") == 0
    with RunFile(h5) as a, RunFile(tmp_path / "b" / "cavity.h5") as b:
        assert np.array_equal(a.read_field(40, "u"), b.read_field(40, "u"))
        assert np.array_equal(a.read_field(40, "rho"), b.read_field(40, "rho"))
    from iceresist.io import read_checkpoint

    fa = read_checkpoint(tmp_path / "a" / "cavity.checkpoint.h5")["model"]["f"]
    fb = read_checkpoint(tmp_path / "b" / "cavity.checkpoint.h5")["model"]["f"]
    assert fa.dtype == np.float32 and np.array_equal(fa, fb)
