"""The ship in a brash-ice channel, the part tiers 1 and 2 share (paper section 3, docs/SHIP.md).

:class:`ShipModel` sets up what both tiers hold: the hull geometry and its DEM sphere clump, the ice channel
layout, the stem start and the steady window, the DEM system with its contact law and the tank walls, the ice
cube shape. Tier 1 (:mod:`iceresist.models.tier1`) adds water models to the DEM; tier 2
(:mod:`iceresist.models.tier2`) the coupled free-surface LBM.

Frames: world x along the tank, y across, z up from the tank bottom; the water surface is at
``free_surface.water_depth_m``. The ship position ``x_bow_m`` is the stem at the waterline.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.dem import ContactParameters, DEMSystem, box
from iceresist.errors import InputError
from iceresist.models.base import Model
from iceresist.scene.schema import Contact
from iceresist.ship.from_scene import (check_hull_fits, hull_geometry, hull_shape, ice_layout, ship_start_x_m,
                                       steady_window_m)
from iceresist.ship.icefield import IceField
from iceresist.ship.meshhull import MeshHull


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
