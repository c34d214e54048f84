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


def refined_sphere_drag(run_diameters: float, operator="cumulant", precision="float32"):
    """C_d of the sphere in the refined patch (the mean over the last quarter of ``run_diameters`` d / U) and the
    cell updates per level-0 step of the refined and the uniform fine grid."""
    shape0 = tuple(int(n * D0) for n in LENGTHS)
    faces = {"x-": Face("velocity_inlet", (U, 0, 0)), "x+": Face("pressure_outlet")}
    c0 = np.array([X_SPHERE * D0, shape0[1] / 2, shape0[2] / 2])
    lo_box, hi_box = c0 - 1.5 * D0, c0 + np.array([2.5, 1.5, 1.5]) * D0
    tree = BlockOctree(tuple(n // 8 for n in shape0), 1, periodic=(False, True, True)).refine(
        lambda lo, hi: np.where(((lo < hi_box[None]) & (hi > lo_box[None])).all(axis=1), 1, 0))
    d_fine = 2 * D0
    tau_fine = 3 * U * d_fine / RE + 0.5
    m = RefinedLBM(tree, tau0=0.5 + (tau_fine - 0.5) / 2, faces=faces, operator=operator, precision=precision)
    m.initialize(u=(U, 0, 0))
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    r_fine = d_fine / 2
    dem.add_body(sphere(r_fine, 1000.0), position_m=tuple(2 * c0), kinematic=True)
    cp = FluidStructureCoupling(m.solvers[1], dem, [Sphere(r_fine)], Units.lattice(tau=m.tau[1]))
    fx = []

    def fine_step():
        cp.step(1)
        fx.append(cp.force_lattice[0, 0])

    m.set_stepper(1, fine_step)
    m.step(int(round(run_diameters * d_fine / U)) // 2)
    fx = np.array(fx)
    cd = float(fx[int(0.75 * len(fx)):].mean()) / (0.5 * U ** 2 * math.pi * r_fine ** 2)
    refined = m.views[0].nleaves * 512 + 2 * m.views[1].nleaves * 512
    uniform = 2 * int(np.prod([2 * n for n in shape0]))
    return cd, refined, uniform


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
