"""The contact film (iceresist.coupling.kernels, "Contact film"): a submerged body touching another body or the
tank floor feels the fluid pressure on the touching face, so its fluid force stays its buoyancy.

Reference: Archimedes, rho g V, for a 41 mm cube held at rest in still water (4 cells per edge, BGK, float64).
Without the film the touching face carries no pressure and the cube is pressed onto what it touches with the
gauge pressure times the face area: measured 3.2 x the buoyancy under a plate 6 cells below the surface and
-3.9 x on the floor of a 0.2 m deep tank (24 x 24 x 48 cells). The CI cases use a smaller tank (16 x 16 x 24).
"""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.coupling import Box
from iceresist.coupling.floating import FloatingBodies
from iceresist.dem import box

EDGE_M = 0.041
DX_M = EDGE_M / 4
ARCHIMEDES_N = 1000.0 * 9.81 * EDGE_M ** 3
DEPTH_M = 0.2


def _held_cube(where, film, target=jit.cpu, steps=150, gap_cells=0.0, nxy=16, tile_cells=None):
    """Fluid force (N) on a cube held at rest, touching the tank floor or the underside of a fixed plate, in a
    tank of nxy x nxy x 24 cells."""
    model = FloatingBodies((nxy, nxy, 24), depth_m=DEPTH_M, dx_m=DX_M, tau=0.6, precision="float64",
                           contact_film=film, target=target)
    xy = nxy / 2 * DX_M
    if where == "floor":
        zc = gap_cells * DX_M + EDGE_M / 2
    else:
        top = DEPTH_M - 6 * DX_M                                # plate underside, 6 cells under the surface
        model.add_body(Box((0.3, 0.3, 4 * DX_M)), box((0.3, 0.3, 4 * DX_M), 950.0),
                       position_m=(xy, xy, top + 2 * DX_M), kinematic=True)
        zc = top - gap_cells * DX_M - EDGE_M / 2
    cube = model.add_body(Box((EDGE_M,) * 3), box((EDGE_M,) * 3, 950.0), position_m=(xy, xy, zc), kinematic=True)
    model.start()
    if tile_cells is not None:
        model.coupling.tile_cells = tile_cells
    model.step(steps)
    return model.fluid_force_N[cube].copy(), model


@pytest.mark.parametrize("where", ["floor", "plate"])
def test_a_cube_touching_a_wall_or_a_body_keeps_its_buoyancy_with_the_film(where):
    """Regression pin, not a reference: the reference is Archimedes (1.0); the band 0.75-1.1 is drawn around the
    code's own output (0.79-1.05 x Archimedes on the 4-cell staircase at gaps of 0.5-4 cells) and holds the
    staircase error, which no analytic figure bounds here. The film's effect is checked against its absence in
    the next test (several times the buoyancy without it)."""
    force, _ = _held_cube(where, film=True)
    touching = force[2] / ARCHIMEDES_N
    # the staircase of 4 cells per edge: 0.79-1.05 x Archimedes at gaps of 0.5-4 cells in the larger tank
    assert 0.75 < touching < 1.1
    assert abs(force[0]) < 0.02 * ARCHIMEDES_N and abs(force[1]) < 0.02 * ARCHIMEDES_N


@pytest.mark.parametrize("where, sign", [("floor", -1), ("plate", 1)])
def test_without_the_film_the_touching_face_presses_the_cube_on(where, sign):
    """The defect the film mends: the missing pressure on the touching face is several times the buoyancy."""
    force, _ = _held_cube(where, film=False)
    excess = force[2] / ARCHIMEDES_N - 1.0
    assert sign * excess > 1.5


def test_the_film_leaves_a_cube_with_water_around_it_alone():
    """One cell of water between the cube and the plate: no link touches, the force is the same with the film."""
    on, _ = _held_cube("plate", film=True, steps=20, gap_cells=1.0)
    off, _ = _held_cube("plate", film=False, steps=20, gap_cells=1.0)
    assert np.array_equal(on, off)


def test_a_body_launched_in_slabs_has_no_film_between_its_own_slabs():
    """The plate launched as z-slabs of 256 cells (rows of its own, iceresist.coupling.coupler.tile_bodies): the
    cells of its other slabs are the plate itself, not a body it touches, so both forces equal the unsplit ones."""
    whole, m_whole = _held_cube("plate", film=True, steps=5)
    split, m_split = _held_cube("plate", film=True, steps=5, tile_cells=256)
    assert m_split.coupling._tile_body is not None and len(m_split.coupling._tile_body) > 3
    assert np.allclose(m_whole.fluid_force_N, m_split.fluid_force_N, rtol=1e-12, atol=1e-12 * ARCHIMEDES_N)


@pytest.mark.slow   # 133 s in the CUDA simulator with 2 test processes on a 2-core x86 VM
def test_cpu_and_cuda_simulator_agree_on_the_film_force():
    cpu, m_cpu = _held_cube("plate", film=True, steps=2, nxy=8)
    gpu, m_gpu = _held_cube("plate", film=True, target=jit.cuda(), steps=2, nxy=8)
    assert cpu[2] > 0
    assert np.allclose(cpu, gpu, rtol=0, atol=1e-11 * np.abs(cpu).max())
    assert np.allclose(m_cpu.fluid_torque_N_m, m_gpu.fluid_torque_N_m, rtol=0,
                       atol=1e-11 * np.abs(cpu).max() * EDGE_M)      # zero by symmetry: round-off
