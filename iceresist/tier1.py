"""Tier 1: the ship in a brash-ice channel with DEM contacts and water models, no flow field (DESIGN.md section 1).

The hull is a kinematic clump of spheres moving at the prescribed ship speed along +x; the ice cubes are free
clumps floating in still water (buoyancy, quadratic drag and added mass, :mod:`iceresist.dem.hydro`); the tank
walls (sides, bottom, ends) are DEM planes. One model step is one record interval
(``contact.sample_interval_s``, rounded to whole DEM sub-steps): the recorded ice force is the mean over the
sub-steps of the interval of the contact force the ice exerts on the hull (paper section 4.2; water resistance
is not part of it). The model follows the protocol of :mod:`iceresist.simulation`.

Frames: world x along the tank, y across, z up from the tank bottom; the water surface is at
``free_surface.water_depth_m``. The ship position ``x_bow_m`` is the stem at the waterline.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from iceresist.errors import InputError
from iceresist.ship.channel import ChannelLayout, channel_layout
from iceresist.ship.hull import HullGeometry

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Tier1Units:
    """What the run job needs of a tier-1 model's units: no lattice (``tau`` is NaN, ``dx_m`` the sphere size)."""

    dx_m: float
    dt_s: float
    tau: float = float("nan")

    def describe(self) -> dict:
        return {"dx_m": self.dx_m, "dt_s": self.dt_s, "lattice": False}


def hull_geometry(scene) -> HullGeometry:
    """The :class:`HullGeometry` of a scene's ``[ship]`` section."""
    sh = scene.ship
    stern = sh.stern_angle_deg
    if stern is None:
        stern = 45.0 if sh.bow_angle_deg == 30.0 else 30.0 if sh.bow_angle_deg == 45.0 else sh.bow_angle_deg
    return HullGeometry(length_overall_m=sh.length_m, beam_m=sh.beam_m, draught_m=sh.draught_m,
                        parallel_length_m=sh.parallel_length_m, waterline_angle_deg=sh.waterline_angle_deg,
                        bow_rake_deg=sh.bow_angle_deg, stern_rake_deg=stern)


def hull_shape(geometry: HullGeometry, spacing_m: float, band_m: float, density_kg_m3: float = 500.0):
    """The hull as a DEM clump: spheres on the faces, kept up to ``band_m`` above the waterline.

    Mass properties are those of the whole solid (they do not matter for a kinematic body)."""
    from iceresist.dem import convex_polyhedron

    shape = convex_polyhedron(geometry.vertices(), density_kg_m3, spacing_m, name="hull")
    model_z = (shape.model_com_m + shape.sphere_offsets_m @ shape.model_to_body.T)[:, 2]
    keep = model_z <= geometry.draught_m + band_m
    return dataclasses.replace(shape, sphere_offsets_m=shape.sphere_offsets_m[keep])


def ice_layout(scene, width_m: float, centre_y_m: float, level_m: float, rho_w_kg_m3: float) -> ChannelLayout:
    """The scene's ice channel (``[ice]``) across ``width_m``, centred on ``centre_y_m``, floating at ``level_m``,
    after the pre-run ice limits (:func:`iceresist.limits.check_scene_ice`); shared by tiers 1 and 2."""
    from iceresist.limits import check_scene_ice

    ice = scene.ice
    check_scene_ice(scene, width_m)
    jitter = ice.jitter_m if ice.jitter_m is not None else (math.inf if ice.arrangement == "random" else 0.0)
    return channel_layout(width_m=width_m, length_m=ice.channel_length_m, cube_m=ice.size_m,
                          concentration=ice.concentration, count=ice.count, start_x_m=ice.channel_start_x_m,
                          centre_y_m=centre_y_m, water_level_m=level_m, ice_density_kg_m3=ice.density_kg_m3,
                          water_density_kg_m3=rho_w_kg_m3, jitter_m=jitter, seed=ice.seed)


def steady_window_m(scene, geometry: HullGeometry, layout: ChannelLayout) -> tuple[float, float]:
    """Stem positions (x0, x1) of the steady window (``ship.steady_window_m`` or the default of the schema)."""
    if scene.ship.steady_window_m is not None:
        return tuple(float(v) for v in scene.ship.steady_window_m)
    x0, x1 = layout.start_x_m, layout.start_x_m + layout.length_m
    if layout.length_m > geometry.waterline_length_m:
        return x0 + geometry.waterline_length_m, x1
    return x0 + geometry.end_length_m, x1


class Tier1Model:
    """DEM ship + ice + tier-1 water for a scene with ``[ship]``, ``[ice]`` and ``[free_surface]``."""

    components = ("dem", "ship", "ice", "water-model")

    def __init__(self, scene, *, backend: str | None = None, precision: str | None = None):
        from iceresist.dem import ContactParameters, DEMSystem, Water, box
        from iceresist.scene.schema import Contact

        if scene.ship is None or scene.ice is None or scene.free_surface is None:
            raise InputError(f"{scene.source_name}: a tier-1 ship scene needs [ship], [ice] and [free_surface]")
        self.scene = scene
        sh, ice = scene.ship, scene.ice
        con = scene.contact or Contact()
        self.contact = con
        size = scene.domain.size_m or tuple(n * scene.domain.dx_m for n in scene.domain.cells)
        self.domain_m = tuple(float(v) for v in size)
        self.level_m = float(scene.free_surface.water_depth_m)
        if self.level_m >= self.domain_m[2]:
            raise InputError(f"free_surface.water_depth_m: {self.level_m} m fills the {self.domain_m[2]} m deep domain")
        self.rho_w = float(scene.rho_kg_m3)
        self.geometry = hull_geometry(scene)
        g = self.geometry
        self.centre_y_m = sh.centre_y_m if sh.centre_y_m is not None else 0.5 * self.domain_m[1]
        width = ice.channel_width_m or self.domain_m[1]
        from iceresist.limits import check_tier1

        self.layout = ice_layout(scene, width, self.centre_y_m, self.level_m, self.rho_w)
        self.speed_m_s = float(sh.speed_m_s)
        self.start_x_m = float(sh.start_x_m) if sh.start_x_m is not None else ice.channel_start_x_m - 0.05
        self.window_m = steady_window_m(scene, g, self.layout)
        self.backend = backend or scene.numerics.backend
        self.precision = precision or "float64"
        kt = con.tangential_stiffness_ratio * con.stiffness_N_m
        self.dem = DEMSystem(backend=self.backend, precision=self.precision,
                             gravity_m_s2=scene.fluid.gravity_m_s2,
                             ice_ice=ContactParameters(con.stiffness_N_m, kt, con.restitution, con.friction_ice_ice),
                             ice_ship=ContactParameters(con.stiffness_N_m, kt, con.restitution, con.friction_ice_hull),
                             safety=con.dem_safety)
        self.hull = hull_shape(g, sh.sphere_spacing_m, sh.sphere_band_m)
        self.hull_body = self.dem.add_body(self.hull, position_m=(self.start_x_m, self.centre_y_m,
                                                                  self.level_m - g.draught_m),
                                           velocity_m_s=(self.speed_m_s, 0.0, 0.0), kinematic=True,
                                           material="ship", name="hull")
        self.cube = box((ice.size_m,) * 3, ice.density_kg_m3, spheres_per_edge=ice.spheres_per_edge, name="ice")
        for c in self.layout.centres_m:
            self.dem.add_body(self.cube, position_m=c, material="ice")
        Lx, Ly, Lz = self.domain_m
        for point, normal in (((0, 0, 0), (1, 0, 0)), ((Lx, 0, 0), (-1, 0, 0)), ((0, 0, 0), (0, 1, 0)),
                              ((0, Ly, 0), (0, -1, 0)), ((0, 0, 0), (0, 0, 1))):
            self.dem.add_wall(point, normal)
        self.dem.set_water(Water(level_m=self.level_m, density_kg_m3=self.rho_w,
                                 drag_coefficient=ice.drag_coefficient,
                                 added_mass_coefficient=ice.added_mass_coefficient))
        self.substep_s = self.dem.substep_s()
        self.substeps_per_step = max(1, int(math.ceil(con.sample_interval_s / self.substep_s - 1e-9)))
        self.dt_s = self.substeps_per_step * self.substep_s
        self.substep_s = self.dt_s / self.substeps_per_step  # the sub-step DEMSystem.step takes, to the last bit
        self.units = Tier1Units(dx_m=2 * self.cube.sphere_radius_m, dt_s=self.dt_s)
        check_tier1(self)
        self.cells = 0
        self.shape_cells = None
        self.iteration = 0
        self._force_mean = np.zeros(3)
        self._force_last = np.zeros(3)
        log.info("tier 1: %d ice cubes (%d x %d), %d hull spheres, %d spheres, sub-step %.3g s, %d per record",
                 self.layout.count, self.layout.n_across, self.layout.n_along, self.hull.n_spheres,
                 self.dem.n_spheres, self.substep_s, self.substeps_per_step)

    # -- protocol ---------------------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return self.iteration * self.dt_s

    @property
    def target(self):
        """The DEM's compile target (what the run job logs)."""
        return self.dem.target

    @property
    def x_bow_m(self) -> float:
        """Stem position at the waterline (m); the hull moves rigidly at the prescribed speed."""
        return self.start_x_m + self.speed_m_s * self.time_s

    def step(self, n: int = 1):
        """n record intervals; each leaves the mean ice force on the hull over its sub-steps (kept by the DEM)."""
        for _ in range(int(n)):
            self.dem.step(self.dt_s, substeps=self.substeps_per_step)
            self.iteration += 1
        self._force_mean = self.dem.mean_contact_force_on(self.hull_body)
        self._force_last = self.dem.ice_force_on(self.hull_body)

    def fields(self) -> dict:
        return {}

    @staticmethod
    def field_units(lattice: bool) -> dict:
        return {}

    def is_finite(self) -> bool:
        return bool(np.isfinite(self._force_mean).all() and np.isfinite(self.dem.positions).all())

    def diagnostics(self) -> dict:
        """One record: mean ice force on the hull (N), the stem position (m), contacts, ice kinetic energy (J)."""
        return {"Fx_N": self._force_mean[0], "Fy_N": self._force_mean[1], "Fz_N": self._force_mean[2],
                "Fx_last_N": self._force_last[0], "x_bow_m": self.x_bow_m, "contacts": self.dem.contact_count(),
                "ice_kinetic_energy_J": self.dem.kinetic_energy()}

    def watchdog_probe(self) -> dict:
        """What the run watchdog checks (:mod:`iceresist.watchdog`): finite state, the fastest ice body against
        10 x max(ship speed, sqrt(g a)), and the growth of the ice kinetic energy,
        counted from at least that of all the ice moving at max(ship speed, sqrt(g a))."""
        ice = np.arange(self.dem.n_bodies) != self.hull_body
        pos, vel = self.dem.positions[ice], self.dem.velocities[ice]
        bad = ~(np.isfinite(pos).all(axis=1) & np.isfinite(vel).all(axis=1))
        if bad.any() or not np.isfinite(self._force_mean).all():
            where = int(np.flatnonzero(ice)[np.flatnonzero(bad)[0]]) if bad.any() else self.hull_body
            return {"finite": (False, {"body": where})}
        speed = np.sqrt((vel ** 2).sum(axis=1))
        b = int(np.argmax(speed)) if speed.size else 0
        g = float(np.linalg.norm(self.scene.fluid.gravity_m_s2)) or 9.81
        u_ref = max(self.speed_m_s, math.sqrt(g * self.layout.cube_m))
        mass = self.layout.count * self.cube.mass_kg
        return {"finite": (True, None),
                "max_body_speed_m_s": (float(speed[b]) if speed.size else 0.0,
                                       {"body": int(np.flatnonzero(ice)[b])} if speed.size else None),
                "max_body_speed_limit_m_s": 10.0 * u_ref,
                "kinetic_energy": self.dem.kinetic_energy(), "kinetic_energy_ref": 0.5 * mass * u_ref ** 2}

    def ice_state(self) -> dict:
        """Cube centres (n, 3) m, quaternions (n, 4) and velocities (n, 3) m/s now (hull excluded)."""
        ice = np.arange(self.dem.n_bodies) != self.hull_body
        return {"positions_m": self.dem.positions[ice], "quaternions": self.dem.quaternions[ice],
                "velocities_m_s": self.dem.velocities[ice]}

    def state(self) -> dict:
        """Everything a checkpoint needs to continue bit for bit: the step count, the last recorded forces and
        the DEM state with its contact history (``dem``); the ice bodies alone under ``positions_m`` etc."""
        return {"iteration": np.int64(self.iteration), "force_mean_N": self._force_mean.copy(),
                "force_last_N": self._force_last.copy(), "dem": self.dem.state(), **self.ice_state()}

    def load_state(self, state: dict):
        """Continue from :meth:`state` of a model built from the same scene."""
        if "dem" not in state:
            raise InputError("the checkpoint holds no DEM state (it was written before tier-1 checkpoints kept "
                             "the contact history): run the scene again without --pickup")
        self.dem.load_state(state["dem"])
        self.iteration = int(state["iteration"])
        self._force_mean = np.asarray(state["force_mean_N"], dtype=float).copy()
        self._force_last = np.asarray(state["force_last_N"], dtype=float).copy()

    def describe(self) -> dict:
        g = self.geometry
        return {"components": list(self.components), "tier": 1, "backend": self.dem.target.name,
                "precision": self.precision, "cells": 0, "bodies": self.dem.n_bodies,
                "spheres": self.dem.n_spheres, "hull_spheres": self.hull.n_spheres, "ice_cubes": self.layout.count,
                "channel_grid": [self.layout.n_across, self.layout.n_along],
                "concentration": self.layout.concentration, "cube_m": self.layout.cube_m,
                "channel_start_x_m": self.layout.start_x_m, "channel_length_m": self.layout.length_m,
                "channel_width_m": self.layout.width_m, "centre_y_m": self.centre_y_m,
                "water_level_m": self.level_m, "speed_m_s": self.speed_m_s, "start_x_m": self.start_x_m,
                "steady_window_m": list(self.window_m), "substep_s": self.substep_s,
                "substeps_per_record": self.substeps_per_step, "record_interval_s": self.dt_s,
                "critical_step_s": self.dem.critical_step_s(), "resolution_m": 2 * self.cube.sphere_radius_m,
                "hull": {"length_overall_m": g.length_overall_m, "beam_m": g.beam_m, "draught_m": g.draught_m,
                         "parallel_length_m": g.parallel_length_m, "waterline_angle_deg": g.waterline_angle_deg,
                         "bow_rake_deg": g.bow_rake_deg, "stern_rake_deg": g.stern_rake_deg,
                         "waterline_length_m": g.waterline_length_m, "freeboard_m": g.freeboard_m}}

    def allocated_bytes(self) -> int:
        return 0
