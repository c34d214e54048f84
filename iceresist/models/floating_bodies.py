"""Rigid bodies in water with a free surface: a scene with ``[[bodies]]`` and ``[free_surface]`` (paper sections
2.2-2.5; the floating cube, :mod:`iceresist.validate.cases.floating_cube`), on one level or on the levels of its
``[refinement]`` (the cube and tier 2's ice and hull on the levels of the paper's figure 1).

:class:`FloatingBodiesModel` is :class:`~iceresist.models.surface.FreeSurfaceModel` (the surface in the finest level,
the coarser levels all water) with the bodies of :class:`~iceresist.models.bodies.BodiesModel` on the finest level
(level 0 of a grid without ``[refinement]``): the coupling (interpolated bounce-back, momentum exchange, refill with h
and phi, the contact film, eqs. 16-21) runs on that level's free-surface fluid at that level's own time step, after
the level's ghost blocks are refilled with bulk water as without bodies (:meth:`RefinedFreeSurface.refill_ghosts`).
The buoyancy is the hydrostatic pressure of gravity in the water, summed by the momentum exchange; the DEM carries
gravity. The water volume is the finest level's phase volume outside the bodies plus the coarser levels' water, in
level-0 cells.

One level is a closed tank of walls with water over the whole floor, starting still. On levels every body, with two
cells to spare, must lie on the finest level's leaves (``refinement.body_band_m`` refines around it); with
``refinement.regrid_every_steps`` the band follows the bodies (block AMR part 2): at a regrid the populations of
every level, the finest level's h, phi and flags (:meth:`RefinedFreeSurface.carry_from`) and the coupling's cell
owners are carried to the new blocks, the DEM goes on. On several MPI ranks (``comm``) each takes its share of the
levels as for the water alone, the finest level's halo leaves swap their whole state after the coupling's boundary
passes and after each step (:meth:`_swap_finest`), and every rank runs the same DEM on the forces summed over the
ranks.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.coupling import FluidStructureCoupling
from iceresist.coupling.floating import free_level_cells
from iceresist.errors import InputError
from iceresist.models.bodies import FinestLevelBodies
from iceresist.models.surface import FreeSurfaceModel
from iceresist.scene.checks import check_tank


class FloatingBodiesModel(FinestLevelBodies, FreeSurfaceModel):
    """Bodies, fixed, prescribed or free, in water with a free surface on any grid (module docstring).
    ``backend`` and ``precision`` override the scene's ``[numerics]``; ``comm``: several MPI ranks.

    Time series (:meth:`diagnostics`): the per-body columns of :class:`~iceresist.models.bodies.BodyShapes` and the
    water's (:meth:`FreeSurfaceModel.diagnostics`) with its volume outside the bodies, the volume's drift and the
    water level (:meth:`water_level_m`)."""

    components = ("fluid", "free_surface", "dem", "coupling")
    #: Every block holds its populations: the coupling's refill reads them wherever a body goes.
    pool_populations = False

    def _check_limits(self, scene, u):
        """One level: the closed tank (:func:`check_tank`); levels: the fluid's stability limits."""
        if self.uniform:
            check_tank(scene, u)
        super()._check_limits(scene, u)

    def _build(self, initialize: bool = True):
        """The levels with the surface (:meth:`FreeSurfaceModel._build`) and the coupling on the finest
        level's free-surface fluid. The first call also builds the DEM and places the bodies in the still water; a
        later one (a regrid, a pickup onto another octree) keeps the DEM and carries the coupling's state
        (:meth:`FinestLevelBodies._carry_finest`)."""
        first = getattr(self, "dem", None) is None
        old = None if first else self._carried_or_finest_state()
        super()._build(initialize)
        if first:
            self._check_bodies()
            self._make_bodies(self.scene.fluid.gravity_m_s2)   # gravity on the bodies; buoyancy is the pressure
        con = self.scene.contact
        self.coupling = FluidStructureCoupling(self.fs.surface, self.dem, self.geoms, self.units_finest,
                                               contact_film=True if con is None else con.fluid_film)
        if self.decomp is not None:     # the links of this rank's own leaves; the halo swapped after the boundaries
            self.coupling.distribute(self.fs.surface.decomp)
            self.coupling.after_boundaries = self._swap_finest
        self.lbm.set_stepper(self.finest, self._finest_step)
        if old is not None:
            self._carry_finest(old)
            return
        self.coupling.update_boundaries()       # the bodies placed in the still water (their cells leave it)
        self._swap_finest()
        self._buoyancy_N = np.zeros((len(self.scene.bodies), 3))
        self.volume0_cells = self.water_volume_cells()

    def _finest_step(self):
        """One step of the finest level: the ghost blocks refilled from the coarser level, then the coupled step
        (boundaries, free-surface step, DEM: :meth:`FinestLevelBodies._couple`); on several ranks the halo leaves swapped after it."""
        self.fs.refill_ghosts()
        self._couple()
        self._swap_finest()

    def _swap_finest(self):
        """On several ranks: the finest level's halo leaves take their owners' whole state (populations, h, phi,
        flags): the coupling's boundary passes and the free-surface step each reach up to 5 cells into the one block
        of halo, together more than a block, so the swap follows each (the coupling's ``after_boundaries`` and
        :meth:`_finest_step`). The cell owners follow from the bodies, replicated on every rank."""
        d = self.decomp
        if d is None:
            return
        for arr in self.fs.surface.halo_state:
            d.exchange(self.finest, arr, self.target)

    # -- values per leaf ---------------------------------------------------------------------------------
    def water_volume_cells(self) -> float:
        """The water volume in level-0 cells: the finest level's phase volume over its leaves outside the bodies
        (:meth:`PhaseField.volume_per_block`) over 8^L, plus every coarser level's leaf cells over 8^l
        (:meth:`RefinedFreeSurface.volume`: the same float64 on any number of ranks)."""
        return self.fs.volume(self.fs.surface.phase.volume_per_block())

    def water_level_m(self) -> float | None:
        """The mean height of phi = 1/2 over the finest level's columns no body reaches (all of them where the
        bodies reach every one; :func:`free_level_cells`), m above z = 0; on several ranks on rank 0 (None on the
        others)."""
        sf = self.fs.surface
        owners = sf.dense(self.coupling.owners().astype(np.float64))
        h = sf.surface_height()
        return None if h is None else free_level_cells(h, owners) * self.units_finest.dx_m

    def _surface_reach(self, bulk: float, owner=None) -> np.ndarray:
        """The finest leaf blocks with a cell less liquid than ``bulk`` outside the bodies: a body's cells hold the
        phi they had when it covered them, which says nothing of the surface (a sphere sunk from under the surface
        carries phi = 0.98 down with it)."""
        return super()._surface_reach(bulk, self.coupling.owner_array)

    def _covered(self) -> np.ndarray:
        """The finest level's leaf cells a body covers (nleaves, 512; this rank's own leaves on several ranks)."""
        n = self.grid.own_leaves(self.finest)
        return self.coupling.owners()[:n] >= 0

    def _leaf(self, lv: int):
        """As :meth:`FreeSurfaceModel._leaf`, the cells the bodies cover at the reference state too."""
        rho, u, xyz = super()._leaf(lv)
        if lv == self.finest:
            covered = self._covered()
            rho = np.where(covered, 1.0, rho)
            u = np.where(covered[None], 0.0, u)
        return rho, u, xyz

    def _leaf_extra(self, lv: int) -> list:
        """phi of the leaves, 0 in the cells a body covers (no water there)."""
        phi = super()._leaf_extra(lv)[0]
        if lv == self.finest:
            phi = np.where(self._covered(), 0.0, phi)
        return [phi]

    # -- protocol ------------------------------------------------------------------------------------------
    def diagnostics(self) -> dict[str, float]:
        """The per-body columns (:meth:`BodyShapes.body_columns`) and the water's (:meth:`FreeSurfaceModel.
        diagnostics`) with the volume outside the bodies and the water level."""
        self.coupling.check_link_list()
        out = super().diagnostics()
        v = self.water_volume_cells()
        out.update(water_volume_m3=float(v * self.units.dx_m ** 3),
                   water_volume_drift=float((v - self.volume0_cells) / self.volume0_cells),
                   water_level_m=self.grid.bcast(self.water_level_m()))
        return {**self.body_columns(), **out}

    def is_finite(self) -> bool:
        volume = self.water_volume_cells()          # on several ranks a collective call: every rank takes it
        return self.grid.all(self._bodies_finite() and math.isfinite(volume) and math.isfinite(self.lbm.mass()))

    def state(self) -> dict:
        """The water's state (:meth:`FreeSurfaceModel.state`: the finest level's flags, with the cells the
        bodies cover, among it), the coupling and the DEM: a bit-for-bit restart (on several ranks the whole levels
        on rank 0, None on the others)."""
        water, coupling = super().state(), self.coupling.state()
        if water is None:
            return None
        return {**water, "coupling": coupling, "dem": self.dem.state()}

    def load_state(self, state: dict):
        if "coupling" not in state or "dem" not in state:
            raise InputError("the checkpoint holds no bodies: it belongs to another scene; run again without "
                             "--pickup")
        if self.uniform and "fluid" in state:   # one level's layout before the grid became a parameter
            state = {**state, **state["fluid"]}
        super().load_state(state)
        self.coupling.load_state(state["coupling"])
        self.dem.load_state(state["dem"])
