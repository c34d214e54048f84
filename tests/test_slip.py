"""Free-slip faces (specular reflection, ``iceresist.lbm.boundary``) against closed forms.

* A force-driven channel with a no-slip wall on one side and a free-slip face on the other is one half
  of the symmetric Poiseuille channel: u(s) = F / (2 nu) s (2 N - s), s the distance from the no-slip
  half-way wall, zero shear at the slip face s = N. Every normal axis and flow axis, slip face on
  either side, so each mirrored direction of the generated kernel is used.
* A uniform flow parallel to two slip faces stays uniform to round-off (no shear enters).
* A closed box with slip faces (edges and corners shared with slip and no-slip faces) keeps its mass
  to round-off: the reflection maps leaving populations one to one onto entering ones.
* The CUDA launcher (simulator without a GPU) matches the CPU one.
"""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.grid import BlockForest, Face
from iceresist.lbm.solver import LBMSolver
from tests.test_poiseuille import run_to_steady

TAU = 0.8
NU = (TAU - 0.5) / 3.0
AXES = "xyz"


def half_channel_error(n, normal, flow, slip_side, operator="bgk", precision="float64", rtol=1e-8):
    """Relative L2 error of the steady profile across ``normal`` (n cells) against the half-Poiseuille; steady
    when the velocity changes by less than ``rtol`` of its largest value over a chunk."""
    u_max = 0.01
    force = 2.0 * NU * u_max / n ** 2             # u(N) = F N^2 / (2 nu)
    a, b = AXES.index(normal), AXES.index(flow)
    shape = [8, 8, 8]
    shape[a] = n
    wall_side = "+" if slip_side == "-" else "-"
    faces = {normal + slip_side: Face("slip"), normal + wall_side: Face("wall")}
    fo = BlockForest.uniform(tuple(shape), faces=faces)
    F = [0.0, 0.0, 0.0]
    F[b] = force
    s = LBMSolver(fo, tau=TAU, force=tuple(F), operator=operator, precision=precision, target=jit.cpu)
    pos = np.indices(shape)[a] + 0.5
    dist = pos if wall_side == "-" else n - pos   # distance from the no-slip wall
    exact = force / (2 * NU) * dist * (2 * n - dist)
    u0 = np.zeros((3, *shape))
    u0[b] = 0.5 * exact                           # start away from the answer
    s.initialize(u=u0)
    u = run_to_steady(s, chunk=max(50, int(0.1 * 4 * n * n / (NU * np.pi ** 2))), rtol=rtol,
                      max_steps=160 * n * n)
    other = [c for c in range(3) if c != b]
    assert np.nanmax(np.abs(u[other])) < 1e-12                 # no cross flow
    prof, ref = np.moveaxis(u[b], a, 0).reshape(n, -1), np.moveaxis(exact, a, 0).reshape(n, -1)[:, 0]
    assert np.nanmax(np.abs(prof - prof[:, :1])) < 1e-12       # uniform along the face
    prof, exact = prof[:, 0], ref
    return float(np.sqrt(np.sum((prof - exact) ** 2) / np.sum(exact ** 2)))


@pytest.mark.parametrize("normal, flow", [("z", "x"), ("z", "y"), ("x", "y"), ("x", "z"), ("y", "z"), ("y", "x")])
@pytest.mark.parametrize("slip_side", ["-", "+"])
def test_half_channel_matches_half_poiseuille(normal, flow, slip_side):
    # steady to 1e-6 (the transient left is 1e-5 of the profile, the bound 2e-3): 30 % fewer steps than 1e-8
    err = half_channel_error(16, normal, flow, slip_side, rtol=1e-6)
    assert err < 2e-3, err


def test_half_channel_second_order_cumulant():
    e = [half_channel_error(n, "z", "x", "+", operator="cumulant") for n in (8, 16, 32)]
    orders = np.log2(np.array(e[:-1]) / np.array(e[1:]))
    assert e[-1] < 5e-4 and np.all(np.abs(orders - 2.0) < 0.25), (e, orders)


def test_uniform_flow_between_slip_faces_stays_uniform():
    fo = BlockForest.uniform((16, 8, 16), faces={"z-": Face("slip"), "z+": Face("slip")})
    s = LBMSolver(fo, tau=0.6, operator="cumulant", precision="float64", target=jit.cpu)
    U = np.array([0.05, -0.02, 0.0])
    s.initialize(u=np.broadcast_to(U[:, None, None, None], (3, 16, 8, 16)))
    s.step(200)
    rho, u = s.macroscopic()
    assert np.nanmax(np.abs(u - U[:, None, None, None])) < 1e-13
    assert np.nanmax(np.abs(rho - 1.0)) < 1e-13
    # the same flow between no-slip walls is slowed at the walls: the check above can fail
    fo = BlockForest.uniform((16, 8, 16), faces={"z-": Face("wall"), "z+": Face("wall")})
    w = LBMSolver(fo, tau=0.6, operator="cumulant", precision="float64", target=jit.cpu)
    w.initialize(u=np.broadcast_to(U[:, None, None, None], (3, 16, 8, 16)))
    w.step(200)
    assert np.nanmax(np.abs(w.macroscopic()[1] - U[:, None, None, None])) > 1e-3


def closed_box(precision, target, rng):
    """16^3 cells: slip floor and x faces, no-slip y faces, slip lid; random start, a body force."""
    faces = {"x-": Face("slip"), "x+": Face("slip"), "y-": Face("wall"), "y+": Face("wall"),
             "z-": Face("slip"), "z+": Face("slip")}
    fo = BlockForest.uniform((16, 16, 16), faces=faces)
    s = LBMSolver(fo, tau=0.7, force=(1e-5, -2e-5, 3e-6), operator="bgk", precision=precision, target=target)
    s.initialize(rho=1 + 0.01 * rng.standard_normal(fo.shape_cells),
                 u=0.02 * rng.standard_normal((3, *fo.shape_cells)))
    return s


def test_closed_box_keeps_its_mass(rng):
    s = closed_box("float64", jit.cpu, rng)
    m0 = s.mass()
    s.step(300)
    assert abs(s.mass() - m0) < 1e-11 * m0
    assert np.isfinite(s.populations()).all()


def test_cuda_matches_cpu_with_slip_faces(precision):
    if not jit.cuda_available():
        pytest.skip("no CUDA GPU and the simulator is off")
    cpu = closed_box(precision, jit.cpu, np.random.default_rng(3))
    gpu = closed_box(precision, jit.cuda(), np.random.default_rng(3))
    cpu.step(2)
    gpu.step(2)
    a, b = cpu.populations(), gpu.populations()
    assert np.abs(a - b).max() < {"float32": 1e-6, "float64": 1e-13}[precision]
    assert np.abs(a).max() > 1e-3


def test_scene_face_kind_slip():
    """A scene names a free-slip face `slip`; it has no velocity, and the forest gives it the slip code."""
    from pydantic import ValidationError

    from iceresist.grid import flags as FL
    from iceresist.scene.schema import Face as SceneFace

    assert SceneFace(kind="slip").kind == "slip"
    with pytest.raises(ValidationError, match="velocity_m_s"):
        SceneFace(kind="slip", velocity_m_s=(0.1, 0.0, 0.0))
    fo = BlockForest.uniform((8, 8, 16), faces={"z-": Face("slip"), "z+": Face("wall")})
    assert fo.bc_kind[1 + 4] == FL.BC_SLIP and fo.bc_kind[1 + 5] == FL.BC_WALL
    assert (fo.flags[fo.cell_coordinates()[2] == 0] & FL.NEAR_WALL).all()
