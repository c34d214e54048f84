"""Moving-boundary coupling: signed distances, cell marking, forces by momentum exchange, refill, mass, CPU vs CUDA."""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.coupling import Box, ConvexPolyhedron, FluidStructureCoupling, Sphere
from iceresist.dem import DEMSystem, box, sphere
from iceresist.grid.forest import BlockForest
from iceresist.lattice import C
from iceresist.lbm.solver import LBMSolver
from iceresist.units import Units
from tests.conftest import SIMULATED

UNITS = Units.lattice(tau=0.8)     # lattice units throughout (dx = dt = rho0 = 1; the coupling reads only these)


def quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3), body -> world, of unit quaternions (n, 4) (w, x, y, z): the host reference
    for the rotation the coupling computes on the target (iceresist.coupling.bodystate)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


def _setup(shape, geometry, shape_dem, position, velocity=(0, 0, 0), omega=(0, 0, 0), u_fluid=(0, 0, 0),
           orientation=None, target=jit.cpu, debug=False, tau=0.6):
    fo = BlockForest.uniform(shape)
    solver = LBMSolver(fo, tau=tau, operator="bgk", precision="float64", target=target)
    solver.initialize(u=u_fluid)
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    dem.add_body(shape_dem, position_m=position, velocity_m_s=velocity, angular_velocity_rad_s=omega,
                 orientation=orientation, kinematic=True)
    return solver, dem, FluidStructureCoupling(solver, dem, [geometry], UNITS, debug=debug)


def _momentum(solver, coupling):
    f = solver.populations()
    m = coupling.fluid_mask()
    return np.einsum("qa,bqc->a", C.astype(float), np.where(m[:, None, :], f, 0.0))


def test_signed_distances_are_exact_for_sphere_box_and_hull():
    p = np.array([[0.0, 0, 0], [3.0, 0, 0], [2.0, 3.0, 0], [3.0, 4.0, 2.0], [0.5, 0.2, -0.1]])
    assert np.allclose(Sphere(1.0).sdf(p), np.linalg.norm(p, axis=1) - 1.0)
    b = Box((2.0, 4.0, 2.0))                     # half extents 1, 2, 1
    expect = [-1.0, 2.0, np.hypot(1.0, 1.0), 3.0, -0.5]      # (2, 2, 1) outside the corner; 0.5 to the x face
    assert np.allclose(b.sdf(p), expect)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-2, 2) for sz in (-1, 1)], dtype=float)
    hull = ConvexPolyhedron(corners)
    inside = p[b.sdf(p) <= 0]
    assert np.allclose(hull.sdf(inside), b.sdf(inside))
    face_region = np.array([[3.0, 0.5, 0.2], [0.1, -5.0, 0.3]])     # nearest point inside a face: exact
    assert np.allclose(hull.sdf(face_region), b.sdf(face_region))
    corner_region = np.array([[3.0, 4.0, 2.0]])                      # near a corner: max of planes <= distance
    assert hull.sdf(corner_region)[0] <= b.sdf(corner_region)[0]
    assert hull.volume_m3() == pytest.approx(16.0)


def test_marked_cells_match_the_signed_distance_of_a_rotated_box():
    angle = 0.4
    q = np.array([np.cos(angle / 2), 0.3 * np.sin(angle / 2), 0.0, np.sqrt(0.91) * np.sin(angle / 2)])
    size = (9.0, 6.0, 5.0)
    solver, dem, cp = _setup((32, 24, 24), Box(size), box(size, 900.0), (15.3, 11.7, 12.2), orientation=q)
    cp.update_boundaries()
    x, y, z = solver.forest.cell_coordinates()
    pts = np.stack([x, y, z], axis=-1) + 0.5 - dem.positions[0]
    R = quaternion_matrices(dem.quaternions)[0]
    sdf = Box(size).sdf(pts @ R)
    owners = cp.owners()
    assert ((owners == 0) == (sdf < 0)).all()
    assert (owners == 0).sum() == pytest.approx(np.prod(size), rel=0.1)
    assert cp.links[0] > 0


def test_body_at_rest_in_fluid_at_rest_feels_no_force_and_leaves_the_fluid_at_rest():
    solver, dem, cp = _setup((16, 16, 16), Sphere(3.2), sphere(3.2, 1000.0), (8.1, 7.9, 8.3))
    cp.step(5)
    assert np.abs(cp.force_lattice).max() < 1e-13
    assert np.abs(cp.torque_lattice).max() < 1e-12
    rho, u = solver.macroscopic()
    assert np.nanmax(np.abs(u)) < 1e-14


@pytest.fixture(scope="module")
def drag_runs():
    """A sphere (d = 8 cells) held in a periodic box of flowing fluid, and the same sphere moving through
    fluid at rest (the Galilean twin), 200 steps each; force histories and fluid momenta."""
    U, R, shape = 0.04, 4.0, (32, 24, 24)
    out = {}
    for case in ("fixed", "moving"):
        vel = (0.0, 0, 0) if case == "fixed" else (-U, 0, 0)
        uf = (U, 0, 0) if case == "fixed" else (0, 0, 0)
        solver, dem, cp = _setup(shape, Sphere(R), sphere(R, 1000.0), (20.0, 12.0, 12.0), velocity=vel,
                                 u_fluid=uf)
        forces, momenta = [], []
        for _ in range(200):
            momenta.append(_momentum(solver, cp))
            cp.step(1)
            forces.append(cp.force_lattice[0].copy())
        out[case] = (np.array(forces), np.array(momenta), cp)
    return out


def test_momentum_exchange_balances_the_fluid_momentum(drag_runs):
    """Fixed sphere: the fluid loses what the sphere gains, d/dt (sum c f) = -F (eq. 17-18)."""
    forces, momenta, _ = drag_runs["fixed"]
    lost = momenta[60, 0] - momenta[199, 0]
    impulse = forces[60:199, 0].sum()
    assert impulse > 0
    assert lost == pytest.approx(impulse, rel=0.02)


def test_moving_sphere_feels_the_drag_of_the_fixed_sphere_in_moving_fluid(drag_runs):
    """Galilean invariance of eq. (17): same drag within 3 % (averaged over steps 100-200)."""
    fixed = drag_runs["fixed"][0][100:, 0].mean()
    moving = drag_runs["moving"][0][100:, 0].mean()
    assert fixed > 0
    assert moving == pytest.approx(fixed, rel=0.03)


def _moving_sphere_run(diameters, d_cells, U, shape, check_every):
    R = d_cells / 2
    solver, dem, cp = _setup(shape, Sphere(R), sphere(R, 1000.0), (shape[0] / 2, shape[1] / 2, shape[2] / 2),
                             velocity=(U, 0.3 * U, 0.0), omega=(0.0, 0.0, 0.02), debug=True)
    cp.update_boundaries()
    m0, _ = cp.fluid_mass()
    steps = int(round(diameters * d_cells / U))
    worst = 0.0
    for i in range(steps):
        cp.step(1)
        if (i + 1) % check_every == 0 or i == steps - 1:
            cp.check_populations()
            m, _ = cp.fluid_mass()
            worst = max(worst, abs(m - m0) / m0)
    return worst, cp


def test_moving_sphere_keeps_the_water_mass_and_leaves_no_cell_empty():
    """A sphere (d = 4) crossing a periodic box 5 diameters, NaN-poisoned covered cells: no fluid cell
    ever reads an unset population, and the fluid mass stays within 0.5 %."""
    worst, cp = _moving_sphere_run(5, 4, 0.08, (32, 16, 16), 25)
    assert worst < 5e-3
    assert cp.dem.positions[0, 0] == pytest.approx(16.0 + 20.0)


@pytest.mark.slow
def test_moving_sphere_keeps_the_water_mass_over_20_diameters():
    worst, _ = _moving_sphere_run(20, 6, 0.05, (48, 24, 24), 50)
    assert worst < 5e-3


def test_debug_check_finds_a_cell_without_populations():
    solver, dem, cp = _setup((16, 16, 16), Sphere(3.0), sphere(3.0, 1000.0), (8.0, 8.0, 8.0))
    cp.step(1)
    f = solver.state
    mask = cp.fluid_mask()
    b, c = np.argwhere(mask)[0]
    f[b, 5, c] = np.nan
    with pytest.raises(Exception, match="non-finite"):
        cp.check_populations()


def test_cpu_and_cuda_simulator_agree_for_a_moving_rotating_box():
    size = (5.0, 4.0, 3.0)
    args = dict(velocity=(0.05, -0.02, 0.01), omega=(0.01, 0.02, -0.03), u_fluid=(0.01, 0.0, 0.0),
                orientation=np.array([0.95, 0.1, 0.2, 0.2]) / np.linalg.norm([0.95, 0.1, 0.2, 0.2]))
    res = {}
    for name, target in (("cpu", jit.cpu), ("cuda", jit.cuda())):
        solver, dem, cp = _setup((16, 16, 16), Box(size), box(size, 900.0), (8.2, 7.7, 8.4), target=target, **args)
        cp.step(2)
        res[name] = (solver.populations(), cp.force_lattice.copy(), cp.torque_lattice.copy(), cp.owners())
    assert (res["cpu"][3] == res["cuda"][3]).all()
    assert np.allclose(res["cpu"][1], res["cuda"][1], rtol=1e-10, atol=1e-14)
    assert np.allclose(res["cpu"][2], res["cuda"][2], rtol=1e-10, atol=1e-14)
    fluid = res["cpu"][3] < 0
    assert np.allclose(res["cpu"][0][:, :, :][np.broadcast_to(fluid[:, None, :], res["cpu"][0].shape)],
                       res["cuda"][0][np.broadcast_to(fluid[:, None, :], res["cuda"][0].shape)], atol=1e-14)


def test_launch_rows_partition_each_box_into_runs():
    from iceresist.coupling.coupler import slab_counts, tile_rows

    bint = np.array([[1, 0, 6, 0, 0, 0, 3, 3, 3],            # 64 cells: stays one row
                     [1, 6, 6, -2, 5, 1, 9, 12, 10]], np.int32)  # 12 x 8 x 10 = 960 cells: 10 runs of 96
    assert slab_counts(bint, 100).tolist() == [1, 10] and slab_counts(bint, 1).tolist() == [64, 960]
    assert slab_counts(bint, 300).tolist() == [1, 4] and slab_counts(bint, 10 ** 6).tolist() == [1, 1]
    empty = np.array([[1, 0, 6, 5, 0, 0, 4, 3, 3]], np.int32)   # clipped away: no cells, still one row
    assert slab_counts(empty, 100).tolist() == [1]
    rows = tile_rows(slab_counts(bint, 100))
    assert rows[:, 0].tolist() == [1] * 5 + [0] + [1] * 5           # the runs spread around the small body
    assert sorted(rows[rows[:, 0] == 1, 1].tolist()) == list(range(10)) and (rows[rows[:, 0] == 1, 2] == 10).all()
    assert rows[rows[:, 0] == 0].tolist() == [[0, 0, 1]]
    assert tile_rows([1, 4])[:, 0].tolist() == [1, 1, 0, 1, 1]


@pytest.mark.parametrize("runs", [4, 12, 33, 1000])
def test_runs_partition_the_cell_box_of_a_body(runs):
    """The rows of a body split into ``runs`` runs visit every cell of its box once: 4, 12 or 33 runs of nearly
    equal length (they differ by at most one cell), or 1000 runs, more than the box's cells, of which the surplus
    stay empty. Each row's box keeps the whole box in x and y and only the planes its run touches; the boxes come
    from the body state on the target (iceresist.coupling.bodystate)."""
    _, dem, cp = _setup((16, 16, 16), Box((4.0, 5.0, 6.0)), box((4.0, 5.0, 6.0), 900.0), (8.2, 7.7, 8.4))
    cp._slabs = np.array([runs])
    cp.update_boundaries()
    whole = cp._host(cp._d["box"])[0]
    ext = whole[3:] - whole[:3] + 1
    assert ext[2] == 10
    bint = cp._host(cp._d["bint"]).astype(np.int64)
    assert len(bint) == runs and (bint[:, 3:5] == whole[:2]).all() and (bint[:, 6:8] == whole[3:5]).all()
    plane = ext[0] * ext[1]
    cells = np.concatenate([(r[5] - whole[2]) * plane + np.arange(r[10], r[11]) for r in bint])
    assert np.sort(cells).tolist() == list(range(ext.prod()))
    lengths = bint[:, 11] - bint[:, 10]
    assert lengths.max() - lengths.min() <= 1 and lengths.sum() == ext.prod()
    full = lengths > 0
    first_plane = whole[2] + ((bint[full, 5] - whole[2]) * plane + bint[full, 10]) // plane
    last_plane = whole[2] + ((bint[full, 5] - whole[2]) * plane + bint[full, 11] - 1) // plane
    assert (first_plane == bint[full, 5]).all() and (last_plane == bint[full, 8]).all()
    assert (bint[full, 10] < plane).all()


@pytest.mark.slow   # 226 s with 2 test processes on a 2-core x86 VM
def test_mark_and_link_run_forms_give_the_results_of_the_cell_forms():
    """The CPU run forms of ``mark`` (the sign of the next cells of a line taken from an evaluated cell: from its face
    planes for a box or a convex polyhedron, floor(|d| - 0.01) cells for a sphere) and of the link pass (cells far
    outside or deeper than 2 inside passed over) against the per-cell visits: a sphere, a rotated box, a rotated
    convex polyhedron, a union of three convex pieces (evaluated at every cell), a sphere across the periodic x
    boundary and a box longer than half the periodic length (evaluated at every cell), moving and spinning in a
    periodic 48 x 32 x 32 box with a stream, launched whole and in runs of 200 cells: the same owner in every cell,
    the same populations written, links, forces and torques. Skipping one cell too many (floor(|d| + 1) for the
    sphere, one more than the planes allow for the boxes and the polyhedron, iceresist.coupling.runs) fails it."""
    from iceresist.backends.launch import BodyLauncher
    from iceresist.coupling.geometry import ConvexUnion
    from iceresist.coupling.kernels import LINK_ARGS, MARK_ARGS, build_visits
    from iceresist.dem import convex_polyhedron

    octahedron = np.array([[6.0, 0, 0], [-6, 0, 0], [0, 5, 0], [0, -5, 0], [0, 0, 4], [0, 0, -4.5]])
    a = np.array([[x, y, z] for x in (-8.0, 0.0) for y in (-3.0, 3.0) for z in (-2.0, 2.0)])
    b = np.array([[x, y, z] for x in (0.0, 6.0) for y in (-3.0, 3.0) for z in (-2.0, 7.0)])
    w = np.array([[6.0, -3, -2], [6, 3, -2], [6, -3, 2], [6, 3, 2], [11, 0, -2], [11, 0, 2]])
    q1 = np.array([0.9, 0.2, -0.3, 0.25])
    q2 = np.array([0.8, -0.1, 0.4, 0.3])
    oct_shape = convex_polyhedron(octahedron, 900.0, 1.0)
    union_shape = convex_polyhedron(np.vstack([a, b, w]), 900.0, 1.0)
    bodies = [(Sphere(5.3), sphere(5.3, 900.0), (10.2, 8.3, 9.1), None),
              (Box((9.0, 6.4, 4.2)), box((9.0, 6.4, 4.2), 900.0), (30.4, 10.2, 20.3), q1),
              (ConvexPolyhedron.of_shape(octahedron, oct_shape), oct_shape, (20.3, 21.7, 12.2), q2),
              (ConvexUnion.of_shape([a, b, w], 1.0, union_shape), union_shape, (34.1, 22.6, 12.4), q1),
              (Sphere(4.0), sphere(4.0, 900.0), (0.7, 20.2, 22.3), None),
              (Box((30.0, 3.0, 3.0)), box((30.0, 3.0, 3.0), 900.0), (24.2, 26.3, 27.1), None)]
    rng = np.random.default_rng(3)
    for tile in (10 ** 6, 200):
        solver = LBMSolver(BlockForest.uniform((48, 32, 32)), tau=0.6, operator="bgk", precision="float64")
        solver.initialize(u=(0.02, -0.01, 0.005))
        dem = DEMSystem(gravity_m_s2=(0, 0, 0))
        for _, shape, pos, q in bodies:
            dem.add_body(shape, position_m=pos, orientation=q, velocity_m_s=tuple(rng.uniform(-0.02, 0.02, 3)),
                         angular_velocity_rad_s=tuple(rng.uniform(-0.005, 0.005, 3)), kinematic=True)
        cp = FluidStructureCoupling(solver, dem, [g for g, *_ in bodies], UNITS)
        cp.tile_cells = tile
        cp.step(3)
        cp.update_boundaries()
        d, rows = cp._d, len(cp._rows)
        mark, links = build_visits(jit.cpu, cp.real)[:2]
        owner = np.full_like(d["owner"], -1)
        BodyLauncher(jit.cpu, mark, MARK_ARGS, label="mark_cells")(
            rows, d["bint"], d["body"], d["planes"], d["grid"], d["block_map"], d["flags0"], owner)
        assert np.array_equal(owner, d["owner"])
        owners = cp.owners()
        assert all((owners == i).sum() > 40 for i in range(len(bodies)))
        out = []
        for launch in (cp._k["links"], BodyLauncher(jit.cpu, links, LINK_ARGS, label="links_cells")):
            f = np.array(solver.state)
            sums = [np.zeros_like(d[n]) for n in ("bforce", "btorque", "nlinks")]
            launch(rows, d["bint"], d["body"], d["planes"], d["grid"], d["block_map"], d["flags0"], d["owner"], f,
                   *sums, solver.flags, d["film"], np.int64(cp.nowned))
            out.append((f, *sums))
        assert out[0][3].sum() > 1000                           # links counted
        for a, b in zip(out[0], out[1]):
            assert np.array_equal(a, b)


def _two_moving_boxes(target, tile_cells, steps, recount=False):
    """A small and a larger box moving (and the larger one spinning) in different directions through a periodic
    32 x 16 x 16 channel, launched with ``tile_cells`` per row; ``recount``: count the slabs anew every step."""
    fo = BlockForest.uniform((32, 16, 16))
    solver = LBMSolver(fo, tau=0.6, operator="bgk", precision="float64", target=target)
    solver.initialize(u=(0.01, 0.0, 0.0))
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    q = np.array([0.95, 0.1, 0.2, 0.2]) / np.linalg.norm([0.95, 0.1, 0.2, 0.2])
    small, large = (2.0, 2.0, 2.0), (5.0, 4.0, 3.0)
    dem.add_body(box(small, 900.0), position_m=(4.3, 8.1, 8.2), velocity_m_s=(-0.2, 0.1, 0.05), kinematic=True)
    dem.add_body(box(large, 900.0), position_m=(16.2, 7.7, 8.4), velocity_m_s=(0.3, -0.12, 0.06),
                 angular_velocity_rad_s=(0.01, 0.02, -0.03), orientation=q, kinematic=True)
    cp = FluidStructureCoupling(solver, dem, [Box(small), Box(large)], UNITS)
    cp.tile_cells = tile_cells
    rows = set()
    for _ in range(steps):
        if recount:
            cp.tile_cells = tile_cells
        cp.step(1)
        rows.add(None if cp._tile_body is None else tuple(cp._tile_body))
    return (solver.populations(), cp.force_lattice.copy(), cp.torque_lattice.copy(), cp.owners(), cp.links.copy(),
            rows)


@pytest.mark.parametrize("backend", ["cpu", pytest.param("cuda", marks=pytest.mark.slow)])   # cuda: 120 s, CI time
def test_bodies_split_into_runs_give_the_unsplit_result(backend):
    """Two moving boxes launched as runs of at most 64 cells (20 rows) cover the same cells and give the same
    populations, forces and torques (to the order of summation) as launched whole, over 8 steps in which their
    cell boxes change and they uncover cells: the refill reads the velocity of the body that uncovered a cell
    through the row that covered it a step earlier, so the rows must keep their bodies (counting the runs anew
    every step moves them: the populations then differ by 0.035). On the CUDA simulator 2 steps (each uncovers
    6-9 cells; the second's refill reads the rows of the first): a simulated step takes 20-30 s, and 8 + 8 of them
    made this the longest test of the suite."""
    target = jit.cpu if backend == "cpu" else jit.cuda()
    steps = 2 if backend == "cuda" and SIMULATED else 8
    whole, split = _two_moving_boxes(target, 10 ** 6, steps), _two_moving_boxes(target, 64, steps)
    assert whole[5] == {None} and len(split[5]) == 1 and len(next(iter(split[5]))) == 20
    assert (whole[3] == split[3]).all() and (whole[3] == 1).sum() > 40 and (whole[3] == 0).sum() > 5
    assert (whole[4] == split[4]).all() and whole[4][1] > 100
    assert np.allclose(whole[1], split[1], rtol=1e-12, atol=1e-15) and np.abs(whole[1]).max() > 1e-4
    assert np.allclose(whole[2], split[2], rtol=1e-12, atol=1e-15)
    assert np.allclose(whole[0], split[0], rtol=0, atol=1e-15)
    if backend == "cpu":
        moved = _two_moving_boxes(target, 64, 8, recount=True)
        assert len(moved[5]) > 1 and np.abs(moved[0] - whole[0]).max() > 1e-3


@pytest.mark.slow   # 47 s on a busy 2-core x86 VM (200 coupled steps of a 24^3 box)
def test_rotating_sphere_carried_by_the_stream_feels_its_torque_and_no_force():
    """Galilean check of the wall-velocity term of eq. (17): a sphere (a = 4 cells) rotating at Omega = 0.01 about z
    and moving with a uniform stream U = 0.04 along x (periodic 24^3 box, tau = 0.8) has no velocity relative to the
    fluid but its spin. Force: zero; measured mean over steps 100-200 (-6e-4, 3.8e-3, 0) (steps scatter 5.7e-3 in
    y), asserted |F| < 0.03. Without the u_w (f*_opp - f_q) term, or with its sign flipped, the
    links carry the moving surface's momentum flux rho u_w (u_w . n), which sums to 2 rho V Omega x U = 0.214 in y
    for the flipped sign (measured -0.214): it fails. On a sphere that only spins (u_w . n = 0) or a body that only
    translates (closed surface) that flux sums to zero, which is why the drag tests above cannot see the term.
    Torque: 8 pi mu a^3 Omega (Stokes) times the periodic-array correction, measured 1.058 at solid fraction
    1.9 % and 4 cells per radius; asserted within 1.00-1.10 (its sign is that of the bounce-back's 6 w rho c.u_w)."""
    a, U, omega, tau = 4.0, 0.04, 0.01, 0.8
    solver, dem, cp = _setup((24, 24, 24), Sphere(a), sphere(a, 1000.0), (12.0, 12.0, 12.0), velocity=(U, 0, 0),
                             omega=(0, 0, omega), u_fluid=(U, 0, 0), tau=tau)
    forces, torques = [], []
    for _ in range(200):
        cp.step(1)
        forces.append(cp.force_lattice[0].copy())
        torques.append(cp.torque_lattice[0].copy())
    force = np.mean(forces[100:], axis=0)
    torque = np.mean(torques[100:], axis=0)
    assert np.abs(force).max() < 0.03, force
    stokes = 8 * np.pi * (tau - 0.5) / 3 * a**3 * omega
    assert -1.10 < torque[2] / stokes < -1.00


def test_spinning_sphere_carried_by_the_stream_feels_no_force():
    """The force half of the slow test above in 40 steps (the wall-velocity flux is there from the first step):
    mean over steps 20-40 measured (-5e-4, 6.7e-3, 0), asserted |F| < 0.05; the u_w term of eq. (17) with its sign
    flipped gives Fy = -0.211 (2 rho V Omega U = 0.214) and fails."""
    a, U, omega = 4.0, 0.04, 0.01
    solver, dem, cp = _setup((24, 24, 24), Sphere(a), sphere(a, 1000.0), (12.0, 12.0, 12.0), velocity=(U, 0, 0),
                             omega=(0, 0, omega), u_fluid=(U, 0, 0), tau=0.8)
    forces = []
    for _ in range(40):
        cp.step(1)
        forces.append(cp.force_lattice[0].copy())
    force = np.mean(forces[20:], axis=0)
    assert np.abs(force).max() < 0.05, force
