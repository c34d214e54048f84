"""`iceresist run` on a free-surface scene: model, HDF5 fields (phi, surface), checkpoint restart, bad keys.

A small dam break (the ``dam_break`` preset shrunk to 32 x 8 x 16 cells, BGK in float64 like the other
free-surface CI tests) runs through ``cmd_run``.
"""

import argparse

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.io import RunFile, read_checkpoint
from iceresist.models import FluidModel, FreeSurfaceModel, build_model
from iceresist.run import add_run_arguments
from iceresist.scene import parse_scene, preset_text

SMALL = {"cells = [64, 8, 32]": "cells = [32, 8, 16]",
         'operator = "cumulant"': 'operator = "bgk"',
         'precision = "float32"': 'precision = "float64"',
         "water_depth_m = 16.0": "water_depth_m = 10.0",
         "column_length_m = 16.0": "column_length_m = 8.0",
         "fields_every_steps = 200": "fields_every_steps = 10"}


def _dam_break_text(**extra) -> str:
    text = preset_text("dam_break")
    for a, b in SMALL.items():
        assert a in text
        text = text.replace(a, b)
    lines = [ln for ln in text.splitlines() if ln.split("=")[0].strip() not in extra]
    return "\n".join(lines + [f"{key} = {value}" for key, value in extra.items()]) + "\n"


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("scene") / "dam_break.toml"
    p.write_text(_dam_break_text())
    return p


def _run(*argv) -> int:
    args = add_run_arguments(argparse.ArgumentParser()).parse_args([str(a) for a in argv] + ["--no-progress"])
    return args.func(args)


def test_free_surface_scene_builds_fluid_and_phase_field_only(scene_file):
    """4 x 1 x 2 blocks, water over x < 8 up to z = 10: 4 blocks hold populations (x-blocks 0 and 1, both
    layers) plus ceil(1.0 * 2) spare = 6 rows of 8; h (D3Q15) and phi in all 8; no DEM, no coupling."""
    model = build_model(parse_scene(scene_file.read_text()), backend="cpu")
    assert isinstance(model, FreeSurfaceModel) and model.components == ("fluid", "free_surface")
    assert not any(k in vars(model) for k in ("dem", "bodies", "coupling", "ship", "ice", "solver"))
    parts = model.fluid.allocated_bytes()
    nb, cell = 8, 512
    assert parts["f"] == 6 * 2 * 27 * 8 * cell + 4 * nb
    assert parts["phase"] == nb * cell * 8 * (2 * 15 + 1)
    assert model.allocated_bytes() == sum(parts.values())
    assert model.describe()["f_pool_rows"] == 6 and model.describe()["h_lattice"] == "D3Q15"
    d = model.diagnostics()
    assert d["water_volume_m3"] == pytest.approx(8 * 8 * 10, rel=0.02) and d["water_volume_drift"] == 0.0
    f = model.fields()
    assert f["phi"].shape == (32, 8, 16) and f["surface"].shape == (32, 8, 16)
    assert f["surface"][2, 3, 0] == pytest.approx(10.0, abs=0.05) and f["surface"][20, 3, 5] == 0.0


def test_single_phase_scene_allocates_no_phase_field():
    model = build_model(parse_scene(preset_text("cavity").replace('"cumulant"', '"bgk"')), backend="cpu")
    assert isinstance(model, FluidModel)
    assert not any(k in vars(model) for k in ("phase", "fluid", "h", "phi"))
    assert model.allocated_bytes() == 2 * 27 * 4 * 16 ** 3
    assert "phi" not in model.fields()


@pytest.mark.parametrize("extra, field", [
    ({"h_lattice": '"D3Q9"'}, "free_surface.h_lattice"),
    ({"f_pool_margin": "-0.5"}, "free_surface.f_pool_margin"),
    ({"interface_width_cells": "1.0"}, "free_surface.interface_width_cells"),
    ({"wetting": "0.5"}, "free_surface.wetting"),
])
def test_bad_free_surface_keys_are_one_line_input_errors(extra, field):
    with pytest.raises(InputError) as exc:
        parse_scene(_dam_break_text(**extra))
    msg = str(exc.value)
    assert field in msg and "\n" not in msg


def test_model_level_input_errors_name_the_key():
    with pytest.raises(InputError, match=r"^free_surface\.water_depth_m: 40.0 m is 40 cells") as exc:
        build_model(parse_scene(_dam_break_text().replace("water_depth_m = 10.0", "water_depth_m = 40.0")),
                    backend="cpu")
    assert "\n" not in str(exc.value)
    with pytest.raises(InputError, match=r"^fluid\.gravity_m_s2: the free surface needs gravity along -z"):
        build_model(parse_scene(_dam_break_text().replace("[0.0, 0.0, -2.0e-4]", "[1.0e-4, 0.0, -2.0e-4]")),
                    backend="cpu")
    with pytest.raises(InputError, match=r"^output\.fields: phi need a \[free_surface\]"):
        build_model(parse_scene(preset_text("cavity").replace('fields = ["rho", "u", "flags"]',
                                                             'fields = ["rho", "phi"]')), backend="cpu")


def test_free_surface_scene_runs_to_hdf5_and_restarts_bitwise(tmp_path, scene_file):
    """20 steps straight and 10 + pickup 10 give the same populations, h, phi and fields bit for bit; the
    result holds phi and the surface; the water volume drifts by < 5e-4: measured +1.4e-4 at step 10, -3.7e-5 at
    step 20 (the phase field runs only in the blocks within reach of the surface, iceresist/freesurface/bulk.py;
    the column's start sends h of 5e-3 through the air, where phi is 1e-3, out of them; the drift settles at
    -4.4e-5 within 600 steps, when every block has become active). The whole-grid step keeps it to 1e-15."""
    assert _run(scene_file, "--output", tmp_path / "a", "--steps", "20", "--backend", "cpu") == 0
    with RunFile(tmp_path / "a" / "dam_break.h5") as rf:
        assert rf.snapshot_iterations() == [0, 10, 20]
        phi = rf.read_field(20, "phi")
        # the diffuse interface over- and undershoots a little where the column's corner falls (measured -0.013)
        assert phi.shape == (32, 8, 16) and phi.min() > -0.05 and phi.max() < 1.05
        assert phi[2, 4, 2] > 0.99 and phi[28, 4, 12] < 0.01
        surface = rf.read_field(0, "surface")
        assert surface[0, 0, 0] == pytest.approx(10.0, abs=0.05) and surface[31, 0, 0] == 0.0
        ts = rf.timeseries()
        assert np.abs(ts["water_volume_drift"]).max() < 5e-4
        assert ts["water_volume_m3"][0] == pytest.approx(8 * 8 * 10, rel=0.02)
    assert _run(scene_file, "--output", tmp_path / "b", "--steps", "10", "--backend", "cpu") == 0
    assert _run(scene_file, "--output", tmp_path / "b", "--steps", "20", "--backend", "cpu", "--pickup") == 0
    a = read_checkpoint(tmp_path / "a" / "dam_break.checkpoint.h5")["model"]
    b = read_checkpoint(tmp_path / "b" / "dam_break.checkpoint.h5")["model"]
    for key in ("f_blocks", "f", "h", "phi", "flags"):
        assert np.array_equal(a[key], b[key]), key
    assert int(a["iteration"]) == int(b["iteration"]) == 20
    with RunFile(tmp_path / "a" / "dam_break.h5") as ra, RunFile(tmp_path / "b" / "dam_break.h5") as rb:
        for name in ("phi", "u", "rho", "surface"):
            assert np.array_equal(ra.read_field(20, name), rb.read_field(20, name)), name


def test_a_free_surface_run_killed_after_a_checkpoint_continues_bit_for_bit(tmp_path, scene_file):
    """Crash safety on a grid: ``iceresist run`` of the small dam break killed with SIGKILL after it wrote a
    checkpoint (its result file open, stepping past the checkpoint), then ``--pickup`` to iteration K, gives the
    populations, h, phi and flags of a straight run to K bit for bit, and the result file reads whole."""
    import os
    import signal
    import subprocess
    import sys
    import time

    text = scene_file.read_text().replace("fields_every_steps = 10", "fields_every_steps = 1000000")
    assert text.count("[output]\n") == 1
    scene = tmp_path / "dam_break.toml"
    scene.write_text(text.replace("[output]\n", "[output]\ncheckpoint_every_steps = 10\n"))
    killed, straight = tmp_path / "killed", tmp_path / "straight"
    cmd = [sys.executable, "-m", "iceresist", "run", str(scene), "--backend", "cpu", "--no-progress"]
    proc = subprocess.Popen(cmd + ["--output", str(killed), "--steps", "1000000"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    chk = killed / "dam_break.checkpoint.h5"
    deadline = time.monotonic() + 600.0        # a cold kernel cache compiles first
    def checkpointed() -> int:                 # the iteration of the checkpoint there now (replaced atomically)
        return int(read_checkpoint(chk)["model"]["iteration"]) if chk.exists() else -1

    try:
        while checkpointed() < 10:             # the start writes one at iteration 0
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "no checkpoint past the start in 600 s"
            time.sleep(0.05)
        time.sleep(0.2)                        # past the checkpoint, into the next rows
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    at = checkpointed()
    assert at >= 10 and at % 10 == 0
    end = at + 20
    assert subprocess.run(cmd + ["--output", str(killed), "--steps", str(end), "--pickup"],
                          capture_output=True, timeout=600).returncode == 0
    assert _run(scene, "--output", straight, "--steps", end, "--backend", "cpu") == 0
    a = read_checkpoint(straight / "dam_break.checkpoint.h5")["model"]
    b = read_checkpoint(chk)["model"]
    assert int(a["iteration"]) == int(b["iteration"]) == end
    for key in ("f_blocks", "f", "h", "phi", "flags"):
        assert np.array_equal(a[key], b[key]), key
    with RunFile(straight / "dam_break.h5") as ra, RunFile(killed / "dam_break.h5") as rb:
        assert rb.meta["legs"] == 2 and rb.meta["finished"]
        np.testing.assert_array_equal(ra.timeseries()["iteration"], rb.timeseries()["iteration"])
        for name in ("phi", "u", "rho"):
            assert np.array_equal(ra.read_field(end, name), rb.read_field(end, name)), name
