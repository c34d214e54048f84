"""Tier 2: the ship in a brash-ice channel with the coupled LBM-DEM, the paper's method (sections 2-4).

Built on :class:`~iceresist.coupling.floating.FloatingBodies`: water under gravity in a closed tank (free-surface
LBM with the phase field, eqs. 1-11), the hull as a kinematic body moving at the prescribed speed along +x
(convex-hull signed distance for the fluid, the same DEM sphere clump as tier 1 for contacts), the ice cubes as
dynamic bodies (box signed distance + DEM clump) moved by gravity, the fluid force of the momentum exchange
(eqs. 16-21; buoyancy is the hydrostatic pressure of the LBM) and the DEM contacts, the tank walls as DEM planes.

Units (the rule of :meth:`iceresist.scene.schema.Scene.units`):

* dx = ``domain.dx_m``;
* dt = mach dx / max(U_ship, sqrt(g h)), ``numerics.mach`` the lattice velocity limit, h the water depth: the
  ship and the shallow-water wave both stay at or below ``mach`` in lattice units. Gravity is then fixed by dt:
  g_lattice = g dt^2 / dx (what :class:`FloatingBodies` takes; its hydrostatic density change over the depth,
  3 g_lattice h/dx = 3 (sqrt(g h) dt/dx)^2 <= 3 mach^2, is the same limit seen from the pressure);
* tau = 1/2 + 3 nu dt / dx^2 from ``fluid.nu_m2_s``. The paper runs the cumulant operator without a turbulence
  model at the water's viscosity (tau - 1/2 ~ 1e-5 here); we do the same when ``fluid.nu_m2_s`` is the water's.
  Coarse presets may raise ``fluid.nu_m2_s`` (an effective viscosity, a stability floor written in the scene,
  see :mod:`iceresist.scene.case_scenes`); ``tau_floor`` (constructor) is the other way to set a floor on tau.

One model step is one record interval: ``contact.sample_interval_s`` rounded to whole LBM steps. The recorded
ice force is the mean over the LBM steps of the interval (each the mean over its DEM sub-steps) of the DEM contact
force of the ice on the hull (paper section 4.2; water resistance excluded); the fluid force on the hull
(pressure and friction of the LBM, eq. 20) is recorded beside it as ``Fx_fluid_N`` etc.

The set-up both tiers share (hull, ice channel, DEM, frames) is :class:`~iceresist.models.ship.ShipModel`.
"""

from __future__ import annotations

import logging
import math
from abc import abstractmethod

import numpy as np

from iceresist.backends.graphs import StepReplay
from iceresist.coupling.floating import FloatingBodies
from iceresist.coupling.geometry import Box, ConvexPolyhedron, ConvexUnion
from iceresist.errors import InputError
from iceresist.grid.grid import Grid
from iceresist.models.base import array_bytes
from iceresist.models.fluid import check_block_shape, resolve_target
from iceresist.models.ship import ShipModel, ship_start_x_m, steady_window_m
from iceresist.ship.meshhull import MeshHull
from iceresist.ship.tank import start_wave, tank_flow
from iceresist.units import GRAVITY_M_S2, Units

log = logging.getLogger(__name__)


def start_wave_of_scene(scene, geometry, layout) -> tuple:
    """(:class:`~iceresist.ship.tank.StartWave`, steady window in s after the start) of a tier-2 ship scene:
    the long wave of the impulsive start in the scene's tank, and when the window begins and ends."""
    width_m = scene.shape_cells()[1] * scene.units().dx_m
    speed = float(scene.ship.speed_m_s)
    wave = start_wave(geometry.midship_area_m2, width_m, float(scene.free_surface.water_depth_m), speed,
                      geometry.prismatic_length_m)
    x0 = ship_start_x_m(scene)
    window_m = steady_window_m(scene, geometry, layout)
    window_s = tuple((x - x0) / speed for x in window_m) if speed > 0 else (math.inf, math.inf)
    return wave, window_s


class Tier2Ship(ShipModel):
    """What both tier-2 models share (the uniform grid's :class:`Tier2Model` and the refined levels'
    :class:`~iceresist.models.refined_tier2.RefinedTier2Model`): the scene's checks, the ship, ice and tank, the
    bodies the coupling moves, and the tank's water motion read from the surface heights."""

    components = ("lbm", "free-surface", "dem", "coupling", "ship", "ice")
    tier = 2

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

    @abstractmethod
    def _surface_height_m(self) -> np.ndarray | None:
        """Height (m from the bottom) of the free surface over each level-0 column (nx, ny), a floe counted as water
        (:meth:`FreeSurfaceFluid.surface_height`); None on an MPI rank other than 0."""

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


class Tier2Model(Tier2Ship):
    """Coupled LBM-DEM ship + ice + water for a scene with ``[ship]`` (tier 2), ``[ice]`` and ``[free_surface]``.

    ``backend``, ``precision`` override the scene's ``[numerics]``; ``tau_floor`` raises tau to at least this
    value (module docstring); ``comm``: the MPI communicator of a run on several ranks (the tank split over them,
    :class:`~iceresist.coupling.floating.FloatingBodies`; records, fields and checkpoints the whole tank's)."""

    def __init__(self, scene, *, backend: str | None = None, precision: str | None = None,
                 tau_floor: float | None = None, comm=None):
        self.backend, self.precision = backend, precision
        gvec = self._set_up_tier2(scene)
        lu = scene.units()
        dx = lu.dx_m
        con = self.contact
        dem_backend = "cuda" if self.target.is_cuda else "cpu"

        # lattice units: dt from the Mach rule, gravity from dt, tau from the viscosity (or the floor)
        lbm_dt = lu.dt_s
        g_lat = GRAVITY_M_S2 * lbm_dt ** 2 / dx
        tau = max(lu.tau, float(tau_floor)) if tau_floor is not None else lu.tau
        nu = (tau - 0.5) * dx * dx / (3.0 * lbm_dt)

        dem = self._make_dem(backend=dem_backend, precision="float64", gravity_m_s2=gvec)
        self._add_tank_walls(dem)
        self.fb = FloatingBodies(self.shape_cells, depth_m=self.level_m, dx_m=dx, tau=tau, g_lattice=g_lat,
                                 rho_kg_m3=self.rho_w, operator=scene.fluid.operator, precision=self.precision,
                                 target=self.target, mobility=scene.free_surface.mobility_lattice,
                                 width=scene.free_surface.interface_width_cells, dem=dem,
                                 contact_film=con.fluid_film, comm=comm)
        self.grid = Grid.of_forest(self.fb.global_forest, comm, self.fb.decomp)
        self.comm, self.decomp = self.grid.comm, self.grid.decomp
        self.dem = dem
        self.hull_body = 0                      # the hull first (:meth:`coupled_bodies`)
        for geometry, shape, kw in self.coupled_bodies():
            self.fb.add_body(geometry, shape, **kw)
        self.fb.start()
        self.lbm_dt_s = self.fb.dt_s
        self.lbm_steps_per_record = max(1, int(math.ceil(con.sample_interval_s / self.lbm_dt_s - 1e-9)))
        self.dt_s = self.lbm_steps_per_record * self.lbm_dt_s
        #: the lattice's scales: dt is the LBM step (a model step, one record, is ``dt_s``)
        self.units = Units(dx_m=dx, dt_s=self.lbm_dt_s, rho0_kg_m3=self.rho_w, nu_m2_s=nu, tau=tau)
        self.g_lattice = g_lat
        self.cells = int(self.fb.global_forest.cells)
        self._iteration = 0
        self.lbm_steps = 0
        self._probes = 0
        self._force_mean = np.zeros(3)
        self._force_last = np.zeros(3)
        self._fluid_mean = np.zeros(3)
        self.water_volume0_m3 = self.fb.water_volume_m3()
        #: on a GPU (one process) the coupled step is replayed as a CUDA graph (:mod:`iceresist.backends.graphs`)
        self.replay = StepReplay(self.target, enabled=self.decomp is None)
        log.info("tier 2: %d cells %s, dx %.4g m, dt %.4g s (%d per record), tau %.6g, g_lattice %.3g, "
                 "ship %.3g cells/step; %s, %d hull spheres", self.cells, self.shape_cells, dx,
                 self.lbm_dt_s, self.lbm_steps_per_record, tau, g_lat, self.speed_m_s * self.lbm_dt_s / dx,
                 self.ice_summary(), self.hull.n_spheres)

    # -- protocol ---------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return self._iteration

    @property
    def lattice_steps_per_step(self) -> int:
        return self.lbm_steps_per_record

    @property
    def substeps_per_record(self) -> int:
        return self.lbm_steps_per_record * max(1, self.dem.substeps_for(self.lbm_dt_s))

    def step(self, n: int = 1):
        """n record intervals of ``lbm_steps_per_record`` coupled steps; each leaves the mean ice (contact) force
        and the mean fluid force on the hull over the interval."""
        hb = self.hull_body
        for _ in range(int(n)):
            self.dem.reset_contact_sums()
            self.fb.coupling.reset_fluid_load_sum()
            subs = 0
            for _ in range(self.lbm_steps_per_record):
                self.replay.run(self._coupled_step)
                subs += self.dem.last_substeps
            self._iteration += 1
            self.lbm_steps += self.lbm_steps_per_record
            # the sums stay on the target over the interval: one read each per record
            self._force_mean = self.dem.contact_sum_on(hb)[:3] / max(subs, 1)
            self._fluid_mean = self.fb.coupling.take_fluid_load_sum()[hb, :3] / self.lbm_steps_per_record
        self._force_last = self.dem.ice_force_on(hb)

    def _coupled_step(self):
        self.fb.step(1, accumulate_contacts=True)

    def fields(self) -> dict:
        """Dense fields (physical units): rho (kg/m^3), u (m/s, [x, y, z, 3]), pressure (Pa, gauge
        c_s^2 (rho - 1) rho_w (dx/dt)^2, zero at the free surface), flags (1 liquid, 0 gas or solid), phi (phase
        field, 1 water, 0 air). rho, u and pressure are 0 outside the liquid (where flags = 0), so that the NaN
        check of the field writer sees only real blow-ups."""
        phi, rho, u = self.fb.fields()
        if phi is None:         # an MPI rank other than 0
            return None
        c = self.units.dx_m / self.units.dt_s
        liquid = np.isfinite(rho)
        return {"rho": np.where(liquid, rho * self.rho_w, 0.0),
                "u": np.where(liquid[..., None], np.moveaxis(u, 0, -1) * c, 0.0),
                "pressure": np.where(liquid, (rho - 1.0) / 3.0 * self.rho_w * c * c, 0.0),
                "flags": liquid.astype(np.uint8), "phi": phi}

    def field_units(self, lattice: bool) -> dict:
        return {"rho": "kg/m^3", "u": "m/s", "pressure": "Pa", "flags": "bits", "phi": "1"}

    def surface_height_m(self) -> np.ndarray:
        """Height of the free surface (phi = 1/2) in each column (nx, ny), metres from the tank bottom (on several
        ranks on rank 0, None on the others)."""
        h = self.fb.fluid.surface_height()
        return None if h is None else h * self.units.dx_m

    def is_finite(self) -> bool:
        return bool(np.isfinite(self._force_mean).all() and np.isfinite(self._fluid_mean).all()
                    and np.isfinite(self.dem.positions).all() and math.isfinite(self.fb.water_volume_m3()))

    #: Records between watchdog checks (:mod:`iceresist.watchdog`): a record is several LBM steps, and a blow-up
    #: grows from one cell to NaN within a few of them.
    watchdog_interval = 1

    #: Every this many probes (the first included) the watchdog reads the populations: density band and kinetic
    #: energy. The probes between read the velocity the step already holds. Both are reduced per block on the
    #: target (:mod:`iceresist.freesurface.probe`): on a 3.2e6-cell quick case on a 2-core CPU the full probe
    #: takes 0.13 s and the cheap one 0.03 s, against about 10 s for a record (docs/notes/coupled-step-speed.md).
    full_probe_every = 10

    def watchdog_probe(self, full: bool | None = None) -> dict:
        """What the run watchdog checks, with the cell where it happens (:mod:`iceresist.watchdog`): finite phase
        field, finite velocity on the liquid cells (a cell a body covers is GHOST, not liquid), the fastest wet
        cell (lattice speed), reduced on the target (:meth:`FreeSurfaceFluid.probe`), the fastest ice body against
        10 x max(ship speed, sqrt(g a)) (as tier 1); and on a ``full`` probe (default: every
        :attr:`full_probe_every`-th, the first included) finite populations, the lattice density band and the
        fluid kinetic energy of the wet cells (lattice units; reference: all cells moving at the ship's
        lattice speed)."""
        if full is None:
            full = self._probes % self.full_probe_every == 0
        self._probes += 1
        self.fb.coupling.check_link_list()      # CUDA: the links passes since the last probe found no cell left out
        u_ship = self.speed_m_s * self.units.dt_s / self.units.dx_m
        probe = self.fb.fluid.probe(full, 0.5 * self.cells * u_ship ** 2)
        if not probe["finite"][0]:
            return probe
        ice = self.ice_probe()
        if not ice["finite"][0]:
            return ice
        return {**probe, **{k: v for k, v in ice.items() if k != "finite"}}

    def diagnostics(self) -> dict:
        """One record: mean ice (contact) force on the hull (N), the mean fluid force on it (N), stem position (m),
        contacts, ice kinetic energy (J), water volume (m^3, outside the bodies), and the tank's water motion
        (:meth:`tank_motion`)."""
        return self.record_columns(self.fb.water_volume_m3())

    def _surface_height_m(self) -> np.ndarray | None:
        h = self.fb.fluid.surface_height(covered_as_water=True)
        return None if h is None else h * self.units.dx_m

    def state(self) -> dict:
        """Everything a bit-for-bit restart needs: the record count and the last forces, the fluid (population
        rows, h, phi, flags), the coupling (cell owners, previous forces), the DEM with its contact history, and
        the ice bodies alone under ``positions_m`` etc. (for readers of the checkpoint). On several ranks the whole
        tank on rank 0 (None on the others), so that a checkpoint restarts on any number of ranks."""
        flow = self.fb.state()
        if flow is None:        # an MPI rank other than 0
            return None
        return {"iteration": np.int64(self.iteration), "lbm_steps": np.int64(self.lbm_steps),
                "force_mean_N": self._force_mean.copy(), "force_last_N": self._force_last.copy(),
                "fluid_force_mean_N": self._fluid_mean.copy(), "precision": self.precision,
                **flow, "dem": self.dem.state(), **self.ice_state()}

    def load_state(self, state: dict):
        """Continue from :meth:`state` of a model built from the same scene (same backend precision)."""
        if "fluid" not in state or "coupling" not in state or "dem" not in state:
            raise InputError("the checkpoint holds no tier-2 flow state (it was written before tier-2 checkpoints "
                             "kept the populations and the phase field): run the scene again without --pickup")
        if str(state.get("precision", self.precision)) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        self.fb.load_state(state["fluid"], state["coupling"])
        self.dem.load_state(state["dem"])
        self._iteration = int(state["iteration"])
        self.lbm_steps = int(state["lbm_steps"])
        self._force_mean = np.asarray(state["force_mean_N"], dtype=float).copy()
        self._force_last = np.asarray(state["force_last_N"], dtype=float).copy()
        self._fluid_mean = np.asarray(state["fluid_force_mean_N"], dtype=float).copy()

    def allocation(self) -> dict:
        """Bytes held per component: LBM populations and fluid arrays, phase field (h, phi), DEM, coupling."""
        fl = self.fb.fluid
        return {"lbm": array_bytes(fl.fluid, fl), "phase_field": array_bytes(fl.phase),
                "dem": array_bytes(self.dem), "coupling": array_bytes(self.fb.coupling)}

    def describe(self) -> dict:
        u = self.units
        return {**self.describe_ship(), "shape_cells": list(self.shape_cells),
                "substep_s": self.lbm_dt_s / max(1, self.dem.substeps_for(self.lbm_dt_s)),
                "substeps_per_record": self.substeps_per_record,
                "record_interval_s": self.dt_s, "lbm_dt_s": self.lbm_dt_s,
                "lbm_steps_per_record": self.lbm_steps_per_record,
                "resolution_m": u.dx_m, "dx_m": u.dx_m, "tau": u.tau, "g_lattice": self.g_lattice,
                "nu_m2_s": u.nu_m2_s, "operator": self.scene.fluid.operator,
                "ship_lattice_speed": self.speed_m_s * u.dt_s / u.dx_m, "tank": self.tank.describe(),
                "start_wave": {**self.start_wave.describe(), "steady_window_s": list(self.window_s),
                               "window_fraction": self.start_wave.window_fraction(*self.window_s)},
                "cells_per_cube": self.layout.cube_m / u.dx_m, "allocation_bytes": self.allocation(),
                **self.grid.describe()}
