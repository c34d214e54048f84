"""Tier 1: the ship in a brash-ice channel with DEM contacts and water models, no flow field (docs/SHIP.md).

The hull is a kinematic clump of spheres moving at the prescribed ship speed along +x; the ice cubes are free
clumps floating in still water (buoyancy, quadratic drag and added mass, :mod:`iceresist.dem.hydro`); the tank
walls (sides, bottom, ends) are DEM planes. One model step is one record interval
(``contact.sample_interval_s``, rounded to whole DEM sub-steps): the recorded ice force is the mean over the
sub-steps of the interval of the contact force the ice exerts on the hull (paper section 4.2; water resistance
is not part of it). The set-up both tiers share is :class:`~iceresist.models.ship.ShipModel`.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.dem import Water
from iceresist.errors import InputError
from iceresist.limits import check_tier1
from iceresist.models.base import array_bytes
from iceresist.models.ship import ShipModel

log = logging.getLogger(__name__)


class Tier1Model(ShipModel):
    """DEM ship + ice + tier-1 water for a scene with ``[ship]``, ``[ice]`` and ``[free_surface]``."""

    components = ("dem", "ship", "ice", "water-model")
    tier = 1
    units = None  # no lattice

    def __init__(self, scene, *, backend: str | None = None, precision: str | None = None):
        size = scene.domain.size_m or tuple(n * scene.domain.dx_m for n in scene.domain.cells)
        self._set_up_ship(scene, size)
        g, ice, con = self.geometry, scene.ice, self.contact
        self.backend = backend or scene.numerics.backend
        self.precision = precision or "float64"
        self.dem = self._make_dem(backend=self.backend, precision=self.precision,
                                  gravity_m_s2=scene.fluid.gravity_m_s2)
        self.hull_body = self.dem.add_body(self.hull, position_m=(self.start_x_m, self.centre_y_m,
                                                                  self.level_m - g.draught_m),
                                           velocity_m_s=(self.speed_m_s, 0.0, 0.0), kinematic=True,
                                           material="ship", name="hull")
        for shape, c, q in zip(self.floe_shapes, self.layout.centres_m, self.floe_orientations):
            self.dem.add_body(shape, position_m=c, orientation=q, material="ice")
        self._add_tank_walls(self.dem)
        self.dem.set_water(Water(level_m=self.level_m, density_kg_m3=self.rho_w,
                                 drag_coefficient=ice.drag_coefficient,
                                 added_mass_coefficient=ice.added_mass_coefficient))
        self.substep_s = self.dem.substep_s()
        self.substeps_per_step = max(1, int(math.ceil(con.sample_interval_s / self.substep_s - 1e-9)))
        self.dt_s = self.substeps_per_step * self.substep_s
        self.substep_s = self.dt_s / self.substeps_per_step  # the sub-step DEMSystem.step takes, to the last bit
        check_tier1(self)
        self._iteration = 0
        self._force_mean = np.zeros(3)
        self._force_last = np.zeros(3)
        log.info("tier 1: %s, %d hull spheres, %d spheres, sub-step %.3g s, %d per record", self.ice_summary(),
                 self.hull.n_spheres, self.dem.n_spheres, self.substep_s, self.substeps_per_step)

    # -- protocol ---------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return self._iteration

    @property
    def target(self):
        """The DEM's compile target (what the run job logs)."""
        return self.dem.target

    def step(self, n: int = 1):
        """n record intervals; each leaves the mean ice force on the hull over its sub-steps (kept by the DEM)."""
        for _ in range(int(n)):
            self.dem.step(self.dt_s, substeps=self.substeps_per_step)
            self._iteration += 1
        self._force_mean = self.dem.mean_contact_force_on(self.hull_body)
        self._force_last = self.dem.ice_force_on(self.hull_body)

    def fields(self) -> dict:
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
        10 x max(ship speed, sqrt(g a)) (:meth:`ShipModel.ice_probe`), and the growth of the ice kinetic energy,
        counted from at least that of all the ice moving at max(ship speed, sqrt(g a))."""
        probe = self.ice_probe()
        if not probe["finite"][0]:
            return probe
        if not np.isfinite(self._force_mean).all():
            return {"finite": (False, {"body": self.hull_body})}
        u_ref = self.ice_speed_reference_m_s()
        mass = self.layout.count * self.cube.mass_kg
        return {"max_body_speed_m_s": (0.0, None), "max_body_speed_limit_m_s": 10.0 * u_ref, **probe,
                "kinetic_energy": self.dem.kinetic_energy(), "kinetic_energy_ref": 0.5 * mass * u_ref ** 2}

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
        self._iteration = int(state["iteration"])
        self._force_mean = np.asarray(state["force_mean_N"], dtype=float).copy()
        self._force_last = np.asarray(state["force_last_N"], dtype=float).copy()

    def describe(self) -> dict:
        return {**self.describe_ship(), "substep_s": self.substep_s, "substeps_per_record": self.substeps_per_step,
                "record_interval_s": self.dt_s, "resolution_m": 2 * self.cube.sphere_radius_m}

    def allocation(self) -> dict[str, int]:
        """Bytes of the DEM's arrays (bodies, spheres, contacts); there is no lattice."""
        return {"dem": array_bytes(self.dem)}
