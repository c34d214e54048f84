"""Rigid bodies floating in water with a free surface on one uniform grid: a scene with ``[[bodies]]`` and
``[free_surface]`` without ``[refinement]`` (the floating cube, :mod:`iceresist.validate.cases.floating_cube`).

A closed tank of walls, water at ``free_surface.water_depth_m``, and the bodies, all in a
:class:`~iceresist.coupling.floating.FloatingBodies`: the hydrostatic pressure of the gravity body force is the
buoyancy, the DEM carries gravity. The bodies' shapes, DEM and columns are those of
:class:`~iceresist.models.bodies.BodiesModel` (:class:`~iceresist.models.bodies.BodyShapes`); on levels the same
scene is :class:`~iceresist.models.refined_surface_bodies.RefinedSurfaceBodiesModel`.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.coupling.floating import FloatingBodies
from iceresist.errors import InputError
from iceresist.grid import flags as FL
from iceresist.grid.grid import Grid, several
from iceresist.models.base import Model, array_bytes
from iceresist.models.bodies import BodyShapes, check_bodies, fmt_g
from iceresist.models.fluid import check_block_shape, check_free_surface_forces, resolve_target
from iceresist.models.regions import body_mesh
from iceresist.models.surface import FreeSurfaceModel
from iceresist.scene.schema import Scene


def _check_free_surface(scene: Scene) -> None:
    """What the closed tank of :class:`~iceresist.coupling.floating.FloatingBodies` takes."""
    fl, fs = scene.fluid, scene.free_surface
    check_free_surface_forces(scene)
    for name, face in scene.domain.faces.items():
        if face.kind != "wall":
            raise InputError(f"domain.faces.{name}: a free-surface scene with [[bodies]] is a closed tank: set "
                             f"{name} = \"wall\" (not {face.kind!r})")
    if fs.column_length_m is not None:
        raise InputError("free_surface.column_length_m: a scene with [[bodies]] starts with water over the whole "
                         "floor: leave column_length_m out")
    if any(fl.initial_velocity_m_s):
        raise InputError("fluid.initial_velocity_m_s: a free-surface scene with [[bodies]] starts from still "
                         "water: leave initial_velocity_m_s out")


class FloatingBodiesModel(BodyShapes, Model):
    """Boxes, spheres and convex meshes, free, fixed or prescribed, in a closed tank of water with a free surface
    (module docstring). ``backend`` and ``precision`` override the scene's ``[numerics]``; ``comm``: several MPI
    ranks (:class:`FloatingBodies` swaps the halo).

    Time series (:meth:`diagnostics`): the per-body columns of :class:`~iceresist.models.bodies.BodyShapes`, the
    water's mass, kinetic energy, largest speed, volume outside the bodies (and its drift) and level.
    """

    components = ("fluid", "free_surface", "dem", "coupling")

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        self.scene = scene
        self.comm = several(comm)
        self.backend = backend or scene.numerics.backend
        self.precision = precision or scene.numerics.precision
        self.target = resolve_target(self.backend)
        self.dem_backend = "cuda" if self.target.is_cuda else "cpu"
        u0 = scene.units()
        self.box_m = tuple(n * u0.dx_m for n in scene.domain.shape_cells())
        self.meshes = {i: body_mesh(b, i, scene.source_name) for i, b in enumerate(scene.bodies) if b.shape == "mesh"}
        check_bodies(scene, self.box_m, self.meshes)
        self.names = [b.name for b in scene.bodies]
        self._probes = 0
        self._build_free_surface(u0)

    def _build_free_surface(self, u0):
        """The tank, the DEM and the bodies placed in the still water."""
        scene = self.scene
        _check_free_surface(scene)
        fs = scene.free_surface
        self.shape_cells = scene.shape_cells()
        check_block_shape(self.shape_cells)
        nz = self.shape_cells[2]
        depth_cells = fs.water_depth_m / u0.dx_m
        if not 0.0 < depth_cells < nz:
            raise InputError(f"free_surface.water_depth_m: {fs.water_depth_m} m is {depth_cells:g} cells, outside "
                             f"the {nz}-cell-high domain")
        g = -float(scene.fluid.gravity_m_s2[2])
        g_lattice = float(u0.acceleration_to_lattice(g))
        if not 0.0 < g_lattice <= 0.01:
            raise InputError(f"numerics.dt_s: gravity is {g_lattice:.4g} in lattice units (g dt^2 / dx), above "
                             f"0.01: use a smaller time step, numerics.dt_s <= "
                             f"{fmt_g(math.sqrt(0.01 * u0.dx_m / g))} s")
        self.dem = self._make_dem((0.0, 0.0, -g))
        self._add_walls(self.dem)
        con = scene.contact
        self.fb = FloatingBodies(self.shape_cells, depth_m=fs.water_depth_m, dx_m=u0.dx_m, tau=u0.tau,
                                 g_lattice=g_lattice, rho_kg_m3=scene.rho_kg_m3, operator=scene.fluid.operator,
                                 precision=self.precision, target=self.target, mobility=fs.mobility_lattice,
                                 width=fs.interface_width_cells, dem=self.dem,
                                 contact_film=True if con is None else con.fluid_film, h_lattice=fs.h_lattice,
                                 g_m_s2=g, comm=self.comm)
        for (geom, shape, kinematic, velocity, material), body in zip(self._shapes(), scene.bodies):
            self.fb.add_body(geom, shape, position_m=tuple(float(v) for v in body.position_m),
                             velocity_m_s=velocity, kinematic=kinematic, material=material)
        self.fb.start()
        self.units = self.fb.units
        self.grid = Grid.of_forest(self.fb.global_forest, self.comm, self.fb.decomp)
        self.global_forest, self.forest, self.decomp = self.fb.global_forest, self.fb.forest, self.fb.decomp
        self.coupling = self.fb.coupling
        self.solver = None
        self.g_lattice = g_lattice
        self._buoyancy_N = np.zeros((len(scene.bodies), 3))
        self.volume0_cells = self.coupling.water_volume()
        self.cells = int(self.global_forest.cells)
        self.dt_s = self.fb.dt_s

    # -- clock ------------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return int(self.coupling.iteration)

    def step(self, n: int = 1):
        self.fb.step(int(n))        # FloatingBodies exchanges the halo on several ranks

    # -- fields -----------------------------------------------------------------------------------------
    def fields(self) -> dict[str, np.ndarray]:
        """As :class:`FreeSurfaceModel` (rho0, u = 0 and pressure 0 in the gas and the bodies), with phi and
        surface (0 in a column without a crossing of phi = 1/2)."""
        u = self.units
        phi, rho_lat, u_lat = self.fb.fields()
        flags, surface = self.fb.dense_flags(), self.fb.fluid.surface_height()
        if phi is None:         # an MPI rank other than 0
            return None
        liquid = np.isfinite(rho_lat)
        rho_lat = np.where(liquid, rho_lat, 1.0)
        u_lat = np.where(liquid[None], u_lat, 0.0)
        surface = np.nan_to_num(surface, nan=0.0)
        return {"rho": u.density_to_physical(rho_lat),
                "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": np.nan_to_num(flags, nan=FL.SOLID).astype(np.uint8),
                "phi": np.nan_to_num(phi, nan=0.0),
                "surface": np.broadcast_to(u.length_to_physical(surface)[:, :, None], self.shape_cells).copy()}

    @staticmethod
    def field_units(lattice: bool) -> dict[str, str]:
        return FreeSurfaceModel.field_units(lattice)

    def water_level_m(self) -> float:
        """The mean height of phi = 1/2 over the columns no body reaches (all columns where the bodies reach every
        one), m above z = 0; on several ranks on rank 0 (None on the others)."""
        owners = self.fb.dense_owners()
        h = self.fb.fluid.surface_height()
        if h is None:
            return None
        free = (np.nan_to_num(owners, nan=-1) < 0).all(axis=2)
        sel = h[free] if free.any() else h.ravel()
        sel = sel[np.isfinite(sel)]
        return float(sel.mean()) * self.units.dx_m if sel.size else math.nan

    def _water_columns(self) -> dict[str, float]:
        """Mass (kg), kinetic energy (J) and largest speed (m/s and lattice) of the water, its volume outside the
        bodies (m^3), the volume's drift from t = 0 and the water level (m); None on MPI ranks other than 0."""
        u = self.units
        cell_m3 = u.dx_m ** 3
        rho_d, u_d = self.fb.fluid.macroscopic()
        vol, level = self.coupling.water_volume(), self.water_level_m()
        if rho_d is None:       # an MPI rank other than 0: rank 0's columns follow
            return None
        now = np.isfinite(rho_d)
        rho_lat, u_lat = rho_d[now], u_d[:, now]
        out = {"water_volume_m3": float(vol * cell_m3),
               "water_volume_drift": float((vol - self.volume0_cells) / self.volume0_cells), "water_level_m": level}
        speed2 = (u_lat ** 2).sum(axis=0)
        rho_kg = u.density_to_physical(rho_lat)
        umax = float(np.sqrt(speed2.max())) if speed2.size else 0.0
        out.update(mass_kg=float(rho_kg.sum() * cell_m3),
                   kinetic_energy_J=float(0.5 * (rho_kg * u.velocity_to_physical(1.0) ** 2 * speed2).sum()
                                          * cell_m3),
                   max_speed_m_s=float(u.velocity_to_physical(umax)), max_lattice_speed=umax)
        return out

    def diagnostics(self) -> dict[str, float]:
        """One row: the per-body columns and the water's (:meth:`_water_columns`, from rank 0 on several ranks)."""
        self.coupling.check_link_list()
        return {**self.body_columns(), **self.grid.bcast(self._water_columns())}

    def is_finite(self) -> bool:
        bodies = bool(np.isfinite(self.dem.positions).all() and np.isfinite(self.coupling.fluid_force_N).all())
        return bodies and math.isfinite(self.coupling.water_volume())

    #: Every this many probes (the first included) a probe reads the populations (as tier 2).
    full_probe_every = 10

    def watchdog_probe(self) -> dict:
        """Finite bodies, and the water's quantities (:mod:`iceresist.watchdog`); the reference kinetic energy is
        that of the whole fluid moving at the scene's largest speed (at least a tenth of numerics.mach)."""
        if not np.isfinite(self.dem.positions).all():
            return {"finite": (False, None)}
        u_ref = max(float(self.units.velocity_to_lattice(self.scene.largest_speed_m_s())),
                    0.1 * self.scene.numerics.mach)
        full = self._probes % self.full_probe_every == 0
        self._probes += 1
        return self.fb.fluid.probe(full, 0.5 * self.cells * u_ref ** 2)

    # -- checkpoints ------------------------------------------------------------------------------------
    def state(self) -> dict:
        """Everything a bit-for-bit restart needs: the water (population rows, h, phi, flags), the coupling (cell
        owners, the forces of the last step), the DEM with its contact history, and the step count."""
        st = self.fb.state()
        return None if st is None else {"iteration": np.int64(self.iteration), "precision": self.precision,
                                        "dem": self.dem.state(), **st,
                                        "volume0_cells": np.float64(self.volume0_cells)}

    def load_state(self, state: dict):
        if "coupling" not in state or "dem" not in state:
            raise InputError("the checkpoint holds no bodies (no coupling or DEM state): it belongs to another "
                             "scene; run again without --pickup")
        if str(state.get("precision", self.precision)) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        if "fluid" not in state:
            raise InputError("the checkpoint holds no free-surface state: it belongs to another scene")
        self.fb.fluid.load_state(state["fluid"])
        self.volume0_cells = float(state["volume0_cells"])
        self.coupling.load_state(state["coupling"])
        self.dem.load_state(state["dem"])

    # -- identity ---------------------------------------------------------------------------------------
    def describe(self) -> dict:
        u, fs = self.units, self.scene.free_surface
        return {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
                "blocks": int(self.global_forest.nblocks), "operator": self.scene.fluid.operator,
                "precision": self.precision, "backend": self.target.name, "units": u.describe(),
                "unit_system": self.scene.scene.units, "box_m": list(self.box_m),
                "dem_substeps": int(self.dem.substeps_for(self.dt_s)),
                "bodies": self.body_list(),
                "gravity_lattice": self.g_lattice, "water_depth_cells": fs.water_depth_m / u.dx_m,
                "h_lattice": fs.h_lattice, "mobility_lattice": fs.mobility_lattice,
                "interface_width_cells": fs.interface_width_cells, "f_pool": "full", **self.grid.describe()}

    def allocation(self) -> dict[str, int]:
        """Bytes of state per component: the LBM and the phase field, the DEM and the coupling."""
        fl = self.fb.fluid
        return {"dem": array_bytes(self.dem), "coupling": array_bytes(self.coupling),
                "lbm": array_bytes(fl.fluid, fl), "phase_field": array_bytes(fl.phase)}
