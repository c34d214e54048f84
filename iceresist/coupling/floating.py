"""Rigid bodies in water with a free surface: the composition of the free-surface LBM, the DEM and the coupling
(paper sections 2.2-2.4).

:class:`FloatingBodies` owns a :class:`~iceresist.freesurface.fluid.FreeSurfaceFluid` (water under gravity in a
tank of walls), a :class:`~iceresist.dem.DEMSystem` (bodies, walls, contacts) and a
:class:`~iceresist.coupling.FluidStructureCoupling` joining them. Dynamic bodies (ice) move under gravity, the
fluid force and the DEM contacts; kinematic bodies (a ship) move at their prescribed velocity and push the
water (one-way, paper section 2.4). Buoyancy is not modelled: it is the hydrostatic pressure of the gravity
body force in the LBM, summed by the momentum exchange over the wetted surface.

Units: the cell size ``dx_m`` and the lattice gravity ``g_lattice`` fix the time step,
dt = sqrt(g_lattice dx / g); the relaxation time ``tau`` fixes the viscosity, nu = (tau - 1/2) dx^2 / (3 dt)
(:attr:`FloatingBodies.viscosity_m2_s`). Positions are metres from the lower corner of the tank.

Use::

    model = FloatingBodies((24, 24, 32), depth_m=0.1, dx_m=0.005, tau=0.55)
    cube = model.add_body(Box((0.041,) * 3), box((0.041,) * 3, 950.0), position_m=(0.06, 0.06, 0.11))
    ship = model.add_body(Box((0.2, 0.05, 0.05)), box((0.2, 0.05, 0.05), 500.0), position_m=...,
                          velocity_m_s=(0.1, 0, 0), kinematic=True)
    model.start()                   # hydrostatic still water, bodies placed
    model.step(100)                 # coupled steps
    model.fluid_force_N             # (n_bodies, 3), eq. (20); model.dem for contacts, positions, velocities
    model.water_volume_m3()         # sum phi dx^3 outside the bodies (conserved)
    phi, rho, u = model.fields()    # dense fields (lattice units), NaN outside the liquid

The scene models build the same composition on their grid, one level or many
(:class:`~iceresist.models.floating_bodies.FloatingBodiesModel`, :class:`~iceresist.models.tier2.Tier2Model`); this
class is the tank of one uniform forest for scripts and tests.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.backends import jit
from iceresist.coupling.coupler import FluidStructureCoupling
from iceresist.dem import DEMSystem
from iceresist.errors import InputError
from iceresist.freesurface.fluid import FreeSurfaceFluid
from iceresist.grid.forest import BlockForest, Face
from iceresist.parallel.decomposition import Decomposition
from iceresist.units import GRAVITY_M_S2, Units

log = logging.getLogger(__name__)


def free_level_cells(heights, owners) -> float:
    """The mean of the surface ``heights`` (nx, ny; cells, NaN in a column without a surface) over the columns no
    body reaches (``owners`` (nx, ny, nz): the body covering each cell, -1 for none, NaN outside the blocks), over
    every column where the bodies reach all of them; NaN where no column has a surface."""
    free = (np.nan_to_num(owners, nan=-1) < 0).all(axis=2)
    sel = heights[free] if free.any() else heights.ravel()
    sel = sel[np.isfinite(sel)]
    return float(sel.mean()) if sel.size else math.nan


class FloatingBodies:
    """Water of depth ``depth_m`` in a closed tank of ``shape_cells`` (multiples of 8) cells of ``dx_m``, with
    rigid bodies.

    ``tau``: relaxation time of the water (lattice units); ``g_lattice``: gravity in lattice units (sets dt);
    ``rho_kg_m3``: water density; ``operator`` ("bgk" or "cumulant"), ``precision``, ``target`` as in
    :class:`~iceresist.lbm.solver.LBMSolver`; ``mobility``, ``width``: the phase field (eqs. 9-10);
    ``dem``: a :class:`~iceresist.dem.DEMSystem` with contact parameters and walls of your own (its gravity
    must be (0, 0, -``g_m_s2``)), default one with the tank floor as a wall; ``contact_film``: the fluid pressure
    on faces in contact (:class:`~iceresist.coupling.FluidStructureCoupling`); ``h_lattice``: the velocity set of
    the phase-field populations; ``g_m_s2``: gravity (m/s^2; with ``g_lattice`` it sets dt, so that a scene in
    lattice units, g = g_lattice and dx = 1, gets dt = 1); ``comm``: the MPI communicator of a run on several
    ranks (:mod:`iceresist.parallel`): the tank's blocks are split along the Morton curve, each rank steps its own
    and exchanges the whole state of its halo blocks twice per step (after the coupling's boundary passes and after
    the free-surface step), every rank runs the same DEM on the fluid loads summed over the ranks, and the dense
    views, the water volume, the probe and :meth:`state` are the whole tank's (the dense ones on rank 0).
    """

    def __init__(self, shape_cells, *, depth_m: float, dx_m: float, tau: float = 0.55, g_lattice: float = 1e-3,
                 rho_kg_m3: float = 1000.0, operator: str = "bgk", precision: str = "float64", target=jit.cpu,
                 mobility: float = 0.05, width: float = 3.0, dem: DEMSystem | None = None,
                 contact_film: bool = True, h_lattice: str = "D3Q15", g_m_s2: float = GRAVITY_M_S2, comm=None):
        shape = tuple(int(v) for v in shape_cells)
        if len(shape) != 3 or any(v <= 0 or v % 8 for v in shape):
            raise InputError(f"shape_cells must be three positive multiples of 8, got {shape_cells!r}")
        if not 0 < g_lattice <= 0.01:
            raise InputError(f"g_lattice must lie in (0, 0.01] (lattice units), got {g_lattice}")
        self.dx_m = float(dx_m)
        self.dt_s = math.sqrt(g_lattice * self.dx_m / float(g_m_s2))
        self.units = Units.from_lattice(self.dx_m, self.dt_s, float(rho_kg_m3), tau)
        self.depth_cells = float(depth_m) / self.dx_m
        self.global_forest = self.forest = BlockForest.uniform(
            shape, {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")})
        self.decomp = None
        if comm is not None and comm.size > 1:
            self.decomp = Decomposition(self.global_forest, comm)
            self.forest = self.decomp.local
        self.fluid = FreeSurfaceFluid(self.forest, tau=tau, gravity_lattice=g_lattice, depth_cells=self.depth_cells,
                                      mobility=mobility, width=width, h_lattice=h_lattice, operator=operator,
                                      precision=precision, target=target, f_pool_margin=None)
        self.fluid.decomp = self.decomp
        if dem is None:     # on the fluid's target, so that the coupling reads and writes the bodies there
            dem = DEMSystem(backend="cuda" if target.is_cuda else "cpu", gravity_m_s2=(0.0, 0.0, -float(g_m_s2)))
            dem.add_wall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        self.dem = dem
        self.contact_film = bool(contact_film)
        self.geometries: list = []
        self.coupling: FluidStructureCoupling | None = None

    # ------------------------------------------------------------------ set-up
    @property
    def viscosity_m2_s(self) -> float:
        """Kinematic viscosity of the water, nu = (tau - 1/2) dx^2 / (3 dt)."""
        return (self.fluid.fluid.tau - 0.5) * self.dx_m ** 2 / (3.0 * self.dt_s)

    def add_body(self, geometry, shape, position_m, velocity_m_s=(0.0, 0.0, 0.0), orientation=None,
                 kinematic: bool = False, angular_velocity_rad_s=(0.0, 0.0, 0.0), material: str = "ice") -> int:
        """Add a rigid body: ``geometry`` (:mod:`iceresist.coupling.geometry`, body frame) for the fluid, ``shape``
        (:mod:`iceresist.dem`) for mass, inertia and contacts; returns its index."""
        if self.coupling is not None:
            raise InputError("bodies must be added before FloatingBodies.start()")
        self.geometries.append(geometry)
        return self.dem.add_body(shape, position_m=position_m, velocity_m_s=velocity_m_s, orientation=orientation,
                                 kinematic=kinematic, angular_velocity_rad_s=angular_velocity_rad_s,
                                 material=material)

    def start(self):
        """Still water in hydrostatic balance, the bodies placed in it (the water in the cells they cover leaves
        the water volume), boundaries and forces of the first step."""
        if not self.geometries:
            raise InputError("FloatingBodies needs at least one body before start()")
        self.fluid.initialize()
        self.coupling = FluidStructureCoupling(self.fluid, self.dem, self.geometries, self.units,
                                               contact_film=self.contact_film)
        if self.decomp is not None:
            self.coupling.distribute(self.decomp)
            self.coupling.after_boundaries = self._exchange
        self.coupling.update_boundaries()
        self._exchange()
        log.info("floating bodies: %d bodies, %d cells, dx %.4g m, dt %.4g s, nu %.3g m^2/s", len(self.geometries),
                 self.forest.cells, self.dx_m, self.dt_s, self.viscosity_m2_s)

    # ------------------------------------------------------------------ time stepping
    def step(self, n: int = 1, accumulate_contacts: bool = False):
        """``n`` coupled steps of dt (boundaries, free-surface LBM step, DEM over dt with the fluid loads);
        ``accumulate_contacts``: the DEM adds the contact loads to its sums (:meth:`DEMSystem.contact_sum_on`)."""
        if self.coupling is None:
            self.start()
        if self.decomp is None:
            self.coupling.step(n, accumulate_contacts=accumulate_contacts)
            return
        for _ in range(int(n)):
            self.coupling.step(1, accumulate_contacts=accumulate_contacts)
            self._exchange()

    def _exchange(self):
        """On several ranks: every halo block takes its owner's whole state (populations, h, phi, flags). The
        coupling's boundary passes (refill, redistribution, mirror, links) reach up to 5 cells and the free-surface
        step up to 5 cells into an 8-cell halo block from its outer side, together more than a block: so the halo is
        exchanged after each (in the CI scenes one exchange per step gave the same result, tests/test_mpi.py); the
        cell owners follow from the bodies, the same on every rank."""
        if self.decomp is None:
            return
        for arr in self.fluid.halo_state:
            self.decomp.exchange(arr, self.fluid.target, full=True)

    @property
    def time_s(self) -> float:
        return self.dem.time_s

    # ------------------------------------------------------------------ results
    @property
    def fluid_force_N(self) -> np.ndarray:
        """Fluid force on each body (n, 3), newtons, averaged over two steps (eq. 20); the hydrostatic buoyancy
        included (gravity acts in the fluid)."""
        return self.coupling.fluid_force_N

    @property
    def fluid_torque_N_m(self) -> np.ndarray:
        """Fluid torque about each centre of mass (n, 3), N m (eq. 21)."""
        return self.coupling.fluid_torque_N_m

    def water_volume_m3(self) -> float:
        """Water volume outside the bodies, sum phi dx^3 (conserved by the phase field and the coupling)."""
        return self.coupling.water_volume() * self.dx_m ** 3

    def water_level_m(self) -> float:
        """Mean height of the free surface (phi = 1/2) over the columns no body reaches, metres (the same on every
        rank; :func:`free_level_cells`)."""
        h = self.fluid.surface_height()
        level = None if h is None else free_level_cells(h, self.dense_owners()) * self.dx_m
        return level if self.decomp is None else self.decomp.bcast(level)

    def dense_owners(self) -> np.ndarray | None:
        """The body covering each cell (nx, ny, nz), -1 for none, NaN outside the blocks (on several ranks the whole
        tank on rank 0, None on the others)."""
        return self.fluid.dense(self.coupling.owners().astype(np.float64))

    def dense_flags(self) -> np.ndarray | None:
        """The cell flags (nx, ny, nz) as float64, NaN outside the blocks (on several ranks the whole tank on rank 0,
        None on the others)."""
        return self.fluid.dense(np.asarray(self.fluid._host(self.fluid.fluid.flags)).astype(np.float64))

    def fields(self):
        """Dense phi (nx, ny, nz), rho and u (3, nx, ny, nz) of the liquid (lattice units, NaN outside it and in
        the cells a body covers, which the coupling flags GHOST and the free surface keeps so); on several ranks the
        whole tank on rank 0, None on the others."""
        rho, u = self.fluid.macroscopic()
        phi = self.fluid.phi()
        return (None, None, None) if phi is None else (phi, rho, u)

    def state(self) -> dict | None:
        """The fluid's and the coupling's restart state (:meth:`FreeSurfaceFluid.state`,
        :meth:`FluidStructureCoupling.state`); on several ranks the whole tank on rank 0, None on the others."""
        fluid, coupling = self.fluid.state(), self.coupling.state()
        return None if fluid is None else {"fluid": fluid, "coupling": coupling}

    def load_state(self, fluid: dict, coupling: dict):
        """Continue from :meth:`state` (written on any number of ranks)."""
        self.fluid.load_state(fluid)
        self.coupling.load_state(coupling)

    def record(self) -> dict:
        """One row of a time series: time, body positions and velocities, fluid forces, water volume."""
        return {"time_s": self.time_s, "position_m": self.dem.positions.copy(),
                "velocity_m_s": self.dem.velocities.copy(), "fluid_force_N": self.fluid_force_N.copy(),
                "water_volume_m3": self.water_volume_m3()}
