"""A fluid scene with ``[refinement]`` (iceresist.models.fluid): the built-in `refined_channel` scene against the
same channel on a uniform grid, mass to round-off, a bit-for-bit restart, and bad refinement input refused with one
line and exit 2."""

import numpy as np
import pytest

from iceresist.models import FluidModel, build_model
from iceresist.scene import parse_scene, preset_text

from test_run import _one_line_error, main  # noqa: F401  (the CLI fixture)

REFINED = preset_text("refined_channel")


def _scene(text=REFINED, steps=None):
    if steps is not None:
        text = text.replace("end_time_s = 20.0", f"steps = {steps}")
    return parse_scene(text, "refined_channel.toml")


def test_the_refined_channel_follows_the_fine_grid_where_refined_and_keeps_its_mass():
    """200 level-0 steps (2 s) from rest. Profiles of u_x on the level-0 grid (mean over x and y; the refined half's
    cells the mean of their eight level-1 cells): the refined lower half within 1 % of the largest speed of the same
    channel on a uniform 0.5 mm grid (averaged the same way), the upper half within 1 % of the uniform 1 mm grid
    (measured 0.1 % and 0.06 %; the uniform 1 mm grid is 7.7 % below the fine one at the wall cell). Mass to 1e-12
    (measured 0). 2-core x86 VM, 2026-11-26."""
    refined = build_model(_scene())
    assert isinstance(refined, FluidModel)
    uniform_text = REFINED.split("[refinement]")[0] + "[run]" + REFINED.split("[run]")[1]
    coarse = build_model(_scene(uniform_text))
    fine = build_model(_scene(uniform_text.replace("dx_m = 0.001 ", "dx_m = 0.0005 ")))
    m0 = refined.diagnostics()["mass_kg"]
    refined.step(200)
    coarse.step(200)
    fine.step(400)
    ur = refined.fields()["u"][..., 0].mean(axis=(0, 1))
    uc = coarse.fields()["u"][..., 0].mean(axis=(0, 1))
    uf = fine.fields()["u"][..., 0].mean(axis=(0, 1)).reshape(-1, 2).mean(axis=1)
    assert ur.shape == uc.shape == uf.shape == (16,)
    assert np.abs(ur[:8] - uf[:8]).max() < 0.01 * uf.max()
    assert np.abs(ur[8:] - uc[8:]).max() < 0.01 * uc.max()
    assert abs(refined.diagnostics()["mass_kg"] - m0) / m0 < 1e-12
    assert refined.lattice_updates_per_step == 512 + 2 * 8 * 512
    assert refined.describe()["leaf_blocks_per_level"] == [1, 8]


def test_the_refined_channel_on_cuda_matches_the_cpu():
    """The refined channel with backend = "cuda" (the CUDA simulator in CI: every level's state and the level
    transfers on the device) against the CPU after two level-0 steps from a sheared start: every level's
    populations to 1e-13 (float64; the CPU collides blocks at once, CUDA cell by cell), the mass to round-off, and
    a checkpoint of the CUDA run restarts on the CPU. Planted: the level transfer skipped on CUDA (fine level
    fed nothing from the coarse one) fails."""
    from iceresist.backends import jit

    if not jit.cuda_available():
        pytest.skip("no CUDA GPU and the simulator is off")
    from tests.conftest import SIMULATED

    steps = 2 if SIMULATED else 50
    text = REFINED.replace(
        'operator = "bgk"', 'operator = "bgk"\ninitial_velocity_m_s = [0.005, 0.0, 0.0]')
    cpu = build_model(_scene(text))
    gpu = build_model(_scene(text), backend="cuda")
    assert gpu.describe()["backend"] != cpu.describe()["backend"]
    cpu.step(steps)
    gpu.step(steps)
    for lv in cpu.lbm.levels:
        a, b = cpu.lbm.solvers[lv].populations(), gpu.lbm.solvers[lv].populations()
        n = cpu.lbm.views[lv].nleaves
        assert np.abs(a[:n] - b[:n]).max() < 1e-13
        assert np.abs(a[:n]).max() > 1e-4
    assert gpu.lbm.mass() == pytest.approx(cpu.lbm.mass(), rel=1e-14)
    again = build_model(_scene(text))
    again.load_state(gpu.state())
    assert again.iteration == steps


def test_a_refined_run_restarts_bit_for_bit():
    a = build_model(_scene())
    a.step(30)
    state = a.state()
    a.step(20)
    b = build_model(_scene())
    b.load_state(state)
    assert b.iteration == 30
    b.step(20)
    for lv in a.lbm.levels:
        assert np.array_equal(a.lbm.solvers[lv].populations(), b.lbm.solvers[lv].populations())
    other = build_model(_scene(REFINED.replace("levels = 1", "levels = 2").replace("level = 1", "level = 2")))
    with pytest.raises(Exception, match="block octree differs"):
        other.load_state(state)


@pytest.mark.parametrize("edit, needle", [
    (("hi_m = [0.008, 0.008, 0.008]", "hi_m = [0.008, 0.008, 0.02]"), "refinement.boxes[0]: the box must lie inside"),
    (("level = 1", "level = 2"), "refinement.boxes[0].level: 2 is finer than levels = 1"),
    (("hi_m = [0.008, 0.008, 0.008]", "hi_m = [0.008, 0.008, 0.0]"), "hi_m: each coordinate must exceed lo_m"),
    (('backend = "cpu"\n\n[refinement]\nlevels = 1', 'backend = "cuda"\n\n[refinement]\nlevels = 1\n'
      'scheme = "interpolate"'), "refinement.scheme"),
    (("[run]", "[contact]\nstiffness_N_m = 1.0e4\n\n[run]"), "refinement: a refined scene is the fluid alone"),
    (("levels = 1", "levels = 9"), "refinement.levels"),
])
def test_bad_refinement_exits_2_with_one_line(tmp_path, main, edit, needle):  # noqa: F811
    assert edit[0] in REFINED
    p = tmp_path / "s.toml"
    p.write_text(REFINED.replace(*edit))
    rc, err = main(p, "--output", tmp_path / "out")
    _one_line_error(rc, err, needle)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_refined_run_writes_every_level_for_paraview(tmp_path, main):  # noqa: F811
    """`iceresist run` of the refined channel (20 level-0 steps, fields at 0.1 s): the result holds level 0 (the
    upper block, 512 cells of 1 mm) and level 1 (the lower half, 4096 cells of 0.5 mm) as hexahedra that tile the
    domain once (their volumes sum to the domain's, each cell's corners span its own cell size), the fields of each
    level's cells in the order of its hexahedra (the level-0 grid's lower cells are the means of eight level-1
    cells), and a levels sidecar naming both levels' meshes and fields in the file. Planted: nodes at the
    coarse cell size on every level (volumes 8x too large on level 1) or the cells written in another order than
    the values fail."""
    import xml.etree.ElementTree as ET

    from iceresist.io.hdf5 import RunFile

    p = tmp_path / "refined_channel.toml"
    p.write_text(REFINED.replace("end_time_s = 20.0", "steps = 20").replace("fields_every_s = 5.0",
                                                                             "fields_every_s = 0.1"))
    rc, err = main(p, "--output", tmp_path / "out")
    assert rc == 0, err
    h5 = tmp_path / "out" / "refined_channel.h5"
    with RunFile(h5) as rf:
        its = rf.level_snapshot_iterations()
        assert its == rf.snapshot_iterations() and its[-1] == 20
        volume = 0.0
        for lv, n, dx in ((0, 512, 1e-3), (1, 4096, 5e-4)):
            nodes, hexes = rf.level_mesh(lv)
            assert hexes.shape == (n, 8)
            corners = nodes[hexes]                                   # (n, 8, 3)
            span = corners.max(axis=1) - corners.min(axis=1)
            assert np.allclose(span, dx)
            volume += float(np.prod(span, axis=1).sum())
            centres = corners.mean(axis=1)
            if lv == 0:
                assert centres[:, 2].min() > 0.008
            else:
                assert centres[:, 2].max() < 0.008
        assert volume == pytest.approx(0.008 * 0.008 * 0.016, rel=1e-12)
        # level 1's u_x against the level-0 grid's lower half, by position
        nodes, hexes = rf.level_mesh(1)
        centres = nodes[hexes].mean(axis=1)
        u1 = rf.read_level_field(20, 1, "u")[:, 0]
        u0 = rf.read_field(20, "u")[..., 0]
        cell0 = np.floor(centres / 1e-3).astype(int)
        means = np.zeros(u0.shape)
        np.add.at(means, tuple(cell0.T), u1 / 8.0)
        assert np.abs(means[:, :, :8] - u0[:, :, :8]).max() < 1e-6 * np.abs(u0).max()
        assert np.abs(u1).max() > 0.0
    xml = ET.parse(h5.with_suffix(".levels.xdmf")).getroot()
    grids = xml.findall("./Domain/Grid/Grid")
    assert len(grids) == len(its)
    names = [g.get("Name") for g in grids[-1].findall("Grid")]
    assert names == ["level_0", "level_1"]
    import h5py
    with h5py.File(h5, "r") as f:
        for item in grids[-1].iter("DataItem"):
            path = item.text.split(":", 1)[1]
            assert path in f
            assert " ".join(map(str, f[path].shape)) == item.get("Dimensions")


def test_a_band_along_the_walls_refines_the_boundary_layers():
    """The refined channel 48 mm high (6 level-0 blocks across it) with refinement.wall_band_m = 4 mm instead of
    boxes: the blocks touching the walls at z = 0 and z = 48 mm are on level 1, the four between on level 0; the
    periodic faces take no band. The run steps and keeps its mass."""
    from iceresist.scene.blocks import build_octree

    text = REFINED.replace("size_m = [0.008, 0.008, 0.016]", "size_m = [0.008, 0.008, 0.048]")
    text = text.split("[[refinement.boxes]]")[0] + "wall_band_m = 0.004\n\n[run]" + text.split("[run]")[1]
    scene = _scene(text, steps=10)
    tree = build_octree(scene)
    levels = {int(c[2] >> lv): int(lv) for lv, c in zip(tree.level, tree.coord)}
    assert levels == {0: 1, 1: 0, 2: 0, 3: 0, 4: 0, 5: 1}
    m = build_model(scene)
    m0 = m.diagnostics()["mass_kg"]
    m.step(10)
    assert abs(m.diagnostics()["mass_kg"] - m0) / m0 < 1e-12
