"""A fixed sphere in a refined patch (block refinement, paper section 2.5): the body and its coupling (interpolated
bounce-back and momentum exchange, paper eqs. 16-19) live on the fine level, stepped at the fine level's own time
step through :meth:`~iceresist.lbm.refinement.RefinedLBM.set_stepper`; the box around it is the coarse level.
Reference: the same sphere on the uniform fine grid (:func:`tests.test_sphere_drag.sphere_drag_coefficient`).

Set-up as tests/test_sphere_drag.py at Re = 10 (velocity inlet, pressure outlet, periodic sides, 12 x 8 x 8 d box,
the sphere 4 d behind the inlet), cumulant, float32, 8 cells per diameter on the fine level (4 on the coarse one);
the patch reaches 1.5 d up- and sideways and 2.5 d downstream of the sphere's centre."""

import math

import numpy as np
import pytest

from iceresist.coupling import FluidStructureCoupling, Sphere
from iceresist.dem import DEMSystem, sphere
from iceresist.grid.forest import Face
from iceresist.grid.octree import BlockOctree
from iceresist.lbm.refinement import RefinedLBM
from iceresist.units import Units
from tests.test_sphere_drag import sphere_drag_coefficient

RE, U, D0 = 10.0, 0.1, 4
LENGTHS, X_SPHERE = (12, 8, 8), 4.0
#: The refined patch of the CI case: (level, reach upstream and sideways, reach downstream), in diameters.
PATCH = ((1, 1.5, 2.5),)
#: The patches of the 20 x 16 x 16 d box (Schiller-Naumann): level 2 (16 cells per diameter) near the sphere,
#: level 1 around it, level 0 (4 cells per diameter) beyond.
BIG_PATCHES = ((2, 1.5, 2.5), (1, 3.0, 6.0))


def refined_sphere_drag(run_diameters: float, re=RE, lengths=LENGTHS, x_sphere=X_SPHERE, patches=PATCH,
                        operator="cumulant", precision="float32"):
    """C_d of the sphere in the refined patches (the mean over the last quarter of ``run_diameters`` d / U; the
    sphere and its coupling on the finest level) and the cell updates per level-0 step of the refined grid and
    of the uniform grid at the finest spacing."""
    shape0 = tuple(int(n * D0) for n in lengths)
    faces = {"x-": Face("velocity_inlet", (U, 0, 0)), "x+": Face("pressure_outlet")}
    c0 = np.array([x_sphere * D0, shape0[1] / 2, shape0[2] / 2])
    finest = max(lv for lv, _, _ in patches)

    def wanted(lo, hi):
        level = np.zeros(len(lo), dtype=np.int64)
        for lv, up, down in patches:
            a, b = c0 - up * D0, c0 + np.array([down, up, up]) * D0
            level = np.maximum(level, np.where(((lo < b[None]) & (hi > a[None])).all(axis=1), lv, 0))
        return level

    tree = BlockOctree(tuple(n // 8 for n in shape0), finest, periodic=(False, True, True)).refine(wanted)
    d_fine = D0 * 2 ** finest
    tau_fine = 3 * U * d_fine / re + 0.5
    m = RefinedLBM(tree, tau0=0.5 + (tau_fine - 0.5) / 2 ** finest, faces=faces, operator=operator,
                   precision=precision)
    m.initialize(u=(U, 0, 0))
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    r_fine = d_fine / 2
    dem.add_body(sphere(r_fine, 1000.0), position_m=tuple(2 ** finest * c0), kinematic=True)
    cp = FluidStructureCoupling(m.solvers[finest], dem, [Sphere(r_fine)], Units.lattice(tau=m.tau[finest]))
    fx = []

    def fine_step():
        cp.step(1)
        fx.append(cp.force_lattice[0, 0])

    m.set_stepper(finest, fine_step)
    m.step(int(round(run_diameters * d_fine / U)) // 2 ** finest)
    fx = np.array(fx)
    cd = float(fx[int(0.75 * len(fx)):].mean()) / (0.5 * U ** 2 * math.pi * r_fine ** 2)
    refined = sum(m.views[lv].nleaves * 512 * 2 ** lv for lv in m.levels)
    uniform = 2 ** finest * int(np.prod([n * 2 ** finest for n in shape0]))
    return cd, refined, uniform


# 46 s warm, 177 s cold (2-core x86 VM): CI time; test_refined_bodies_model.py keeps a refined sphere in CI
@pytest.mark.slow
def test_a_sphere_in_a_refined_patch_has_the_drag_of_the_uniform_fine_grid():
    """C_d within 1 % of the uniform fine grid (the issue's bound) at 18 % of its cell updates: measured 4.5236
    against 4.5217 (+0.04 %) over 16 d / U, about 25 s for both runs (2-core x86 VM, 2026-11-26). Planted: the
    fine level advanced once per coarse step instead of twice fails (-31 % over 4 d / U); the linear
    reconstruction's offsets with their sign flipped move C_d by 0.1 point only, which passes."""
    cd, refined, uniform = refined_sphere_drag(16.0)
    cd_fine = sphere_drag_coefficient(RE, d_cells=2 * D0, lengths=LENGTHS, x_sphere=X_SPHERE, run_diameters=16.0)
    assert refined <= uniform / 3
    assert refined / uniform == pytest.approx(0.180, abs=0.001)
    assert cd == pytest.approx(cd_fine, rel=0.01)
    assert cd == pytest.approx(4.5236, rel=1e-3)      # regression pin of the measured value


@pytest.mark.slow   # about 2.5 min per Reynolds number on a 2-core x86 VM
@pytest.mark.parametrize("re, measured", [(10.0, 4.3245), (50.0, 1.6102)])
def test_a_sphere_in_the_big_box_has_the_drag_of_schiller_naumann(re, measured):
    """Schiller-Naumann within 5 % in the 20 x 16 x 16 d box with the inlet 8 d upstream (issue: the box that
    16 cells per diameter on a uniform grid, 21 M cells, cannot run here): three levels, 16 cells per diameter near
    the sphere, 8 around it, 4 beyond, 2.6 % of the uniform grid's cell updates. Measured +4.18 % at Re 10 (4.3245
    against 4.1511) and +4.69 % at Re 50 (1.6102 against 1.5381), 137 s each (2-core x86 VM, 2026-11-26); the
    12 x 8 x 8 d box on the uniform grid gives +7.3 % and +6.8 % (tests/test_sphere_drag.py). Schiller-Naumann
    lies 2.6 % / 2.3 % below Clift et al.'s correlation at these Reynolds numbers."""
    from tests.test_sphere_drag import schiller_naumann

    cd, refined, uniform = refined_sphere_drag(16.0, re=re, lengths=(20, 16, 16), x_sphere=8.0,
                                               patches=BIG_PATCHES)
    assert refined / uniform < 0.03
    assert cd == pytest.approx(schiller_naumann(re), rel=0.05)
    assert cd == pytest.approx(measured, rel=2e-3)     # regression pin of the measured value
