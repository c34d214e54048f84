"""A scene with ``[free_surface]`` and ``[refinement]`` (iceresist.models.refined_surface): the built-in
`refined_tank` scene (still water, the surface band on level 1) run as a user would, a bit-for-bit restart, and bad
refinement of a free surface refused with one line and exit 2."""

import numpy as np
import pytest

from iceresist.models import FreeSurfaceModel, build_model
from iceresist.scene import parse_scene, preset_text

from test_run import _one_line_error, main  # noqa: F401  (the CLI fixture)

TANK = preset_text("refined_tank")


def _scene(text=TANK):
    return parse_scene(text, "refined_tank.toml")


def test_the_refined_tank_stays_still_and_keeps_its_water():
    """The scene's 500 level-0 steps (1000 on level 1): the surface band put level 1 from z = 8 to the lid (4
    level-0 blocks, 96 level-1 blocks), the water volume within 1e-4 (measured -2.7e-5), the mean surface within
    0.01 cell of 20 (measured -7e-4) and flat, the largest speed in the water below 1e-4 (lattice; measured 6.7e-5,
    the start's half-force shift 1e-4 relaxing), the level-0 fields phi = 1 in the deep water and 0 at the lid."""
    m = build_model(_scene())
    assert isinstance(m, FreeSurfaceModel)
    assert m.describe()["leaf_blocks_per_level"] == [4, 96]
    m.step(500)
    d = m.diagnostics()
    assert abs(d["water_volume_drift"]) < 1e-4
    assert abs(d["surface_mean_m"] - 20.0) < 0.01
    assert d["max_lattice_speed"] < 1e-4
    f = m.fields()
    assert f["phi"].shape == (16, 16, 32)
    assert np.allclose(f["phi"][:, :, :16], 1.0, atol=1e-3) and np.all(f["phi"][:, :, -1] < 1e-3)
    s = f["surface"][:, :, 0]
    assert s.max() - s.min() < 0.01


def test_a_refined_free_surface_run_restarts_bit_for_bit():
    a = build_model(_scene())
    a.step(20)
    state = a.state()
    a.step(10)
    b = build_model(_scene())
    b.load_state(state)
    assert b.iteration == 20
    b.step(10)
    assert_same_water(a, b)


def assert_same_water(a, b):
    """Two refined free-surface models hold the same state bit for bit: every level's populations on its leaves
    (a ghost block's, which the level interface writes where its leaves read them, may differ after a rebuild), the
    finest level's h, phi and flags, and the diagnostics."""
    for lv in a.lbm.levels[:-1]:
        n = a.lbm.views[lv].nleaves
        assert np.array_equal(a.lbm.solvers[lv].fluid.rows()[1][:n], b.lbm.solvers[lv].fluid.rows()[1][:n])
    sa, sb = a.fs.surface.state(), b.fs.surface.state()
    n = a.lbm.views[a.finest].nleaves
    assert np.array_equal(sa["f"][:n], sb["f"][:n]), "f"
    for k in ("h", "phi", "flags"):
        assert np.array_equal(sa[k], sb[k]), k
    assert a.diagnostics() == b.diagnostics()


def test_the_refined_tank_writes_phi_on_every_level(tmp_path, main):  # noqa: F811
    """`iceresist run` of the refined tank for 20 steps: the levels in the result hold phi (1 on level 0, all water;
    from 1 to 0 across the surface on level 1)."""
    from iceresist.io.hdf5 import RunFile

    p = tmp_path / "refined_tank.toml"
    p.write_text(TANK.replace("steps = 500 ", "steps = 20 ").replace("fields_every_steps = 250",
                                                                     "fields_every_steps = 10"))
    rc, err = main(p, "--output", tmp_path / "out")
    assert rc == 0, err
    with RunFile(tmp_path / "out" / "refined_tank.h5") as rf:
        assert rf.level_snapshot_iterations()[-1] == 20
        phi0 = rf.read_level_field(20, 0, "phi")
        phi1 = rf.read_level_field(20, 1, "phi")
    assert phi0.shape == (4 * 512,) and np.all(phi0 == 1.0)
    assert phi1.shape == (96 * 512,) and phi1.max() > 0.999 and phi1.min() < 1e-3


@pytest.mark.parametrize("edit, needle", [
    (("surface_band_m = 6.0", "surface_band_m = 2.0"), "refinement.regions: level 0 reaches the free surface"),
    (("water_depth_m = 20.0 ", "water_depth_m = 20.0\ncolumn_length_m = 8.0 "), "free_surface.column_length_m"),
    (("[free_surface]\nwater_depth_m = 20.0          # cells (lattice units, level 0)\nh_lattice = \"D3Q15\"", ""),
     "refinement.surface_band_m"),
])
def test_bad_refinement_of_a_free_surface_exits_2_with_one_line(tmp_path, main, edit, needle):  # noqa: F811
    assert edit[0] in TANK
    p = tmp_path / "s.toml"
    p.write_text(TANK.replace(*edit))
    rc, err = main(p, "--output", tmp_path / "out")
    _one_line_error(rc, err, needle)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
