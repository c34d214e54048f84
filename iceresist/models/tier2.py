"""Tier 2: the ship in a brash-ice channel with the coupled LBM-DEM, the paper's method (sections 2-5), on one level
or on the levels of a ``[refinement]`` (its figure 5: fine blocks about the hull, the ice and the water surface,
coarse ones in the deep water).

:class:`Tier2Model` is :class:`~iceresist.models.floating_bodies.FloatingBodiesModel` (water under gravity in a
closed tank, free-surface LBM with the phase field, eqs. 1-11; the surface, the gas above it and every body on the
finest level, the coarser levels all water) with the ship and ice of :class:`~iceresist.models.ship.ShipModel`: the
hull a kinematic body moving at the prescribed speed along +x (convex-hull signed distance for the fluid, the same
DEM sphere clump as tier 1 for contacts), the ice cubes dynamic bodies (box signed distance + DEM clump) moved by
gravity, the fluid force of the momentum exchange (eqs. 16-21; buoyancy is the hydrostatic pressure of the LBM) and
the DEM contacts, the tank walls DEM planes; the coupling and the DEM at the finest level's time step. On levels the
band of ``refinement.body_band_m`` is drawn about the hull's box (it translates, never turns) and about each ice
piece's bounding sphere; with ``refinement.regrid_every_steps`` it follows them as they move. The surface must stay
on the finest level: ``refinement.surface_band_m`` (or boxes) from below the ice to the top of the tank.

Units (the rule of :meth:`iceresist.scene.schema.Scene.units`), on level 0:

* dx = ``domain.dx_m``;
* dt = mach dx / max(U_ship, sqrt(g h)), ``numerics.mach`` the lattice velocity limit, h the water depth: the
  ship and the shallow-water wave both stay at or below ``mach`` in lattice units. Gravity is then fixed by dt:
  g_lattice = g dt^2 / dx (its hydrostatic density change over the depth, 3 g_lattice h/dx = 3 (sqrt(g h)
  dt/dx)^2 <= 3 mach^2, is the same limit seen from the pressure);
* tau = 1/2 + 3 nu dt / dx^2 from ``fluid.nu_m2_s``. The paper runs the cumulant operator without a turbulence
  model at the water's viscosity (tau - 1/2 ~ 1e-5 here); we do the same when ``fluid.nu_m2_s`` is the water's.
  Coarse presets may raise ``fluid.nu_m2_s`` (an effective viscosity, a stability floor written in the scene,
  see :mod:`iceresist.scene.case_scenes`).

Level l has cells and steps 2^l times smaller (acoustic scaling, the same viscosity). One model step is one record
interval: ``contact.sample_interval_s`` rounded to whole level-0 steps. The recorded ice force is the mean over the
interval's DEM sub-steps of the DEM contact force of the ice on the hull (paper section 4.2; water resistance
excluded); the fluid force on the hull (pressure and friction of the LBM, eq. 20) is recorded beside it as
``Fx_fluid_N`` etc., the mean over the interval's finest-level steps. On a GPU, one level and one process, each
coupled step is replayed as a CUDA graph (:mod:`iceresist.backends.graphs`).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.backends.graphs import StepReplay
from iceresist.backends.jit import resolve_target
from iceresist.coupling.geometry import Box, ConvexPolyhedron, ConvexUnion
from iceresist.dem.system import centre_of_mass_m
from iceresist.errors import InputError
from iceresist.grid.levels import level_views
from iceresist.models.base import array_bytes
from iceresist.models.floating_bodies import FloatingBodiesModel
from iceresist.models.ship import ShipModel
from iceresist.scene.blocks import build_octree, check_block_shape, forest_faces
from iceresist.ship.from_scene import start_wave_of_scene
from iceresist.ship.meshhull import MeshHull
from iceresist.ship.tank import tank_flow
from iceresist.units import GRAVITY_M_S2

log = logging.getLogger(__name__)


class Tier2Model(FloatingBodiesModel, ShipModel):
    """Coupled LBM-DEM ship + ice + water for a scene with ``[ship]`` (tier 2), ``[ice]`` and ``[free_surface]``, on
    any grid (module docstring). ``backend``, ``precision`` override the scene's ``[numerics]``; ``comm``: an MPI
    communicator of several ranks (CPU or CUDA; the levels split as :class:`~iceresist.models.fluid.FluidModel`
    splits them, the DEM replicated on every rank; records, fields and checkpoints the whole tank's)."""

    components = ("lbm", "free-surface", "dem", "coupling", "ship", "ice")
    tier = 2

    #: The ship's DEM (its contact law), not the bodies scene's.
    _make_dem = ShipModel._make_dem

    def _set_up_tier2(self, scene) -> np.ndarray:
        """Checks (physical units, gravity, whole blocks), the ship and ice in the scene's tank
        (:meth:`ShipModel._set_up_ship`), the tank's blockage and the start wave, each with its warning; the target
        of ``self.backend`` (or ``[numerics]``'s) and ``self.precision`` (or its). Returns gravity (m/s^2)."""
        self._check_sections(scene)
        if scene.is_lattice:
            raise InputError(f"{scene.source_name}: a ship scene is written in physical units ([scene] units)")
        gvec = np.asarray(scene.fluid.gravity_m_s2, dtype=float)
        if not np.allclose(gvec, (0.0, 0.0, -GRAVITY_M_S2)):
            raise InputError(f"fluid.gravity_m_s2: tier 2 runs with gravity [0, 0, -{GRAVITY_M_S2}] "
                             f"(got {list(gvec)})")
        self.shape_cells = tuple(int(n) for n in scene.shape_cells())
        check_block_shape(self.shape_cells)
        self._set_up_ship(scene, tuple(n * scene.units().dx_m for n in self.shape_cells))
        sh, g = scene.ship, self.geometry
        self.tank = tank_flow(g.midship_area_m2, self.domain_m[1], self.level_m, float(sh.speed_m_s))
        if not self.tank.subcritical:
            log.warning("tier 2: %.3g m/s is above the limiting speed of this tank (depth Froude number %.3g, "
                        "Schijf's limit %.3g at blockage %.2f): the ship pushes a bore ahead and the flow past "
                        "it never settles; a deeper or wider tank (free_surface.water_depth_m, domain) lowers the "
                        "blockage", sh.speed_m_s, self.tank.depth_froude, self.tank.limit_froude, self.tank.blockage)
        self.start_wave, self.window_s = start_wave_of_scene(scene, g, self.layout)
        warning = self.start_wave.warning(*self.window_s)
        if warning:
            log.warning("tier 2: %s", warning)
        self.backend = self.backend or scene.numerics.backend
        self.precision = self.precision or scene.numerics.precision
        self.target = resolve_target(self.backend)
        return gvec

    def coupled_bodies(self) -> list[tuple]:
        """The bodies the coupling moves, the hull first: (geometry for the fluid, DEM shape, keywords of
        ``add_body``) each. The hull is kinematic at the ship's speed; its geometry is the convex hull of its
        vertices or, for a mesh hull that is not convex, a union of convex slabs. Every ice piece is a box."""
        g = self.geometry
        pieces = g.fluid_pieces() if isinstance(g, MeshHull) else None
        if pieces is not None and len(pieces[0]) > 1:
            log.info("tier 2: the hull %r is not convex: %d convex slabs for the fluid, %.2f %% more volume than "
                     "the mesh", g.name, len(pieces[0]), 100 * pieces[1])
            hull_geometry = ConvexUnion.of_shape(pieces[0], g.mesh.volume_m3, self.hull)
        else:
            hull_geometry = ConvexPolyhedron.of_shape(g.vertices(), self.hull)
        out = [(hull_geometry, self.hull,
                {"position_m": (self.start_x_m, self.centre_y_m, self.level_m - g.draught_m),
                 "velocity_m_s": (self.speed_m_s, 0.0, 0.0), "kinematic": True, "material": "ship"})]
        floes = self.floes_record()
        for shape, c, q, size, thick in zip(self.floe_shapes, self.layout.centres_m, self.floe_orientations,
                                            floes["floe_sizes_m"], floes["floe_thickness_m"]):
            out.append((Box((size, size, thick)), shape, {"position_m": c, "orientation": q, "material": "ice"}))
        return out

    def record_columns(self, water_volume_m3: float) -> dict:
        """A record's columns (both tier-2 models): the mean ice (contact) force on the hull over the record (N),
        the last one's x, the mean fluid force on it (N), stem position (m), contacts, ice kinetic energy (J), the
        water volume (m^3, outside the bodies) and the tank's water motion (:meth:`tank_motion`)."""
        f, w = self._force_mean, self._fluid_mean
        return {"Fx_N": f[0], "Fy_N": f[1], "Fz_N": f[2], "Fx_last_N": self._force_last[0],
                "Fx_fluid_N": w[0], "Fy_fluid_N": w[1], "Fz_fluid_N": w[2], "x_bow_m": self.x_bow_m,
                "contacts": self.dem.contact_count(), "ice_kinetic_energy_J": self.dem.kinetic_energy(),
                "water_volume_m3": water_volume_m3, **self.tank_motion()}

    #: Length (m) of the bands along the tank over which :meth:`tank_motion` reads the water level.
    level_band_m = 0.32


    def tank_motion(self) -> dict:
        """How the tank's water moves (docs/SHIP.md, "The start wave"): the median height of the surface above
        the still level (m) in the side strips of the tank (outside the hull's beam, so the bow's overhang
        is not read as water) over the band of :attr:`level_band_m` at the fore wall (``level_fore_wall_m``)
        and the band from 0.05 m ahead of the stem (``level_ahead_m``), a floe counted as water
        (:meth:`_surface_height_m`); and the mean x-velocity (m/s) of the cubes whose centres lie ahead of the
        stem (``ice_drift_ahead_m_s``; positive: moving away from the bow). NaN where a band lies outside the tank
        or no cube is ahead."""
        h = self._surface_height_m()
        ice = self.ice_state()
        ahead = ice["positions_m"][:, 0] > self.x_bow_m
        drift = float(ice["velocities_m_s"][ahead, 0].mean()) if ahead.any() else math.nan
        levels = self.grid.bcast(None if h is None else self._level_bands(h - self.level_m))
        return {**levels, "ice_drift_ahead_m_s": drift}

    def _level_bands(self, h) -> dict:
        """The bands of :meth:`tank_motion` on the surface heights ``h`` (nx, ny; m above the still level)."""
        dx = self.units.dx_m
        nx, ny = self.shape_cells[:2]
        x = (np.arange(nx) + 0.5) * dx
        y = (np.arange(ny) + 0.5) * dx
        side = np.abs(y - self.centre_y_m) > 0.5 * self.geometry.beam_m

        def band(x0):
            vals = h[np.ix_((x >= x0) & (x < x0 + self.level_band_m), side)]
            vals = vals[np.isfinite(vals)]  # a column with no surface (all water or all gas) is left out
            return float(np.median(vals)) if vals.size else math.nan

        return {"level_fore_wall_m": band(self.domain_m[0] - self.level_band_m),
                "level_ahead_m": band(self.x_bow_m + 0.05)}

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
        #: on a GPU, one level and one process, the coupled step is replayed as a CUDA graph
        self.replay = StepReplay(self.target, enabled=self.uniform and self.decomp is None)
        log.info("tier 2 on %d levels: %s leaf cells per level, dx %.4g m at level 0 (%.3g cells per cube at level "
                 "%d), dt %.4g s (%d per record), tau %.6g; %s, %d hull spheres", self.finest + 1,
                 [self.cells_per_level[lv] for lv in self.lbm.levels], u.dx_m, self.cells_per_cube, self.finest,
                 u.dt_s, self.lbm_steps_per_record, u.tau, self.ice_summary(), self.hull.n_spheres)

    def _place_bodies(self):
        """The coupled bodies (:meth:`coupled_bodies`), where each starts, and the box the finest level
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
        self._start_positions = np.array([centre_of_mass_m(shape, kw["position_m"], kw.get("orientation"))
                                          for _, shape, kw in bodies])

    @classmethod
    def plan(cls, scene) -> dict:
        """The levels a scene would start on, without building them (no populations allocated): the ship and ice
        placed as :meth:`__init__` places them, the octree of the scene's criteria about them
        (:func:`~iceresist.scene.blocks.build_octree`) and the ghost blocks of every level. Returns
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

    def _check_limits(self, scene, u):
        """None here: a ship scene's limits are tier 2's (the Mach rule of its units, the DEM sub-step)."""

    # -- the bodies (FinestLevelBodies' hooks) ------------------------------------------------------------
    def _check_bodies(self):
        """Nothing to check beyond :meth:`_set_up_tier2` (the ship scene's own checks)."""
        self.box_m = self.domain_m
        self.dem_backend = "cuda" if self.target.is_cuda else "cpu"

    def _make_bodies(self, gravity_m_s2):
        """The DEM with the ship's contact law, the tank walls, the hull and the ice pieces, at the finest level's
        scales; refused naming ``refinement`` where a body does not lie on the finest level's leaves."""
        self._set_finest_units()
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
        """The finest level's coupled step (:meth:`coupled_step`, replayed as a CUDA graph where
        :attr:`replay` is on) and its DEM sub-steps counted for the record."""
        self.replay.run(self.coupled_step)
        self._subs += self.dem.last_substeps

    def coupled_step(self):
        """One coupled step of the finest level (boundaries, free-surface LBM step, DEM over the level's dt) with
        the contact loads summed for the record: the step :mod:`iceresist.validate.launch_budget` counts."""
        self.coupling.step(1, accumulate_contacts=True)

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
        """Cell updates in one record: those of a level-0 step (:attr:`FluidModel.lattice_updates_per_step`) times
        its level-0 steps."""
        return super().lattice_updates_per_step * self.lbm_steps_per_record

    @property
    def substeps_per_record(self) -> int:
        return self.lbm_steps_per_record * 2 ** self.finest * max(1, self.dem.substeps_for(self.units_finest.dt_s))

    @property
    def g_lattice(self) -> float:
        """Gravity in level-0 lattice units, g dt^2 / dx."""
        return self.gravity0

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

    #: Records between watchdog checks (:mod:`iceresist.watchdog`): a record is several LBM steps, and a blow-up
    #: grows from one cell to NaN within a few of them.
    watchdog_interval = 1

    #: Every this many probes (the first included) the watchdog reads the populations: density band and kinetic
    #: energy. The probes between read the velocity the step already holds. Both are reduced per block on the
    #: target (:mod:`iceresist.freesurface.probe`): on a 3.2e6-cell quick case on a 2-core CPU the full probe
    #: takes 0.13 s and the cheap one 0.03 s, against about 10 s for a record (docs/notes/coupled-step-speed.md).
    full_probe_every = 10

    def watchdog_probe(self, full: bool | None = None) -> dict:
        """What the run watchdog checks, with the cell where it happens (:mod:`iceresist.watchdog`), on the finest
        level's free surface (cells in finest-level indices; reduced on the target, :meth:`FreeSurfaceFluid.probe`):
        finite phase field, finite velocity on the liquid cells (a cell a body covers is GHOST, not liquid), the
        fastest wet cell (lattice speed); the fastest ice body against 10 x max(ship speed, sqrt(g a)) (as tier 1);
        the bodies that left the finest level (count, the first's index); and on a ``full`` probe (default: every
        :attr:`full_probe_every`-th, the first included) finite populations, the lattice density band and the
        fluid kinetic energy of the wet cells (lattice units; reference: all cells moving at the ship's lattice
        speed), and the coarser levels' populations finite (reduced on the target too)."""
        if full is None:
            full = self._probes % self.full_probe_every == 0
        self._probes += 1
        self.coupling.check_link_list()     # CUDA: the links passes since the last probe found no cell left out
        u_ship = self.speed_m_s * self.units_finest.dt_s / self.units_finest.dx_m
        n = self.cells_per_level[self.finest]
        probe = self.fs.surface.probe(full, 0.5 * n * u_ship ** 2)
        if not probe["finite"][0]:
            return probe
        if full:
            finite = self.fs.coarse_levels_finite()         # this rank's leaves: every rank must agree
            if not self.grid.all(finite):
                return {"finite": (False, None)}
        ice = self.ice_probe()
        if not ice["finite"][0]:
            return ice
        gone = self.bodies_outside_finest(self.body_positions_m(), margin_cells=1.0)
        return {**probe, **{k: v for k, v in ice.items() if k != "finite"},
                "bodies_outside_finest": (len(gone), gone[0] if gone else None)}

    def diagnostics(self) -> dict:
        """One record (:meth:`record_columns`: forces on the hull, stem, contacts, ice kinetic energy, water volume
        outside the bodies, the tank's water motion) with the volume's drift and, in a regridding run, the leaf
        cells."""
        v, v0 = self.water_volume_cells(), self.volume0_cells
        drift = (v - v0) / v0 if v0 > 0 else math.nan     # no water in a traced build (nothing runs)
        out = {**self.record_columns(float(v * self.units.dx_m ** 3)), "water_volume_drift": float(drift)}
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
        """Continue from :meth:`state`, or from a one-level checkpoint of the layout before the grid became a
        parameter (the fluid under ``fluid``, the records under ``iteration``)."""
        if self.uniform and "fluid" in state and "records" not in state:
            state = {**state, "records": state["iteration"], "volume0_cells": np.float64(self.volume0_cells)}
        if "records" not in state or "coupling" not in state or "dem" not in state:
            raise InputError("the checkpoint holds no tier-2 flow state (populations, phase field, bodies): it "
                             "belongs to another scene; run the scene again without --pickup")
        super().load_state(state)
        self._records = int(state["records"])
        self._force_mean = np.asarray(state["force_mean_N"], dtype=float).copy()
        self._force_last = np.asarray(state["force_last_N"], dtype=float).copy()
        self._fluid_mean = np.asarray(state["fluid_force_mean_N"], dtype=float).copy()

    def allocation(self) -> dict:
        """Bytes held per component: on one level the LBM (populations and fluid arrays) and the phase field (h,
        phi), on levels each level's blocks (populations; the finest with its phase field); the DEM and the
        coupling."""
        if self.uniform:
            fl = self.fluid
            grid = {"lbm": array_bytes(fl.fluid, fl), "phase_field": array_bytes(fl.phase)}
        else:
            grid = {f"level{lv}": int(n) for lv, n in self.level_bytes.items()}
        return {**grid, "dem": array_bytes(self.dem), "coupling": array_bytes(self.coupling)}

    def describe(self) -> dict:
        u = self.units
        per = self.octree.blocks_per_level()
        return {**self.describe_ship(), "shape_cells": list(self.shape_cells), "cells": self.cells,
                "levels": len(per) - 1, "leaf_blocks_per_level": [int(n) for n in per],
                "cells_per_level": {str(k): v for k, v in self.cells_per_level.items()},
                "regrid_every_steps": self.regrid_every, "scheme": self.scheme,
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
