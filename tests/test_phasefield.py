"""Phase-field LBM (paper eqs. 4-10): profile, Galilean advection, volume, CPU vs CUDA."""

import numpy as np
import pytest

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.freesurface.hlattice import H_LATTICES, h_lattice
from iceresist.grid.forest import CELLS, BlockForest, Face
from iceresist.freesurface.phasefield import PhaseField
from iceresist.errors import InputError

W = 3.0


def tanh_profile(s):
    """Equilibrium profile of eq. (4) across a flat interface, s = signed distance into the liquid."""
    return 0.5 + 0.5 * np.tanh(2.0 * s / W)


def slab(z, lo, hi, length):
    """Periodic liquid slab lo < z < hi with tanh edges."""
    centre = 0.5 * (lo + hi)
    s = 0.5 * (hi - lo) - np.abs((z - centre + length / 2) % length - length / 2)
    return tanh_profile(s)


@pytest.mark.parametrize("name", sorted(H_LATTICES))
def test_h_lattice_moments(name):
    lat = h_lattice(name)
    w = np.array(lat.w)
    c = lat.c.astype(float)
    assert w.sum() == pytest.approx(1.0, abs=1e-15)
    assert np.allclose(c.T @ w, 0.0, atol=1e-15)
    assert np.allclose((c.T * w) @ c, lat.cs2 * np.eye(3), atol=1e-15)
    assert np.array_equal(lat.c[list(lat.opp)], -lat.c)


def test_unknown_h_lattice_is_an_input_error():
    with pytest.raises(InputError, match="h_lattice"):
        h_lattice("D3Q9")


def _column(blocks_z, periodic_z):
    """An 8 x 8 x 8 blocks_z column, periodic in x and y; walls or periodic in z."""
    faces = {} if periodic_z else {"z-": Face("wall"), "z+": Face("wall")}
    return BlockForest.uniform((8, 8, 8 * blocks_z), faces)


@pytest.mark.parametrize("name", ["D3Q7", "D3Q15"])
def test_flat_interface_relaxes_to_tanh_profile(name):
    """A sharp step between walls relaxes to phi = 1/2 + 1/2 tanh(2 z / W); measured max error 0.0094."""
    fo = _column(3, False)
    z = np.arange(24) + 0.5
    z0 = 12.0  # 12 liquid cells: the volume fixes the interface at z0
    pf = PhaseField(fo, mobility=0.05, h_lattice=name, precision="float64")
    u = np.zeros((3, 3, CELLS))
    pf.initialize(fo.from_dense(np.broadcast_to((z < z0).astype(float), (8, 8, 24)).copy()), u)
    for _ in range(600):
        pf.step(u)
    phi = fo.to_dense(pf.phi_host())
    assert np.abs(phi - tanh_profile(z0 - z)).max() < 0.012
    assert np.ptp(phi, axis=(0, 1)).max() < 1e-12  # stays flat


@pytest.mark.parametrize("name", ["D3Q7", "D3Q15"])
def test_slab_advected_at_the_flow_velocity(name):
    """Galilean check: a periodic slab carried by u = (0.1, -0.02, 0.05) moves 12 cells in 240 steps, flat and unchanged."""
    fo = _column(3, True)
    z = np.arange(24) + 0.5
    uvec = np.array([0.1, -0.02, 0.05])
    u = np.zeros((3, 3, CELLS)) + uvec[None, :, None]
    pf = PhaseField(fo, mobility=0.05, h_lattice=name, precision="float64")
    pf.initialize(fo.from_dense(np.broadcast_to(slab(z, 6, 18, 24), (8, 8, 24)).copy()), u)
    for _ in range(240):
        pf.step(u)
    phi = fo.to_dense(pf.phi_host())
    centre = np.angle(np.sum(phi[0, 0] * np.exp(2j * np.pi * z / 24))) * 24 / (2 * np.pi)
    assert (centre - 12.0) % 24 == pytest.approx(12.0, abs=0.01)
    assert np.abs(phi[0, 0] - slab(z, 18, 30, 24)).max() < 0.015
    assert np.ptp(phi, axis=(0, 1)).max() < 1e-12


def _advected_wavy_surface_float32(steps):
    """A wavy surface between walls carried by u = (0.05, 0, 0) for ``steps`` steps; returns (field, initial volume)."""
    fo = _column(2, False)
    z = np.arange(16) + 0.5
    x = np.arange(8) + 0.5
    surf = 8.0 + 2.0 * np.sin(2 * np.pi * x / 8)[:, None, None]
    phi0 = tanh_profile(surf - z[None, None, :]) * np.ones((8, 8, 16))
    u = np.zeros((2, 3, CELLS), np.float32)
    u[:, 0] = 0.05
    pf = PhaseField(fo, mobility=0.05, precision="float32")
    pf.initialize(fo.from_dense(phi0), u)
    v0 = pf.volume()
    for _ in range(steps):
        pf.step(u)
    return pf, v0


def test_volume_conserved_float32():
    """sum phi over 1000 steps with walls and a moving interface, float32: relative drift <= 5e-5.

    Exact in exact arithmetic (collision keeps sum h, bounce-back keeps it at walls); the float32
    drift is rounding of h ~ w_k, measured +2.6e-5 per 1000 steps on this case.
    """
    pf, v0 = _advected_wavy_surface_float32(steps=1000)
    assert abs(pf.volume() / v0 - 1.0) < 5e-5


@pytest.mark.slow
def test_volume_conserved_float32_10000_steps():
    """The issue's criterion: <= 0.1 % over 10 000 steps in float32 (measured: see docs/VALIDATION.md)."""
    pf, v0 = _advected_wavy_surface_float32(steps=10000)
    assert abs(pf.volume() / v0 - 1.0) < 1e-3


def test_cuda_matches_cpu_on_2x2x2_blocks(rng):
    """The CUDA launcher (simulator where no GPU) gives the CPU's phi and h after one step."""
    fo = BlockForest.uniform((16, 16, 16), {f: Face("wall") for f in ("y-", "y+", "z-", "z+")})
    x = np.arange(16) + 0.5
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    r = np.sqrt((X - 7.0) ** 2 + (Y - 8.5) ** 2 + (Z - 9.0) ** 2)
    phi0 = fo.from_dense(tanh_profile(5.0 - r))
    u = (0.05 * rng.standard_normal((8, 3, CELLS))).astype(np.float64)
    out = []
    for target in (jit.cpu, jit.cuda()):
        pf = PhaseField(fo, mobility=0.05, precision="float64", target=target)
        pf.initialize(phi0, u)
        pf.step(u)
        out.append((pf.phi_host(), pf._host(pf.h)))
    assert np.allclose(out[0][0], out[1][0], rtol=0, atol=1e-13)
    assert np.allclose(out[0][1], out[1][1], rtol=0, atol=1e-13)


@pytest.mark.parametrize("precision, tol", [("float64", 1e-13), ("float32", 2e-6)])
def test_cpu_block_form_matches_the_cell_form(rng, precision, tol):
    """The vectorised CPU block form of passes 1 and 2 gives the per-cell form's phi and h after 3 steps on a
    forest with walls (x, z), periodic y, interior blocks, a drop crossing block faces and a solid body
    (cells keep phi and h, their neighbours bounce back); a one-cell shift of the stencil would fail it, in the
    general pull as in the line-by-line one of the blocks with no solid in reach (walls included)."""
    fo = BlockForest.uniform((40, 24, 40), {f: Face("wall") for f in ("x-", "x+", "z-", "z+")})
    X, Y, Z = (a + 0.5 for a in fo.cell_coordinates())
    r = np.sqrt((X - 15.0) ** 2 + (Y - 8.0) ** 2 + (Z - 23.0) ** 2)
    phi0 = tanh_profile(9.0 - r)
    u = (0.04 * rng.standard_normal((fo.nblocks, 3, CELLS))).astype(precision)
    solid = np.where((np.abs(X - 20) < 3) & (np.abs(Y - 12) < 4) & (np.abs(Z - 9) < 5), 2, -1).astype(np.int32)
    assert 0 < (solid >= 0).sum() < 512
    out = []
    for vector in (True, False):
        pf = PhaseField(fo, mobility=0.05, precision=precision, vector=vector)
        pf.initialize(phi0, u)
        pf.solid = solid.copy()
        pf.phi[solid >= 0] = 0.25  # the coupling's mirror value: kept by pass 1, read by the stencil
        for _ in range(3):
            pf.step(u)
        if vector:   # both forms of pass 1 ran: blocks pulled plainly (no wall, no solid in reach) and the others
            clear = pf._clear[3]
            assert 0 < clear.sum() < fo.nblocks
        out.append((pf.phi_host(), pf._host(pf.h)))
    assert np.all(out[0][0][solid >= 0] == 0.25)
    assert np.abs(out[0][0] - out[1][0]).max() <= tol
    assert np.abs(out[0][1] - out[1][1]).max() <= tol
    assert np.abs(out[0][0] - phi0).max() > 1e-3  # the drop moved
