"""Tier 2 on refined levels: the ship in a brash-ice channel with ``[refinement]`` (paper sections 2.5 and 3, its
figure 5: fine blocks about the hull, the ice and the water surface, coarse ones in the deep water).

:class:`RefinedTier2Model` is :class:`~iceresist.models.floating_bodies.FloatingBodiesModel` (the
surface, the gas above it and every body on the finest level, the coarser levels all water) with the ship and ice of
:class:`~iceresist.models.tier2.Tier2Model`: the hull kinematic at the ship's speed, the ice pieces free, the
coupling (eqs. 16-21) and the DEM at the finest level's time step, the tank walls as DEM planes. The band of
``refinement.body_band_m`` is drawn about the hull's box (it translates, never turns) and about each ice piece's
bounding sphere; with ``refinement.regrid_every_steps`` it follows them as they move (an ice piece pushed under the
hull takes its fine blocks with it). The surface must stay on the finest level: ``refinement.surface_band_m`` (or
boxes) from below the ice to the top of the tank.

Units as :class:`Tier2Model` on level 0 (``domain.dx_m``; dt by the Mach rule, gravity and tau from it); level l
has cells and steps 2^l times smaller (acoustic scaling, the same viscosity). One model step is one record interval
(``contact.sample_interval_s`` rounded to whole level-0 steps); the recorded ice force is the mean over the
interval's DEM sub-steps of the contact force of the ice on the hull, the fluid force the mean over its finest-level
steps, as on the uniform grid.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from iceresist.dem.bodies import matrix_from_quaternion
from iceresist.errors import InputError
from iceresist.grid.levels import level_views
from iceresist.models.base import array_bytes
from iceresist.models.fluid import forest_faces
from iceresist.models.regions import build_octree
from iceresist.models.floating_bodies import FloatingBodiesModel
from iceresist.models.ship import ShipModel
from iceresist.models.tier2 import Tier2Ship

log = logging.getLogger(__name__)


class RefinedTier2Model(FloatingBodiesModel, Tier2Ship):
    """Coupled LBM-DEM ship + ice + water on refined levels (module docstring); ``backend``, ``precision`` override
    the scene's ``[numerics]``; ``comm``: an MPI communicator of several ranks (CPU or CUDA; the levels split as
    :class:`~iceresist.models.fluid.FluidModel` splits them, the DEM replicated on every rank)."""

    components = ("lbm", "free-surface", "dem", "coupling", "ship", "ice", "refinement")
    tier = 2

    #: The ship's DEM (its contact law), not the bodies scene's.
    _make_dem = ShipModel._make_dem

    def __init__(self, scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        self.backend, self.precision = backend, precision
        gvec = self._set_up_tier2(scene)
        self.decomp = None
        self.dem = None
        self._gravity = gvec
        self._place_bodies()
        self._records = 0
        self._probes = 0
        self._subs = 0
        self._force_mean = np.zeros(3)
        self._force_last = np.zeros(3)
        self._fluid_mean = np.zeros(3)
        super().__init__(scene, backend=self.backend, precision=self.precision, comm=comm)
        u = self.units
        self.lbm_dt_s = u.dt_s
        self.lbm_steps_per_record = max(1, int(math.ceil(self.contact.sample_interval_s / u.dt_s - 1e-9)))
        self.dt_s = self.lbm_steps_per_record * u.dt_s
        self.g_lattice = self.gravity0
        self.water_volume0_m3 = self.volume0_cells * u.dx_m ** 3
        log.info("tier 2 on %d levels: %s leaf cells per level, dx %.4g m at level 0 (%.3g cells per cube at level "
                 "%d), dt %.4g s (%d per record), tau %.6g; %s, %d hull spheres", self.finest + 1,
                 [self.cells_per_level[lv] for lv in self.lbm.levels], u.dx_m, self.cells_per_cube, self.finest,
                 u.dt_s, self.lbm_steps_per_record, u.tau, self.ice_summary(), self.hull.n_spheres)

    def _place_bodies(self):
        """The coupled bodies (:meth:`Tier2Ship.coupled_bodies`), where each starts, and the box the finest level
        holds about each centre of mass (``_reach_m``, (n, 2, 3): lo, hi offsets, m): the hull's own (it translates),
        each ice piece's bounding sphere (it turns)."""
        bodies = self.coupled_bodies()
        self.hull_body = 0
        self.names = ["hull"] + [f"ice{i}" for i in range(len(bodies) - 1)]
        self._reach_m = np.zeros((len(bodies), 2, 3))
        hull = np.asarray(self.geometry.vertices(), dtype=float) - np.asarray(self.hull.model_com_m, dtype=float)
        self._reach_m[0] = (hull.min(axis=0), hull.max(axis=0))
        for i, (geometry, _, _) in enumerate(bodies[1:], start=1):
            r = float(np.linalg.norm(geometry.half_extent_m()))
            self._reach_m[i] = (np.full(3, -r), np.full(3, r))
        self._bodies = bodies
        self._start_positions = self._centres_of_mass(bodies)

    @classmethod
    def plan(cls, scene) -> dict:
        """The levels a scene would start on, without building them (no populations allocated): the ship and ice
        placed as :meth:`__init__` places them, the octree of the scene's criteria about them
        (:func:`~iceresist.models.regions.build_octree`) and the ghost blocks of every level. Returns
        ``cells_per_level`` (leaf cells), ``ghost_cells_per_level``, ``cells_per_cube`` (at the finest level),
        ``updates_per_step`` (cell updates per level-0 step), ``dt_s`` (level 0's step), ``level0_steps`` (the
        case's) and ``level_bytes`` (what :meth:`__init__` checks against the memory: every level's populations, the
        finest level's free surface; the coupling, the DEM and the level-transfer tables come on top)."""
        self = cls.__new__(cls)
        self.backend, self.precision = "cpu", None
        self._set_up_tier2(scene)
        self.scene, self.dem = scene, None
        self._place_bodies()
        octree = build_octree(scene, body_boxes_m=self.body_boxes_m())
        u = scene.units()
        views = level_views(octree, forest_faces(scene, u))
        per = octree.blocks_per_level()
        finest = int(np.flatnonzero(per)[-1])
        cells = {lv: int(n) * 512 for lv, n in enumerate(per) if n}
        return {"cells_per_level": cells,
                "ghost_cells_per_level": {v.level: int(v.nghosts) * 512 for v in views if v is not None},
                "cells_per_cube": self.layout.cube_m / (u.dx_m / 2 ** finest),
                "updates_per_step": int(sum(n * 2 ** lv for lv, n in cells.items())), "dt_s": u.dt_s,
                "level0_steps": int(math.ceil(scene.run.end_time_s / u.dt_s - 1e-9)),
                "level_bytes": self._level_bytes(views)}

    @staticmethod
    def _centres_of_mass(bodies) -> np.ndarray:
        """Where each body's centre of mass starts (n, 3), m: the model frame's origin at ``position_m`` turned by
        ``orientation``, as :meth:`DEMSystem.add_body` places it."""
        out = []
        for _, shape, kw in bodies:
            q = kw.get("orientation")
            turn = np.eye(3) if q is None else matrix_from_quaternion(np.asarray(q, dtype=float))
            out.append(np.asarray(kw["position_m"], dtype=float) + turn @ np.asarray(shape.model_com_m, dtype=float))
        return np.array(out)

    def _check_limits(self, scene, u):
        """None here: a ship scene's limits are tier 2's (the Mach rule of its units, the DEM sub-step), as on the
        uniform grid."""

    # -- the bodies (FinestLevelBodies' hooks) ------------------------------------------------------------
    def _check_bodies(self):
        """Nothing to check beyond :meth:`Tier2Ship._set_up_tier2` (the ship scene's own checks)."""
        self.box_m = self.domain_m
        self.dem_backend = "cuda" if self.target.is_cuda else "cpu"

    def _make_bodies(self, gravity_m_s2):
        """The DEM with the ship's contact law, the tank walls, the hull and the ice pieces, at the finest level's
        scales; refused naming ``refinement`` where a body does not lie on the finest level's leaves."""
        L, u = self.finest, self.units
        self.units_finest = dataclasses.replace(u, dx_m=u.dx_m / 2 ** L, dt_s=u.dt_s / 2 ** L,
                                                tau=float(self.lbm.tau[L]))
        self.dem = self._make_dem(backend=self.dem_backend, precision="float64", gravity_m_s2=self._gravity)
        self._add_tank_walls(self.dem)
        self.geoms = []
        for geometry, shape, kw in self._bodies:
            self.geoms.append(geometry)
            self.dem.add_body(shape, **kw)
        self._check_in_finest(self.body_positions_m(), margin_cells=2.0)

    def body_boxes_m(self, positions_m: np.ndarray | None = None) -> np.ndarray:
        if positions_m is None and self.dem is None:
            positions_m = self._start_positions
        return super().body_boxes_m(positions_m)

    def _couple(self):
        """The finest level's coupled step with the contact loads summed for the record."""
        self.coupling.step(1, accumulate_contacts=True)
        self._subs += self.dem.last_substeps

    # -- protocol ------------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return self._records

    @property
    def lbm_steps(self) -> int:
        """Level-0 steps taken."""
        return self.level0_steps

    @property
    def lattice_steps_per_step(self) -> int:
        return self.lbm_steps_per_record

    @property
    def lattice_updates_per_step(self) -> int:
        """Cell updates in one record: level l's leaf cells 2^l times per level-0 step."""
        return int(sum(n * 2 ** lv for lv, n in self.cells_per_level.items())) * self.lbm_steps_per_record

    @property
    def substeps_per_record(self) -> int:
        return self.lbm_steps_per_record * 2 ** self.finest * max(1, self.dem.substeps_for(self.units_finest.dt_s))

    @property
    def cells_per_cube(self) -> float:
        """The ice's edge over the finest level's cell."""
        return self.layout.cube_m / (self.units.dx_m / 2 ** self.finest)

    def step(self, n: int = 1):
        """``n`` record intervals of ``lbm_steps_per_record`` level-0 steps (regrids included); each leaves the mean
        ice (contact) force and the mean fluid force on the hull over the interval."""
        hb = self.hull_body
        for _ in range(int(n)):
            self.dem.reset_contact_sums()
            self.coupling.reset_fluid_load_sum()
            self._subs = 0
            super().step(self.lbm_steps_per_record)
            self._records += 1
            self._force_mean = self.dem.contact_sum_on(hb)[:3] / max(self._subs, 1)
            steps = self.lbm_steps_per_record * 2 ** self.finest
            self._fluid_mean = self.coupling.take_fluid_load_sum()[hb, :3] / steps
        self._force_last = self.dem.ice_force_on(hb)

    def _surface_height_m(self) -> np.ndarray:
        """The free surface over each level-0 column (m from the bottom), a floe counted as water
        (:meth:`FreeSurfaceModel.surface_cells`); None on an MPI rank other than 0."""
        h = self.surface_cells(covered_as_water=True)
        return None if h is None else h * self.units.dx_m

    def is_finite(self) -> bool:
        volume = self.water_volume_cells()          # on several ranks a collective call, the same on every rank
        return bool(np.isfinite(self._force_mean).all() and np.isfinite(self._fluid_mean).all()
                    and self._bodies_finite() and math.isfinite(volume))

    #: As :attr:`Tier2Model.watchdog_interval` and :attr:`Tier2Model.full_probe_every`.
    watchdog_interval = 1
    full_probe_every = 10

    def watchdog_probe(self, full: bool | None = None) -> dict:
        """As :meth:`Tier2Model.watchdog_probe` on the finest level's free surface (reduced per block on the
        target; cells in finest-level indices), the coarser levels' mass finite on a ``full`` probe, and the bodies
        that left the finest level (count, the first's index)."""
        if full is None:
            full = self._probes % self.full_probe_every == 0
        self._probes += 1
        u_ship = self.speed_m_s * self.units_finest.dt_s / self.units_finest.dx_m
        n = self.cells_per_level[self.finest]
        probe = self.fs.surface.probe(full, 0.5 * n * u_ship ** 2)
        if not probe["finite"][0]:
            return probe
        if full:
            finite = math.isfinite(self.lbm.mass())         # this rank's leaves: every rank must agree
            if not self.grid.all(finite):
                return {"finite": (False, None)}
        ice = self.ice_probe()
        if not ice["finite"][0]:
            return ice
        gone = self.bodies_outside_finest(self.body_positions_m(), margin_cells=1.0)
        return {**probe, **{k: v for k, v in ice.items() if k != "finite"},
                "bodies_outside_finest": (len(gone), gone[0] if gone else None)}

    def diagnostics(self) -> dict:
        """One record, the columns of :meth:`Tier2Model.diagnostics` (forces on the hull, stem, contacts, ice
        kinetic energy, water volume outside the bodies, the tank's water motion) with the volume's drift and, in a
        regridding run, the leaf cells."""
        v = self.water_volume_cells()
        out = {**self.record_columns(float(v * self.units.dx_m ** 3)),
               "water_volume_drift": float((v - self.volume0_cells) / self.volume0_cells)}
        if self.regrid_every:
            out["leaf_cells"] = float(self.cells)
        return out

    def state(self) -> dict:
        """The levels, the free surface, the coupling and the DEM (:meth:`FloatingBodiesModel.state`: a
        bit-for-bit restart), the records and the last forces, and the ice bodies alone under ``positions_m`` etc.
        (for readers of the checkpoint)."""
        levels = super().state()
        if levels is None:          # an MPI rank other than 0
            return None
        return {**levels, "records": np.int64(self._records),
                "force_mean_N": self._force_mean.copy(), "force_last_N": self._force_last.copy(),
                "fluid_force_mean_N": self._fluid_mean.copy(), **self.ice_state()}

    def load_state(self, state: dict):
        if "records" not in state:
            raise InputError("the checkpoint holds no tier-2 ship on refined levels: it belongs to another scene; "
                             "run again without --pickup")
        super().load_state(state)
        self._records = int(state["records"])
        self._force_mean = np.asarray(state["force_mean_N"], dtype=float).copy()
        self._force_last = np.asarray(state["force_last_N"], dtype=float).copy()
        self._fluid_mean = np.asarray(state["fluid_force_mean_N"], dtype=float).copy()

    def allocation(self) -> dict:
        """Bytes per level (populations; the finest with its phase field), the DEM and the coupling."""
        return {**{f"level{lv}": int(n) for lv, n in self.level_bytes.items()}, "dem": array_bytes(self.dem),
                "coupling": array_bytes(self.coupling)}

    def describe(self) -> dict:
        u = self.units
        per = self.octree.blocks_per_level()
        return {**self.describe_ship(), "shape_cells": list(self.shape_cells), "cells": self.cells,
                "levels": len(per) - 1, "leaf_blocks_per_level": [int(n) for n in per],
                "cells_per_level": {str(k): v for k, v in self.cells_per_level.items()},
                "regrid_every_steps": self.regrid_every, "scheme": self.scene.refinement.scheme,
                "substep_s": self.units_finest.dt_s / max(1, self.dem.substeps_for(self.units_finest.dt_s)),
                "substeps_per_record": self.substeps_per_record, "record_interval_s": self.dt_s,
                "lbm_dt_s": self.lbm_dt_s, "lbm_steps_per_record": self.lbm_steps_per_record,
                "resolution_m": self.units_finest.dx_m, "dx_m": u.dx_m, "tau": u.tau, "g_lattice": self.g_lattice,
                "nu_m2_s": u.nu_m2_s, "operator": self.scene.fluid.operator,
                "ship_lattice_speed": self.speed_m_s * u.dt_s / u.dx_m, "tank": self.tank.describe(),
                "start_wave": {**self.start_wave.describe(), "steady_window_s": list(self.window_s),
                               "window_fraction": self.start_wave.window_fraction(*self.window_s)},
                "cells_per_cube": self.cells_per_cube, "bodies_level": self.finest,
                "precision": self.precision, "backend": self.target.name, "allocation_bytes": self.allocation(),
                **self.grid.describe()}
