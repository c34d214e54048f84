"""The ship, its channel and its steady window as a scene's ``[ship]`` and ``[ice]`` give them (paper section 3,
docs/SHIP.md), for the models of tiers 1 and 2 (:mod:`iceresist.models.ship`): the hull geometry and its DEM clump, the
ice layout, the stem's start, the steady window, the start wave and the check that the hull fits the tank.

``scene`` is any object with the scene's sections (:class:`iceresist.scene.schema.Scene`; this module imports nothing
from the scene's package, which imports the ship's).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from iceresist.dem import convex_polyhedron, mesh_solid
from iceresist.errors import InputError
from iceresist.limits import check_ice_floats, check_scene_ice
from iceresist.ship.cases import MIN_WINDOW_HULL_LENGTHS
from iceresist.ship.channel import ChannelLayout, channel_layout
from iceresist.ship.hull import HullGeometry
from iceresist.ship.icefield import IceField, ice_field
from iceresist.ship.meshhull import MeshHull
from iceresist.ship.sizing import check_window
from iceresist.ship.tank import start_wave


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
