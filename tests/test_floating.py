"""Bodies in water with a free surface (paper sections 2.2-2.4): buoyancy from the pressure, the floating cube,
water volume, a kinematic box pushing floating cubes.

CI cases: a cube of 6 cells per edge (BGK, float64) over a short run; the full floating-cube validation
(8 cells per edge, six periods) is marked slow; its figures are in docs/VALIDATION.md ("Floating cube").
"""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.coupling import Box, FluidStructureCoupling
from iceresist.coupling.floating import FloatingBodies
from iceresist.dem import DEMSystem, box
from iceresist.errors import InputError
from iceresist.freesurface.fluid import FreeSurfaceFluid
from iceresist.grid import flags as FL
from iceresist.grid.forest import BlockForest, Face
from iceresist.units import Units
from iceresist.validate.cases import floating_cube as fc


def _still_water_link_force_N(model, n):
    """Vertical force of eq. (17) on an axis-aligned cube of n cells per edge at rest in still water whose faces
    lie half-way between cell centres sideways: each link carries 6 w_q p(x), the pressure of its fluid node x
    (the interpolated bounce-back does not move it), p = c_s^2 (exp(3 g d) - 1) at depth d below the still level
    (the initial state of the free-surface fluid). The links under the bottom face (sum of w_q |c_z| = 1/6 per
    cell) give A p(d_b), d_b the depth of the row of nodes below the face; the diagonal links through the side
    faces (c_z = +-1, sum of w_q = 1/36 per column and face) telescope over the height to P p(d_b - 1) / 6,
    P = 4 n the columns along the perimeter. Archimedes is A p at the face itself: the staircase over-estimate
    is A (p(d_b) - p(face)) + P p(d_b - 1) / 6."""
    g = model.fluid.g
    level = model.depth0
    z_bottom = model.dem.positions[0, 2] / model.units.dx_m - 0.5 * n
    d_b = level - (np.floor(z_bottom - 0.5) + 0.5)
    p = lambda d: (np.exp(3 * g * d) - 1) / 3  # noqa: E731
    return (n * n * p(d_b) + 4 * n * p(d_b - 1) / 6) * model.units.force_to_physical(1.0)


def _water_volume_m3(model):
    """The water volume outside the bodies, m^3."""
    return model.water_volume_cells() * model.units.dx_m ** 3


@pytest.fixture(scope="module")
def short_float():
    """6-cell cube released at 80 % draft: the force of the first step (cube at rest in still water), then 240
    steps (about 0.9 of a heave period) sampled every 5."""
    model = fc.build(6, release_draft=0.8)
    v0 = _water_volume_m3(model)
    f_ref = _still_water_link_force_N(model, 6)
    model.step(1)
    f0 = (model.fluid_force_N[0, 2], f_ref)
    frac, force = [], []
    for _ in range(48):
        model.step(5)
        z_bottom = model.dem.positions[0, 2] - 0.5 * fc.EDGE_M
        frac.append((model.water_level_m() - z_bottom) / fc.EDGE_M)
        force.append(model.fluid_force_N[0, 2])
    return model, v0, f0, np.array(frac), np.array(force)


def test_default_buoyancy_is_the_pressure_when_the_fluid_has_gravity():
    fo = BlockForest.uniform((8, 8, 16), {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")})
    dx, g_lat = 0.005, 1e-3
    dt = np.sqrt(g_lat * dx / 9.81)
    fs = FreeSurfaceFluid(fo, tau=0.6, gravity_lattice=g_lat, depth_cells=10.0, operator="bgk", precision="float64")
    dem = DEMSystem()
    dem.add_body(box((0.02,) * 3, 950.0), position_m=(0.02, 0.02, 0.05))
    cp = FluidStructureCoupling(fs, dem, [Box((0.02,) * 3)], Units.from_lattice(dx, dt, 1000.0, 0.6))
    assert cp.buoyancy is False and cp.surface is fs
    with pytest.raises(InputError, match="gravity_lattice"):
        FluidStructureCoupling(fs, dem, [Box((0.02,) * 3)], Units.from_lattice(dx, 2 * dt, 1000.0, 0.6))


def test_released_cube_feels_the_link_force_of_still_water_and_sinks_towards_95_percent(short_float):
    """At release (cube at rest, 80 % draft, still water) the fluid force is the sum of eq. (17) over the links
    in hydrostatic water (_still_water_link_force_N), within 1 % (the estimate counts the 4 corner-diagonal links
    per layer twice, 0.25 %; the half-force shift of the populations cancels between a link's two populations).
    That sum is 1.25 times Archimedes' 0.8 / 0.95 of the weight here (docs/VALIDATION.md, "Floating cube").
    Then the cube sinks (the fraction grows past 0.9 and stays below 1.1: no overtopping)."""
    model, v0, f0, frac, force = short_float
    weight = fc.RHO_ICE * fc.EDGE_M ** 3 * fc.G
    f0, f_ref = f0
    assert f0 == pytest.approx(f_ref, rel=0.01)
    assert f0 > 0.8 / 0.95 * weight
    assert frac[0] == pytest.approx(0.8, abs=0.03)
    assert frac.max() > 0.9
    assert frac.max() < 1.1
    assert np.isfinite(force).all()


def test_water_volume_is_kept_while_the_cube_moves_through_the_surface(short_float):
    model, v0, f0, frac, force = short_float
    assert abs(_water_volume_m3(model) / v0 - 1) < 5e-3
    model.coupling.check_populations()


def test_kinematic_box_pushes_two_floating_cubes_and_keeps_the_water():
    """A box (16 x 16 x 8 cells) moving at 0.04 cells/step through the surface towards two floating 6-cell cubes
    one cell ahead of it, 150 steps (6 cells): no NaN, water volume kept within 0.5 %, both cubes pushed
    forwards by more than a cell."""
    n, edge = 6, fc.EDGE_M
    dx = edge / n
    model = FloatingBodies((32, 24, 24), depth_m=12 * dx, dx_m=dx, tau=0.55, g_lattice=1e-3)
    u_ship = 0.04 * dx / model.dt_s
    hull = (16 * dx, 16 * dx, 8 * dx)
    model.add_body(Box(hull), box(hull, 500.0), position_m=(9 * dx, 12 * dx, 12 * dx), velocity_m_s=(u_ship, 0, 0),
                   kinematic=True)
    for y in (7.0, 17.0):
        model.add_body(Box((edge,) * 3), box((edge,) * 3, 950.0), position_m=(21 * dx, y * dx, (12 - 5.7 + 3) * dx))
    model.start()
    v0 = model.water_volume_m3()
    x0 = model.dem.positions[1:, 0].copy()
    model.step(150)
    model.coupling.check_populations()
    assert abs(model.water_volume_m3() / v0 - 1) < 5e-3
    assert (model.dem.positions[1:, 0] - x0 > dx).all()
    assert np.isfinite(model.fluid_force_N).all()


def test_redistribution_block_form_equals_the_cell_form():
    """The CPU block form of the free-surface redistribution (only the cells next to an event visited,
    :func:`build_redistribute_block`) against the per-cell visit of every cell of the event blocks: a kinematic
    box moving through the surface past two floating cubes, 40 steps, the same populations, h and phi (a cell
    with nothing to take adds 0, so only the sign of a zero may differ). An offset left out of the event mask
    fails it."""
    from iceresist.backends.launch import ActiveLauncher
    from iceresist.coupling.kernels import REDIST_FS_ARGS
    from iceresist.coupling.surface_kernels import build_surface_visits

    n, edge = 6, fc.EDGE_M
    dx = edge / n
    out, events = [], []
    for per_cell in (False, True):
        model = FloatingBodies((32, 24, 24), depth_m=12 * dx, dx_m=dx, tau=0.55, g_lattice=1e-3)
        u_ship = 0.04 * dx / model.dt_s
        hull = (16 * dx, 16 * dx, 8 * dx)
        model.add_body(Box(hull), box(hull, 500.0), position_m=(9 * dx, 12 * dx, 12 * dx),
                       velocity_m_s=(u_ship, 0, 0.002 * dx / model.dt_s), kinematic=True)
        for y in (7.0, 17.0):
            model.add_body(Box((edge,) * 3), box((edge,) * 3, 950.0), position_m=(21 * dx, y * dx, (12 - 5.7 + 3) * dx))
        model.start()           # its first boundaries with the block form in both runs
        if per_cell:
            cp = model.coupling
            visit = build_surface_visits(jit.cpu, cp.real, model.fluid.phase.lat)[1]
            cp._k = {**cp._k, "redistribute": ActiveLauncher(jit.cpu, visit, REDIST_FS_ARGS, label="redistribute_fs")}
        ev = 0
        for _ in range(40):
            model.step(1)
            ev += model.coupling.event_blocks
        events.append(ev)
        fl = model.fluid
        out.append((fl.fluid.populations(), np.array(fl.phase.h), np.array(fl.phase.phi)))
    assert events[0] == events[1] > 40
    for a, b, name in zip(out[0], out[1], ("f", "h", "phi")):
        assert np.array_equal(a, b), name


@pytest.mark.slow
def test_floating_cube_settles_at_95_percent_and_its_heave_decays():
    """8 cells per edge, six estimated periods: the submerged fraction over the last period within 0.02 of 0.95,
    successive heave extremes decay, the natural period lies between the estimates with C_a = 0 and C_a = 1."""
    series, model, steps, wall = fc.simulate(8, 6.0, release_draft=0.8)
    heave = fc.heave_analysis(series[:, 0], series[:, 1], fc.period_estimate_s(added_mass=0.5))
    assert heave["mean"] == pytest.approx(0.95, abs=0.02)
    assert heave["half_ratio"] < 0.8
    assert fc.period_estimate_s() < heave["natural_period_s"] < fc.period_estimate_s(added_mass=1.0)
    assert np.abs(series[:, 3]).max() < 5e-3


# 120 s on the simulator (2-core x86 VM): CI time; test_transfers.py steps floating bodies on it in CI
@pytest.mark.slow
def test_cpu_and_cuda_simulator_agree_for_a_cube_moving_through_the_surface():
    """A kinematic 4-cell cube moving down and sideways through the surface of an 8 x 8 x 16 tank, 4 steps: its
    faces cross planes of cell centres, so cells are covered (phi handed over) and uncovered (phi and h refilled,
    liquid and gas) under and at the surface, and phi is mirrored into it. The CUDA kernels (simulator) reproduce
    the CPU phi, flags, liquid populations and force to round-off (float64)."""
    dx = 0.01
    out = {}
    for name, target in (("cpu", jit.cpu), ("cuda", jit.cuda())):
        model = FloatingBodies((8, 8, 16), depth_m=8 * dx, dx_m=dx, tau=0.6, g_lattice=1e-3, target=target)
        v = dx / model.dt_s                         # one cell per step in m/s
        model.add_body(Box((4 * dx,) * 3), box((4 * dx,) * 3, 900.0), position_m=(3.45 * dx, 4.1 * dx, 7.62 * dx),
                       velocity_m_s=(0.08 * v, 0.0, -0.1 * v), angular_velocity_rad_s=(0.0, 0.01 / model.dt_s, 0.0),
                       kinematic=True)
        model.start()
        events = 0
        for _ in range(4):
            model.step(1)
            events += model.coupling.event_blocks
        phi, rho, u = model.fields()
        flags = np.array(model.fluid._host(model.fluid.fluid.flags))
        out[name] = (phi, flags, model.fluid.fluid.populations(), model.fluid_force_N.copy(),
                     model.fluid_torque_N_m.copy(), model.coupling.owners(), events)
    cpu, gpu = out["cpu"], out["cuda"]
    assert cpu[6] > 0                                   # cells were covered or uncovered
    assert np.array_equal(cpu[5], gpu[5]) and np.array_equal(cpu[1], gpu[1])
    assert np.allclose(cpu[0], gpu[0], rtol=0, atol=1e-13)
    liquid = (cpu[1] & FL.FLUID) != 0
    assert np.allclose(cpu[2].transpose(1, 0, 2)[:, liquid], gpu[2].transpose(1, 0, 2)[:, liquid], rtol=0, atol=1e-13)
    scale = np.abs(cpu[3]).max()
    assert scale > 0
    assert np.allclose(cpu[3], gpu[3], rtol=0, atol=1e-11 * scale)
    assert np.allclose(cpu[4], gpu[4], rtol=0, atol=1e-11 * np.abs(cpu[4]).max() + 1e-300)
