"""The LBM on the levels of a block octree (iceresist.grid.levels, iceresist.lbm.refinement): ghost blocks and
their sources, the coarse-to-fine interpolation and fine-to-coarse average against exact answers, and a
force-driven Poiseuille channel with a refined band against the analytic profile."""

import numpy as np
import pytest

from iceresist.grid.forest import BlockForest, Face
from iceresist.grid.levels import FROM_COARSER, FROM_FINER, level_views
from iceresist.grid.octree import BlockOctree
from iceresist.lbm.refinement import RefinedLBM, _apply, prolongation_table, restriction_table
from iceresist.lbm.solver import LBMSolver

PERIODIC_XZ = {"x-": Face("periodic"), "x+": Face("periodic"), "z-": Face("periodic"), "z+": Face("periodic"),
               "y-": Face("wall"), "y+": Face("wall")}


def _band_tree():
    """4 level-0 blocks across y (walls), the middle two refined: the band 8 <= y < 24 (level-0 cells)."""
    t = BlockOctree((1, 4, 1), 1, periodic=(True, False, True))
    return t.refine(lambda lo, hi: np.where((lo[:, 1] >= 8) & (hi[:, 1] <= 24), 1, 0))


def test_ghost_blocks_of_a_refined_band():
    v0, v1 = level_views(_band_tree(), PERIODIC_XZ)
    assert (v0.nleaves, v0.nghosts) == (2, 2) and (v0.ghost_source == FROM_FINER).all()
    assert (v1.nleaves, v1.nghosts) == (16, 8) and (v1.ghost_source == FROM_COARSER).all()
    ghost_y = v1.forest.origin[v1.nleaves:, 1]
    assert set(ghost_y.tolist()) == {1, 6}            # one fine block row on each side of the band


def test_prolongation_reproduces_a_linear_field_and_restriction_averages_exactly():
    """Trilinear interpolation is exact for fields linear in x, y, z; the average of eight children is exact for
    them too (the coarse cell centre is their centroid)."""
    t = BlockOctree((2, 2, 2), 1, periodic=(False, False, False)).refine(
        lambda lo, hi: np.where((lo < 8).all(axis=1), 1, 0))
    faces = {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}
    v0, v1 = level_views(t, faces)
    a = np.array([0.3, -0.2, 0.7])

    def field(view, lv):
        x, y, z = view.forest.cell_coordinates()
        xs = [(c + 0.5) / 2 ** lv for c in (x, y, z)]                  # level-0 cell units
        val = 1e-3 * (a[0] * xs[0] + a[1] * xs[1] + a[2] * xs[2])
        return np.repeat(val[:, None, :], 27, axis=1) * np.arange(1, 28)[None, :, None]
    f0, f1 = field(v0, 0), field(v1, 1)
    periodic = (False, False, False)
    # interior fine ghost cells (away from the clamped domain faces) get the exact linear value
    pt = prolongation_table(v1, v0, periodic)
    g1 = f1.copy()
    g1[v1.nleaves:] = 0.0
    _apply(pt, g1, f0)
    x, y, z = v1.forest.cell_coordinates()
    inner = (x > 0) & (y > 0) & (z > 0) & (x < 31) & (y < 31) & (z < 31)
    ghost = np.zeros(x.shape, dtype=bool)
    ghost[v1.nleaves:] = True
    sel = ghost & inner
    assert sel.sum() > 0
    assert np.abs(g1.transpose(0, 2, 1)[sel] - f1.transpose(0, 2, 1)[sel]).max() < 1e-15
    # coarse ghost cells over the fine leaves get the exact value
    rt = restriction_table(v0, v1, periodic)
    g0 = f0.copy()
    g0[v0.nleaves:] = 0.0
    _apply(rt, g0, f1)
    assert np.abs(g0[v0.nleaves:] - f0[v0.nleaves:]).max() < 1e-15


def _poiseuille(tau0, steps, **scheme):
    """Relative L2 error of the refined band channel and of the uniform level-0 grid, both started from the
    analytic profile (equilibrium populations), after ``steps`` level-0 steps."""
    H, umax = 32, 0.02
    nu0 = (tau0 - 0.5) / 3
    g = 8 * nu0 * umax / H ** 2

    def prof(y):
        return g / (2 * nu0) * y * (H - y)

    def init(solver, lv):
        shape = solver.forest.shape_cells
        u = np.zeros((3, *shape))
        u[0] = prof((np.arange(shape[1]) + 0.5) / 2 ** lv)[None, :, None]
        solver.initialize(u=u)

    m = RefinedLBM(_band_tree(), tau0=tau0, force0=(g, 0, 0), faces=PERIODIC_XZ, **scheme)
    for lv, s in m.solvers.items():
        init(s, lv)
    m.step(steps)
    y = np.concatenate([((m.leaf_fields(lv)[2][1] + 0.5) / 2 ** lv).ravel() for lv in m.levels])
    u = np.concatenate([m.leaf_fields(lv)[1][0].ravel() for lv in m.levels])
    refined = np.sqrt(np.mean((u - prof(y)) ** 2) / np.mean(prof(y) ** 2))
    s = LBMSolver(BlockForest.uniform((8, 32, 8), PERIODIC_XZ), tau=tau0, force=(g, 0, 0), operator="bgk",
                  precision="float64")
    init(s, 0)
    s.step(steps)
    _, uu = s.macroscopic()
    yc = np.arange(32) + 0.5
    coarse = np.sqrt(np.mean((uu[0].mean(axis=(0, 2)) - prof(yc)) ** 2) / np.mean(prof(yc) ** 2))
    return refined, coarse


def test_refined_band_poiseuille_with_the_conservative_interface():
    """BGK, float64, tau0 = 0.56 (fine level 0.62), 1500 level-0 steps from the analytic profile: relative L2 error
    0.061 % on the refined grid against 0.112 % on the uniform level-0 grid (2-core x86 VM, 2026-11-26; 0.056 % with
    the constant explosion; at tau0 = 1.4: 0.436 % against 0.440 %). Planted: coalesced packets weighted 1/4 instead of 1/8 (mass doubled across the
    interface) or the interpolating scheme without its rescaling (0.8 % here) fail."""
    refined, coarse = _poiseuille(0.56, 1500)
    assert refined < coarse
    assert refined < 0.0008


def test_refined_band_poiseuille_with_the_papers_interpolation_rescaled():
    """The paper's trilinear coarse-to-fine interpolation with the non-equilibrium part rescaled by (tau - 1) dx
    (Dupuis and Chopard): at tau0 = 1.4, 0.15 % against 0.44 % on the uniform level-0 grid after 1500 steps
    (0.16 % against 0.44 % run from rest to steady state); at tau0 = 0.56-0.8 it loses momentum at the interface
    (0.8-1.7 % against 0.1 %), which the conservative scheme does not. Planted: no rescaling (the paper's
    choice) gives 15 % and fails."""
    refined, coarse = _poiseuille(1.4, 1500, scheme="interpolate", rescale=True)
    assert refined < coarse
    assert refined < 0.003


@pytest.mark.slow   # about 40 s on a 2-core x86 VM
def test_the_papers_unscaled_interface_loses_the_stress():
    """Interpolating post-collision populations without rescaling their non-equilibrium part (the paper's choice)
    carries the coarse level's stress into the fine level unchanged, although it scales as (tau - 1) dx: the band
    channel is off by 15 % after 1500 steps at tau0 = 1.4 and by 28 % at 0.8 (measured)."""
    refined, _ = _poiseuille(1.4, 1500, scheme="interpolate")
    assert refined > 0.1


def _wave_box(precision, **scheme):
    """A periodic 24 x 24 x 8 box with a refined 8 x 8 column, a shear wave and a density wave crossing the
    interface."""
    faces = {k: Face("periodic") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}
    t = BlockOctree((3, 3, 1), 1, periodic=(True, True, True)).refine(
        lambda lo, hi: np.where((lo[:, 0] >= 8) & (hi[:, 0] <= 16) & (lo[:, 1] >= 8) & (hi[:, 1] <= 16), 1, 0))
    m = RefinedLBM(t, tau0=0.6, faces=faces, precision=precision, **scheme)
    for lv, s in m.solvers.items():
        sh = s.forest.shape_cells
        x = (np.arange(sh[0]) + 0.5) / 2 ** lv
        y = (np.arange(sh[1]) + 0.5) / 2 ** lv
        u = np.zeros((3, *sh))
        u[0] = 0.02 * np.sin(2 * np.pi * y / 24)[None, :, None]
        u[1] = 0.01 * np.cos(2 * np.pi * x / 24)[:, None, None]
        s.initialize(rho=1 + 0.001 * np.sin(2 * np.pi * x / 24)[:, None, None] * np.ones(sh), u=u)
    return m


@pytest.mark.parametrize("precision,bound", [("float64", 1e-12), ("float32", 1e-6)])
def test_the_conservative_interface_keeps_the_mass(precision, bound):
    """Mass over all leaves (cell volumes per level) after 1000 level-0 steps with flow and a density wave
    crossing the level interface: drift 2e-16 (float64) and 8e-11 (float32) measured; the interpolating scheme
    drifts 7e-6 (float64). Planted: coalesced packets weighted 1/4 fail."""
    m = _wave_box(precision)
    m0 = m.mass()
    m.step(1000)
    assert abs(m.mass() - m0) / m0 < bound


def test_the_conservative_interface_keeps_the_mass_on_three_levels():
    """Three levels (a periodic 32 x 32 x 8 box, level 1 over its middle 16 x 16 columns, level 2 over the middle
    8 x 8), a shear wave and a density wave crossing both interfaces, float64: mass over all leaves after 200 level-0
    steps, drift 1e-16 measured. The middle level's copy at t serves both interfaces; with the coalescence into
    level 0 after level 1's second sub-step it read level 1 at t + 1/2 and the mass drifted 3.2e-7 (planted: fails)."""
    faces = {k: Face("periodic") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}

    def wanted(lo, hi):
        inner = (lo[:, :2] >= 12).all(axis=1) & (hi[:, :2] <= 20).all(axis=1)
        middle = (lo[:, :2] >= 8).all(axis=1) & (hi[:, :2] <= 24).all(axis=1)
        return np.where(inner, 2, np.where(middle, 1, 0))

    t = BlockOctree((4, 4, 1), 2, periodic=(True, True, True)).refine(wanted)
    assert list(t.blocks_per_level()) == [12, 24, 64]
    m = RefinedLBM(t, tau0=0.6, faces=faces, precision="float64")
    for lv, s in m.solvers.items():
        sh = s.forest.shape_cells
        x, y = ((np.arange(n) + 0.5) / 2 ** lv for n in sh[:2])
        u = np.zeros((3, *sh))
        u[0] = 0.02 * np.sin(2 * np.pi * y / 32)[None, :, None]
        u[1] = 0.01 * np.cos(2 * np.pi * x / 32)[:, None, None]
        s.initialize(rho=1 + 0.001 * np.sin(2 * np.pi * x / 32)[:, None, None] * np.ones(sh), u=u)
    m0 = m.mass()
    m.step(200)
    assert abs(m.mass() - m0) / m0 < 1e-12


def _wall_slab(reconstruction="linear"):
    """The x-slab channel: 32 x 16 x 8 level-0 cells, walls in y, the middle half of the length on level 1 (both
    interfaces meet both walls), tau0 = 0.8, forced along x, float64, started at u = 0.02."""
    H = 16
    t = BlockOctree((H // 4, H // 8, 1), 1, periodic=(True, False, True)).refine(
        lambda lo, hi: np.where((lo[:, 0] >= 8) & (hi[:, 0] <= 24), 1, 0))
    m = RefinedLBM(t, tau0=0.8, force0=(1e-5, 0, 0), faces=PERIODIC_XZ, precision="float64",
                   reconstruction=reconstruction)
    m.initialize(u=(0.02, 0, 0))
    return m


@pytest.mark.parametrize("reconstruction", ["constant", "linear"])
def test_the_conservative_interface_keeps_the_mass_where_it_meets_a_wall(reconstruction):
    """The x-slab channel (H = 16, walls in y, the middle half of the length on level 1, so both interfaces meet both
    walls), float64, forced flow: mass over 1000 level-0 steps within 1e-12 as in a periodic box (issue 33's bound;
    measured 0 to 1e-16). Before the packets at the walls were followed off the walls and the coarse packets that the
    plain coarse bounce-back takes whole were swapped (``_take_free_packets``), -1.15e-6; with the reflection
    alone, +6.5e-8."""
    m = _wall_slab(reconstruction)
    m0 = m.mass()
    m.step(1000)
    assert abs(m.mass() - m0) / m0 < 1e-12


def test_tau_one_cannot_be_rescaled():
    with pytest.raises(Exception, match="tau = 1 on level"):
        RefinedLBM(_band_tree(), tau0=0.75, faces=PERIODIC_XZ, scheme="interpolate", rescale=True)
    with pytest.raises(Exception, match="conservative scheme moves whole packets"):
        RefinedLBM(_band_tree(), tau0=0.6, faces=PERIODIC_XZ, rescale=True)


def _taylor_green_viscosity(solver_levels, steps=200, every=20, L=32, U=0.02):
    """Fitted viscosity (level-0 lattice units) of the decay of a 2D Taylor-Green vortex, E ~ exp(-4 nu k^2 t)."""
    k = 2 * np.pi / L
    for lv, s in solver_levels.items():
        sh = s.forest.shape_cells
        x = (np.arange(sh[0]) + 0.5) / 2 ** lv
        y = (np.arange(sh[1]) + 0.5) / 2 ** lv
        X, Y = np.meshgrid(x, y, indexing="ij")
        u = np.zeros((3, *sh))
        u[0] = (U * np.sin(k * X) * np.cos(k * Y))[:, :, None]
        u[1] = (-U * np.cos(k * X) * np.sin(k * Y))[:, :, None]
        rho = (1 - 0.75 * U ** 2 * (np.cos(2 * k * X) + np.cos(2 * k * Y)))[:, :, None] * np.ones(sh)
        s.initialize(rho=rho, u=u)
    return k


def test_taylor_green_with_a_refined_centre_keeps_the_viscosity_of_the_fine_grid():
    """2D Taylor-Green vortex (32 level-0 cells per wavelength, tau0 = 0.6, BGK float64) with the centre 16 x 16
    cells on level 1, 200 level-0 steps: fitted viscosity 0.033496 against 0.033381 on the uniform fine grid
    (+0.34 %; the issue's bound 1 %) and 0.033523 on the uniform coarse grid; with the constant (first-order)
    explosion +3.0 %, with the paper's rescaled interpolation +14 % (2-core x86 VM, 2026-11-26). Planted: the
    constant reconstruction fails."""
    faces = {k: Face("periodic") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}
    t = BlockOctree((4, 4, 1), 1, periodic=(True, True, True)).refine(
        lambda lo, hi: np.where((lo[:, 0] >= 8) & (hi[:, 0] <= 24) & (lo[:, 1] >= 8) & (hi[:, 1] <= 24), 1, 0))
    m = RefinedLBM(t, tau0=0.6, faces=faces)
    k = _taylor_green_viscosity(m.solvers)
    ts, es = [], []
    for n in range(0, 201, 20):
        if n:
            m.step(20)
        ts.append(n)
        es.append(sum(np.nansum((m.leaf_fields(lv)[1][:2] ** 2).sum(axis=0)) / 8 ** lv for lv in m.levels))
    nu_refined = -np.polyfit(ts, np.log(es), 1)[0] / (4 * k * k)
    fine = LBMSolver(BlockForest.uniform((64, 64, 16), faces), tau=0.7, operator="bgk", precision="float64")
    _taylor_green_viscosity({1: fine})
    ts, es = [], []
    for n in range(0, 201, 20):
        if n:
            fine.step(40)
        _, u = fine.macroscopic()
        ts.append(n)
        es.append((u[:2] ** 2).sum())
    nu_fine = -np.polyfit(ts, np.log(es), 1)[0] / (4 * k * k)
    assert nu_refined == pytest.approx(nu_fine, rel=0.01)


@pytest.mark.parametrize("on", ["cpu", "cuda"])
@pytest.mark.parametrize("linear", [False, True])
@pytest.mark.parametrize("box", ["periodic", "walls"])
def test_the_transfer_kernel_matches_the_numpy_reference(on, linear, box):
    """The level transfer kernel (iceresist.lbm.exchange, one source for CPU and CUDA; the CUDA simulator in CI)
    against the NumPy form of the same tables: explosion (sub-step 2) and coalescence, with and without the
    linear reconstruction, to round-off; in a periodic box and where the interfaces meet walls (packets read from
    another slot than they are written to)."""
    from iceresist.backends import jit
    from iceresist.lbm.exchange import pack_table, transfer_launcher
    from iceresist.lbm.refinement import _apply_slots

    m = _wave_box("float64") if box == "periodic" else _wall_slab()
    if box == "walls":
        for table in (m.explode[1][1], m.coalesce[0]):
            q, sq = np.broadcast_arrays(table[1][:, None], table[6])
            assert (q != sq).any()
    m.step(3)
    target = jit.cpu if on == "cpu" else jit.cuda()
    s0, s1 = m.solvers[0], m.solvers[1]
    c_t, f_t = s0.state.copy(), s1.state.copy()
    f_h = 1.01 * f_t
    for table, dst, sources, weight in ((m.explode[1][1], s1.state, (c_t, f_t, f_t), 1.0),
                                        (m.coalesce[0], s0.state, (c_t, f_t, f_h), 0.125)):
        ref = dst.copy()
        _apply_slots(table, ref, sources, weight=weight, linear=linear)
        p = pack_table(table, np.float64)
        dev = target.to_device
        out = dev(dst.copy())
        cols = [dev(p[k]) for k in ("db", "dq", "dc", "tag", "sb", "sc", "sq", "off", "nb", "nc", "nok")]
        transfer_launcher(target, np.float64)(len(p["db"]), *cols, np.float64(weight), np.int64(linear),
                                              *(dev(a) for a in sources), out)
        got = target.to_host(out)
        assert np.abs(got - ref).max() < 1e-17
        assert np.abs(got - dst).max() > 1e-6      # the slots were written
