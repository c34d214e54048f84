"""Fixed sphere in uniform flow: drag against Schiller-Naumann, C_d = 24/Re (1 + 0.15 Re^0.687) (slow).

Set-up: velocity inlet at x-, pressure outlet at x+, periodic sides, box 12 x 8 x 8 diameters (each side rounded
up to whole 8-cell blocks), the sphere centre 4 d behind the inlet and 8 d ahead of the outlet; cumulant,
float32, U = 0.1 (lattice), tau = 3 U d / Re + 1/2; started impulsively (uniform U everywhere), run for 16 d/U,
C_d the mean over the last quarter (12-16 d/U; from 8 d/U on the means over 2 d/U windows agree to 0.4 %,
0.7 % at Re = 100).

Measured at d = 16 cells (192 x 128 x 128 = 3.1 M cells, 2560 steps; 2-core x86 VM shared with other work,
one numba thread, 20-29 min per Re at 4.6-6.8 MLUPS, ~9 min at the ~15 MLUPS of a free core; docs/VALIDATION.md, "Fixed sphere in uniform flow"):

    Re = 10:  C_d = 4.454 against 4.151, +7.3 %   (d = 8: +9.0 %,  d = 12: +7.5 %)
    Re = 50:  C_d = 1.642 against 1.538, +6.8 %   (d = 8: +13.7 %, d = 12: +8.3 %)
    Re = 100: C_d = 1.145 against 1.092, +4.9 %   (d = 8: +16.8 %, d = 12: +7.5 %)

So the 5 % bound holds at Re = 100 only (by 0.1 %). At Re = 10 the grid is converged to ~0.5 % (12 -> 16 changes
C_d by 0.2 %); at Re = 50 the extrapolated limit of the three grids is still +5.5 %. Measured at d = 8, the box
raises C_d by 2.9 % at Re = 10 and 2.0-2.1 % at Re 50 and 100 (inlet 4 d upstream and lateral period 8 d about 1 %
each; compared with a 20 x 16 x 16 d box, inlet 8 d upstream); Schiller-Naumann lies 2.6 % / 2.3 % below the
standard drag curve of Clift, Grace and Weber (1978) at Re = 10 / 50. Re 10 and 50 are marked xfail (strict, so a
fix shows up); the assertion stays 5 %.

Reproduce one case: ``NUMBA_NUM_THREADS=1 python -c "from tests.test_sphere_drag import sphere_drag_coefficient
as f; print(f(10.0, 16))"`` from the repository root.
"""

import math

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.coupling import FluidStructureCoupling, Sphere
from iceresist.dem import DEMSystem, sphere
from iceresist.grid.forest import BlockForest, Face
from iceresist.lbm.solver import LBMSolver
from iceresist.units import Units


def schiller_naumann(re):
    return 24.0 / re * (1.0 + 0.15 * re ** 0.687)


def sphere_drag_coefficient(re, d_cells, U=0.1, lengths=(12, 8, 8), x_sphere=4.0, run_diameters=16.0,
                            mean_fraction=0.25, target=jit.cpu, operator="cumulant", precision="float32",
                            series=False):
    """C_d of a fixed sphere, the mean over the last ``mean_fraction`` of a run of ``run_diameters`` d/U steps.

    ``lengths``: box in diameters (x, y, z), rounded up to whole 8-cell blocks; ``x_sphere``: centre behind the
    inlet, in diameters. ``series=True`` also returns the x-force of every step (lattice units)."""
    shape = tuple(int(np.ceil(n * d_cells / 8) * 8) for n in lengths)
    faces = {"x-": Face("velocity_inlet", (U, 0, 0)), "x+": Face("pressure_outlet")}
    fo = BlockForest.uniform(shape, faces=faces)
    nu = U * d_cells / re
    solver = LBMSolver(fo, tau=3 * nu + 0.5, operator=operator, precision=precision, target=target)
    solver.initialize(u=(U, 0, 0))
    dem = DEMSystem(gravity_m_s2=(0, 0, 0))
    R = d_cells / 2
    dem.add_body(sphere(R, 1000.0), position_m=(x_sphere * d_cells, shape[1] / 2, shape[2] / 2), kinematic=True)
    cp = FluidStructureCoupling(solver, dem, [Sphere(R)], Units.lattice(tau=solver.tau))
    steps = int(round(run_diameters * d_cells / U))
    fx = np.empty(steps)
    for i in range(steps):
        cp.step(1)
        fx[i] = cp.force_lattice[0, 0]
    cd = float(fx[int((1 - mean_fraction) * steps):].mean()) / (0.5 * U ** 2 * math.pi * R ** 2)
    return (cd, fx) if series else cd


# measured C_d at d = 16 in the box above (module docstring); xfail where it misses 5 %
_MISSES = {10.0: "measured C_d 4.454, +7.3 % (box ~2.9 %, Schiller-Naumann 2.6 % below Clift et al.)",
           50.0: "measured C_d 1.642, +6.8 % (box ~2.1 %, grid ~1.2 %, Schiller-Naumann 2.3 % below Clift et al.)"}


@pytest.mark.slow
@pytest.mark.parametrize("re", [
    pytest.param(re, marks=pytest.mark.xfail(strict=True, reason=_MISSES[re])) if re in _MISSES else re
    for re in (10.0, 50.0, 100.0)])
def test_sphere_drag_matches_schiller_naumann(re):
    cd = sphere_drag_coefficient(re, d_cells=16)
    assert cd == pytest.approx(schiller_naumann(re), rel=0.05)
