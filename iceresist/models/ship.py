"""The ship in a brash-ice channel, the part tiers 1 and 2 share (paper section 3, docs/SHIP.md).

:class:`ShipModel` sets up what both tiers hold: the hull geometry and its DEM sphere clump, the ice channel
layout, the stem start and the steady window, the DEM system with its contact law and the tank walls, the ice
cube shape. Tier 1 (:mod:`iceresist.models.tier1`) adds water models to the DEM; tier 2
(:mod:`iceresist.models.tier2`) the coupled free-surface LBM.

Frames: world x along the tank, y across, z up from the tank bottom; the water surface is at
``free_surface.water_depth_m``. The ship position ``x_bow_m`` is the stem at the waterline.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from iceresist.dem import ContactParameters, DEMSystem, box, convex_polyhedron, mesh_solid
from iceresist.errors import InputError
from iceresist.limits import check_ice_floats, check_scene_ice
from iceresist.models.base import Model
from iceresist.scene.schema import Contact
from iceresist.ship.cases import MIN_WINDOW_HULL_LENGTHS
from iceresist.ship.channel import ChannelLayout, channel_layout
from iceresist.ship.hull import HullGeometry
from iceresist.ship.icefield import IceField, ice_field
from iceresist.ship.meshhull import MeshHull
from iceresist.ship.sizing import check_window


def hull_geometry(scene) -> HullGeometry | MeshHull:
    """The hull of a scene's ``[ship]`` section: the parametric :class:`HullGeometry` or a :class:`MeshHull`."""
    sh = scene.ship
    if sh.hull == "mesh":
        return MeshHull.from_file(sh.mesh_file, sh.draught_m, unit=sh.mesh_unit, bow=sh.mesh_bow, up=sh.mesh_up,
                                  scale=sh.mesh_scale, scene_source=scene.source_name)
    stern = sh.stern_angle_deg
    if stern is None:
        stern = 45.0 if sh.bow_angle_deg == 30.0 else 30.0 if sh.bow_angle_deg == 45.0 else sh.bow_angle_deg
    return HullGeometry(length_overall_m=sh.length_m, beam_m=sh.beam_m, draught_m=sh.draught_m,
                        parallel_length_m=sh.parallel_length_m, waterline_angle_deg=sh.waterline_angle_deg,
                        bow_rake_deg=sh.bow_angle_deg, stern_rake_deg=stern)


def hull_shape(geometry: HullGeometry | MeshHull, spacing_m: float, band_m: float, density_kg_m3: float = 500.0):
    """The hull as a DEM clump: spheres on the faces, kept up to ``band_m`` above the waterline. A convex hull
    (B-063, or a mesh that fills its convex hull) by :func:`~iceresist.dem.convex_polyhedron`, any other mesh by
    :func:`~iceresist.dem.mesh_solid`.

    Mass properties are those of the whole solid (they do not matter for a kinematic body)."""
    if isinstance(geometry, MeshHull) and not geometry.is_convex:
        shape = mesh_solid(geometry.vertices(), geometry.faces, density_kg_m3, spacing_m, name="hull",
                           z_max_m=geometry.draught_m + band_m)
    else:
        shape = convex_polyhedron(geometry.vertices(), density_kg_m3, spacing_m, name="hull")
    model_z = (shape.model_com_m + shape.sphere_offsets_m @ shape.model_to_body.T)[:, 2]
    keep = model_z <= geometry.draught_m + band_m
    return dataclasses.replace(shape, sphere_offsets_m=shape.sphere_offsets_m[keep])


def ice_layout(scene, width_m: float, centre_y_m: float, level_m: float,
               rho_w_kg_m3: float) -> ChannelLayout | IceField:
    """The scene's ice channel (``[ice]``) across ``width_m``, centred on ``centre_y_m``, floating at ``level_m``:
    the cube pattern after the pre-run ice limits (:func:`iceresist.limits.check_scene_ice`), or with
    ``ice.size_distribution`` an :class:`~iceresist.ship.icefield.IceField`."""
    ice = scene.ice
    if ice.size_distribution != "none":
        check_ice_floats(ice.density_kg_m3, rho_w_kg_m3)
        return ice_field(width_m=width_m, length_m=ice.channel_length_m, concentration=ice.concentration,
                         distribution=ice.size_distribution, size_m=ice.size_m, size_min_m=ice.size_min_m,
                         size_max_m=ice.size_max_m, size_sigma=ice.size_sigma, thickness_m=ice.thickness_m,
                         yaw=ice.yaw, start_x_m=ice.channel_start_x_m, centre_y_m=centre_y_m,
                         water_level_m=level_m, ice_density_kg_m3=ice.density_kg_m3,
                         water_density_kg_m3=rho_w_kg_m3, seed=ice.seed)
    check_scene_ice(scene, width_m)
    jitter = ice.jitter_m if ice.jitter_m is not None else (math.inf if ice.arrangement == "random" else 0.0)
    return channel_layout(width_m=width_m, length_m=ice.channel_length_m, cube_m=ice.size_m,
                          concentration=ice.concentration, count=ice.count, start_x_m=ice.channel_start_x_m,
                          centre_y_m=centre_y_m, water_level_m=level_m, ice_density_kg_m3=ice.density_kg_m3,
                          water_density_kg_m3=rho_w_kg_m3, jitter_m=jitter, seed=ice.seed)


def steady_window_m(scene, geometry: HullGeometry, layout: ChannelLayout) -> tuple[float, float]:
    """Stem positions (x0, x1) of the steady window (``ship.steady_window_m`` or the default of the schema). A default
    window shorter than :data:`~iceresist.ship.cases.MIN_WINDOW_HULL_LENGTHS` waterline lengths (empty included) is
    refused in one line naming the channel length that gives one (docs/OWN_SHIP.md)."""
    if scene.ship.steady_window_m is not None:
        return tuple(float(v) for v in scene.ship.steady_window_m)
    x0, x1 = layout.start_x_m, layout.start_x_m + layout.length_m
    lead_in = geometry.waterline_length_m if layout.length_m > geometry.waterline_length_m else geometry.end_length_m
    check_window((x0 + lead_in, x1), geometry.waterline_length_m, MIN_WINDOW_HULL_LENGTHS, layout.length_m, lead_in)
    return x0 + lead_in, x1


def check_hull_fits(scene, geometry: HullGeometry | MeshHull, domain_m, centre_y_m: float, level_m: float) -> None:
    """Refuse a hull that does not fit the tank ``domain_m`` (x along the run, y across, z up): wider than the
    tank across its centreline at ``centre_y_m``, longer than the tank, or as deep as the water ``level_m``; one
    line naming the key that sets the hull (``ship.mesh_file`` or ``ship.beam_m``, ...) and what fits."""
    sh = scene.ship
    mesh = isinstance(geometry, MeshHull)
    if mesh:
        v = geometry.vertices()
        breadth, length = float(np.ptp(v[:, 1])), float(np.ptp(v[:, 0]))
    else:
        breadth, length = float(geometry.beam_m), float(geometry.length_overall_m)
    lx, ly, _ = domain_m
    lo, hi = centre_y_m - 0.5 * breadth, centre_y_m + 0.5 * breadth
    if lo <= 0.0 or hi >= ly:
        key = "ship.mesh_file" if mesh else "ship.beam_m"
        raise InputError(f"{key}: the hull is {breadth:.4g} m wide, so its sides at y = {lo:.4g} .. {hi:.4g} m "
                         f"cross the tank's walls at y = 0 and {ly:.4g} m (domain.size_m); a hull narrower than "
                         f"{2.0 * min(centre_y_m, ly - centre_y_m):.4g} m fits (or widen the domain, or move "
                         f"ship.centre_y_m)")
    if length >= lx:
        key = "ship.mesh_file" if mesh else "ship.length_m"
        raise InputError(f"{key}: the hull is {length:.4g} m long and the tank {lx:.4g} m (domain.size_m): a hull "
                         f"shorter than the tank fits, with room for the channel ahead of it")
    if geometry.draught_m >= level_m:
        raise InputError(f"ship.draught_m: {geometry.draught_m:.4g} m is not less than the water depth "
                         f"{level_m:.4g} m (free_surface.water_depth_m): the hull would sit on the bottom; give a "
                         f"draught below {level_m:.4g} m or deeper water")


def ship_start_x_m(scene) -> float:
    """Stem position at the start (m): ``ship.start_x_m``, by default 5 cm before the channel."""
    sh = scene.ship
    return float(sh.start_x_m) if sh.start_x_m is not None else float(scene.ice.channel_start_x_m) - 0.05


class ShipModel(Model):
    """A ship scene's set-up shared by both tiers: hull, ice channel, DEM with its contact law and tank walls.

    Subclasses call :meth:`_set_up_ship` with the tank's size, then :meth:`_make_dem`, and add the hull and
    the cubes to the DEM (tier 2 through the coupling) in their own order."""

    tier: int
    #: LBM steps taken (tier 2 counts them; tier 1 has no lattice).
    lbm_steps: int = 0

    def _check_sections(self, scene) -> None:
        if scene.ship is None or scene.ice is None or scene.free_surface is None:
            raise InputError(f"{scene.source_name}: a tier-{self.tier} ship scene needs [ship], [ice] and "
                             f"[free_surface]")

    def _set_up_ship(self, scene, domain_m) -> None:
        """Hull geometry, ice layout, speed, start and steady window of ``scene`` in a tank of ``domain_m``."""
        self._check_sections(scene)
        self.scene = scene
        sh, ice = scene.ship, scene.ice
        self.contact = scene.contact or Contact()
        self.domain_m = tuple(float(v) for v in domain_m)
        self.level_m = float(scene.free_surface.water_depth_m)
        if self.level_m >= self.domain_m[2]:
            raise InputError(f"free_surface.water_depth_m: {self.level_m} m fills the {self.domain_m[2]:.4g} m deep "
                             f"domain")
        self.rho_w = float(scene.rho_kg_m3)
        self.geometry = hull_geometry(scene)
        self.centre_y_m = sh.centre_y_m if sh.centre_y_m is not None else 0.5 * self.domain_m[1]
        check_hull_fits(scene, self.geometry, self.domain_m, self.centre_y_m, self.level_m)
        width = ice.channel_width_m or self.domain_m[1]
        self.layout = ice_layout(scene, width, self.centre_y_m, self.level_m, self.rho_w)
        self.speed_m_s = float(sh.speed_m_s)
        self.start_x_m = ship_start_x_m(scene)
        self.window_m = steady_window_m(scene, self.geometry, self.layout)
        self.hull = hull_shape(self.geometry, sh.sphere_spacing_m, sh.sphere_band_m)
        if isinstance(self.layout, IceField):
            # one shape per floe, spheres of one radius (thickness / spheres_per_edge apart); the heaviest floe
            # stands for all where one is asked for (the pre-run limits of the impact overlap)
            lay = self.layout
            spacing = lay.thickness_m / ice.spheres_per_edge
            self.floe_shapes = [box((a, a, lay.thickness_m), ice.density_kg_m3, spacing_m=spacing, name="ice")
                                for a in lay.sizes_m]
            self.floe_orientations = [(math.cos(t / 2), 0.0, 0.0, math.sin(t / 2)) for t in lay.yaw_rad]
            self.cube = self.floe_shapes[int(np.argmax(lay.sizes_m))]
        else:
            self.cube = box((ice.size_m,) * 3, ice.density_kg_m3, spheres_per_edge=ice.spheres_per_edge, name="ice")
            self.floe_shapes = [self.cube] * self.layout.count
            self.floe_orientations = [None] * self.layout.count

    def _make_dem(self, *, backend: str, precision: str, gravity_m_s2):
        """The DEM system with the scene's contact law (ice-ice and ice-ship) and no bodies yet."""
        con = self.contact
        kt = con.tangential_stiffness_ratio * con.stiffness_N_m
        return DEMSystem(backend=backend, precision=precision, gravity_m_s2=tuple(gravity_m_s2),
                         ice_ice=ContactParameters(con.stiffness_N_m, kt, con.restitution, con.friction_ice_ice),
                         ice_ship=ContactParameters(con.stiffness_N_m, kt, con.restitution, con.friction_ice_hull),
                         safety=con.dem_safety, dashpot=con.dashpot)

    def _add_tank_walls(self, dem) -> None:
        """The tank's ends, sides and bottom as DEM planes (the top is open)."""
        Lx, Ly, _ = self.domain_m
        for point, normal in (((0, 0, 0), (1, 0, 0)), ((Lx, 0, 0), (-1, 0, 0)), ((0, 0, 0), (0, 1, 0)),
                              ((0, Ly, 0), (0, -1, 0)), ((0, 0, 0), (0, 0, 1))):
            dem.add_wall(point, normal)

    # -- what both tiers answer the same way ------------------------------------------------------------
    @property
    def x_bow_m(self) -> float:
        """Stem position at the waterline (m); the hull moves rigidly at the prescribed speed."""
        return self.start_x_m + self.speed_m_s * self.time_s

    def _ice_mask(self) -> np.ndarray:
        return np.arange(self.dem.n_bodies) != self.hull_body

    def ice_state(self) -> dict:
        """Cube centres (n, 3) m, quaternions (n, 4) and velocities (n, 3) m/s now (hull excluded)."""
        ice = self._ice_mask()
        return {"positions_m": self.dem.positions[ice], "quaternions": self.dem.quaternions[ice],
                "velocities_m_s": self.dem.velocities[ice]}

    def ice_speed_reference_m_s(self) -> float:
        """max(ship speed, sqrt(g a)), a the cube edge: the speed scale of the ice (watchdog limits)."""
        g = float(np.linalg.norm(self.scene.fluid.gravity_m_s2)) or 9.81
        return max(self.speed_m_s, math.sqrt(g * self.layout.cube_m))

    def ice_probe(self) -> dict:
        """The ice part of the watchdog probe: a body with a non-finite position or velocity, else the fastest
        ice body against 10 x :meth:`ice_speed_reference_m_s`."""
        ice = self._ice_mask()
        pos, vel = self.dem.positions[ice], self.dem.velocities[ice]
        bad = ~(np.isfinite(pos).all(axis=1) & np.isfinite(vel).all(axis=1))
        if bad.any():
            return {"finite": (False, {"body": int(np.flatnonzero(ice)[np.flatnonzero(bad)[0]])})}
        speed = np.sqrt((vel ** 2).sum(axis=1))
        if not speed.size:
            return {"finite": (True, None)}
        b = int(np.argmax(speed))
        return {"finite": (True, None), "max_body_speed_m_s": (float(speed[b]), {"body": int(np.flatnonzero(ice)[b])}),
                "max_body_speed_limit_m_s": 10.0 * self.ice_speed_reference_m_s()}

    def ice_summary(self) -> str:
        """The ice in a few words, for the log."""
        lay = self.layout
        if isinstance(lay, IceField):
            return (f"{lay.count} floes ({lay.distribution} edges {1e3 * lay.sizes_m.min():.0f}-"
                    f"{1e3 * lay.sizes_m.max():.0f} mm, median {1e3 * lay.cube_m:.0f} mm, {1e3 * lay.thickness_m:.0f} mm "
                    f"thick, {100 * lay.concentration:.1f} %)")
        return f"{lay.count} ice cubes ({lay.n_across} x {lay.n_along})"

    def layout_description(self) -> dict:
        """An ice field's distribution and what the packing gave (the floes themselves go to the result file)."""
        lay = self.layout
        return {"distribution": lay.distribution, "seed": lay.seed, "floes": lay.count,
                "concentration": lay.concentration, "thickness_m": lay.thickness_m, "gap_m": lay.gap_m,
                "columns": lay.columns, "size_median_m": lay.cube_m, "size_mean_m": float(lay.sizes_m.mean()),
                "size_smallest_m": float(lay.sizes_m.min()), "size_largest_m": float(lay.sizes_m.max()),
                **lay.info}

    def floes_record(self) -> dict:
        """Per floe at the start: edge (m), thickness (m) and yaw (rad), for the result file's ``bodies`` group."""
        lay = self.layout
        if isinstance(lay, IceField):
            return {"floe_sizes_m": lay.sizes_m, "floe_thickness_m": np.full(lay.count, lay.thickness_m),
                    "floe_yaw_rad": lay.yaw_rad}
        return {"floe_sizes_m": np.full(lay.count, lay.cube_m), "floe_thickness_m": np.full(lay.count, lay.cube_m),
                "floe_yaw_rad": np.zeros(lay.count)}

    def describe_ship(self) -> dict:
        """The run metadata both tiers write: bodies, channel, ship and hull."""
        g = self.geometry
        return {"components": list(self.components), "tier": self.tier, "backend": self.target.name,
                "precision": self.precision, "cells": self.cells, "bodies": self.dem.n_bodies,
                "spheres": self.dem.n_spheres, "hull_spheres": self.hull.n_spheres, "ice_cubes": self.layout.count,
                "channel_grid": [self.layout.n_across, self.layout.n_along],
                "concentration": self.layout.concentration, "cube_m": self.layout.cube_m,
                "channel_start_x_m": self.layout.start_x_m, "channel_length_m": self.layout.length_m,
                "channel_width_m": self.layout.width_m, "centre_y_m": self.centre_y_m,
                "water_level_m": self.level_m, "speed_m_s": self.speed_m_s, "start_x_m": self.start_x_m,
                "steady_window_m": list(self.window_m), "critical_step_s": self.dem.critical_step_s(),
                **({"ice_field": self.layout_description()} if isinstance(self.layout, IceField) else {}),
                "hull": g.describe() if isinstance(g, MeshHull) else
                {"kind": "b063", "length_overall_m": g.length_overall_m, "beam_m": g.beam_m, "draught_m": g.draught_m,
                 "parallel_length_m": g.parallel_length_m, "waterline_angle_deg": g.waterline_angle_deg,
                 "bow_rake_deg": g.bow_rake_deg, "stern_rake_deg": g.stern_rake_deg,
                 "waterline_length_m": g.waterline_length_m, "freeboard_m": g.freeboard_m}}
