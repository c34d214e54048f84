"""A sphere settling in a closed box: terminal velocity against ten Cate et al. (2002), Phys. Fluids 14, 4012.

Experiment: nylon sphere d = 15 mm, rho_s = 1120 kg/m^3, in silicone oil in a 100 x 100 x 160 mm box,
released 120 mm above the bottom. Cases (rho_f kg/m^3, mu Pa s, u_terminal m/s, Re): E1 970, 0.373, 0.038,
1.5; E2 965, 0.212, 0.060, 4.1; E3 962, 0.113, 0.091, 11.6; E4 960, 0.058, 0.128, 31.9. The Re range and
the set-up are those of the paper's abstract; the four (rho, mu, u) triples reproduce its Re = rho u d / mu
within 2 %. The box is rounded up to whole blocks. Run on a GPU (about 2e9 cell updates per case at d = 16).
"""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.coupling import FluidStructureCoupling, LatticeUnits, Sphere
from iceresist.dem import DEMSystem, sphere
from iceresist.grid.forest import BlockForest, Face
from iceresist.lbm.solver import LBMSolver

CASES = {"E1": (970.0, 0.373, 0.038), "E2": (965.0, 0.212, 0.060), "E3": (962.0, 0.113, 0.091),
         "E4": (960.0, 0.058, 0.128)}


def settle(case, d_cells=16, u_lattice=0.04, t_end_s=1.2, target=jit.cpu):
    rho_f, mu, u_ref = CASES[case]
    d = 0.015
    dx = d / d_cells
    dt = u_lattice * dx / u_ref
    shape = tuple(int(np.ceil(L / dx / 8) * 8) for L in (0.1, 0.1, 0.16))
    fo = BlockForest.uniform(shape, faces={k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")})
    tau = 3 * (mu / rho_f) * dt / dx ** 2 + 0.5
    solver = LBMSolver(fo, tau=tau, operator="cumulant", precision="float32", target=target)
    solver.initialize()
    dem = DEMSystem()
    dem.add_body(sphere(d / 2, 1120.0), position_m=(0.05, 0.05, 0.12 + 0.5 * d))
    dem.add_wall((0, 0, 0), (0, 0, 1))
    cp = FluidStructureCoupling(solver, dem, [Sphere(d / 2)], LatticeUnits(dx, dt, rho_f))
    t, w = [], []
    for _ in range(int(t_end_s / dt)):
        cp.step(1)
        t.append(dem.time_s)
        w.append(-dem.velocities[0, 2])
    return np.array(t), np.array(w), u_ref


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_settling_sphere_reaches_the_terminal_velocity_of_ten_cate(case):
    t, w, u_ref = settle(case)
    assert w.max() == pytest.approx(u_ref, rel=0.05)
