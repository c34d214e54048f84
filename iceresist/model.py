"""Models: the state of the components a scene uses and one time step of them; no I/O (DESIGN.md sections 2, 6).

:func:`build_model` builds only what the scene asks for. A fluid-only scene
gets a :class:`FluidModel` (block forest + LBM solver) and nothing else: no
phase-field arrays, no DEM, no coupling state. The model follows the protocol
of :mod:`iceresist.simulation` and speaks physical units to the outside
(``fields()``, ``diagnostics()``, ``time_s``), lattice units inside.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.errors import InputError
from iceresist.scene.schema import Scene
from iceresist.units import Units

log = logging.getLogger(__name__)

#: Scene face name -> block-forest face name.
FOREST_FACE = {"x_min": "x-", "x_max": "x+", "y_min": "y-", "y_max": "y+", "z_min": "z-", "z_max": "z+"}
BLOCK = 8


def resolve_target(backend: str):
    """The compile target of a backend name; a CUDA request without a GPU is an input error."""
    from iceresist.backends import jit

    try:
        return jit.resolve_backend(backend)
    except (RuntimeError, ValueError) as exc:
        raise InputError(f"numerics.backend: {exc}") from None


def forest_faces(scene: Scene, units: Units) -> dict:
    """The scene's faces as block-forest :class:`Face` values in lattice units."""
    from iceresist.grid.forest import Face

    faces = {}
    for name, face in scene.domain.faces.items():
        rho = face.density_kg_m3 if face.density_kg_m3 is not None else scene.rho_kg_m3
        faces[FOREST_FACE[name]] = Face(face.kind, tuple(float(units.velocity_to_lattice(v)) for v in face.velocity_m_s),
                                        float(units.density_to_lattice(rho)))
    return faces


def check_block_shape(shape_cells) -> None:
    """The uniform forest needs whole 8x8x8 blocks: name the key and the nearest valid counts."""
    for axis, n in zip("xyz", shape_cells):
        if n % BLOCK:
            lo, hi = max(BLOCK, n // BLOCK * BLOCK), (n // BLOCK + 1) * BLOCK
            raise InputError(f"domain: {n} cells along {axis} is not a multiple of {BLOCK} (blocks of 8x8x8 cells): "
                             f"use {lo} or {hi} cells (change domain.cells, or domain.size_m / domain.dx_m)")


class FluidModel:
    """The LBM fluid alone: a uniform block forest and an :class:`~iceresist.lbm.solver.LBMSolver`.

    ``backend`` and ``precision`` override the scene's ``[numerics]``.
    """

    components = ("fluid",)

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None):
        self.scene = scene
        self.units = scene.units()
        u = self.units
        self.shape_cells = scene.shape_cells()
        check_block_shape(self.shape_cells)
        from iceresist.grid.forest import BlockForest
        from iceresist.lbm.solver import LBMSolver

        self.backend = backend or scene.numerics.backend
        self.precision = precision or scene.numerics.precision
        self.target = resolve_target(self.backend)
        self.forest = BlockForest.uniform(self.shape_cells, forest_faces(scene, u))
        fl = scene.fluid
        self.force_lattice = tuple(float(u.acceleration_to_lattice(g) + u.force_density_to_lattice(f))
                                   for g, f in zip(fl.gravity_m_s2, fl.body_force_N_m3))
        self.solver = LBMSolver(self.forest, tau=u.tau, force=self.force_lattice, operator=fl.operator,
                                precision=self.precision, target=self.target)
        self.solver.initialize(1.0, tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self.cells = int(self.solver.cells)
        self.dt_s = u.dt_s

    # -- protocol -------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return int(self.solver.iteration)

    @property
    def time_s(self) -> float:
        return self.iteration * self.dt_s

    def step(self, n: int = 1):
        self.solver.step(n)

    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s, [x, y, z, 3]), pressure (Pa, gauge: c_s^2 (rho - rho0)), flags (uint8); NaN in solids."""
        from iceresist.grid import flags as FL

        rho_lat, u_lat = self.solver.macroscopic()
        u = self.units
        flags = self.forest.to_dense(self.forest.flags.astype(np.float64))
        return {"rho": u.density_to_physical(rho_lat),
                "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": np.nan_to_num(flags, nan=FL.SOLID).astype(np.uint8)}

    @staticmethod
    def field_units(lattice: bool) -> dict[str, str]:
        if lattice:
            return {"rho": "lattice", "u": "lattice", "pressure": "lattice", "flags": "bits"}
        return {"rho": "kg/m^3", "u": "m/s", "pressure": "Pa", "flags": "bits"}

    def is_finite(self) -> bool:
        return math.isfinite(self.solver.mass())

    def diagnostics(self) -> dict[str, float]:
        """Fluid mass (kg), kinetic energy (J), largest speed (m/s) and largest lattice speed (u dt/dx)."""
        rho_lat, u_lat = self.solver.macroscopic()
        fluid = np.isfinite(rho_lat)
        speed2 = (u_lat ** 2).sum(axis=0)[fluid]
        u = self.units
        cell_m3 = u.dx_m ** 3
        umax_lat = float(np.sqrt(speed2.max())) if speed2.size else 0.0
        return {"mass_kg": float(u.density_to_physical(rho_lat[fluid]).sum() * cell_m3),
                "kinetic_energy_J": float(0.5 * (u.density_to_physical(rho_lat[fluid])
                                                 * u.velocity_to_physical(1.0) ** 2 * speed2).sum() * cell_m3),
                "max_speed_m_s": float(u.velocity_to_physical(umax_lat)),
                "max_lattice_speed": umax_lat}

    def state(self) -> dict:
        """Populations in storage precision (bit for bit) and the iteration."""
        f = self.solver.populations().astype(self.solver.real)
        return {"f": f, "iteration": np.int64(self.iteration), "precision": self.precision}

    def load_state(self, state: dict):
        f = np.asarray(state["f"])
        if state.get("precision", self.precision) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        expected = (self.forest.nblocks, 27, BLOCK ** 3)
        if f.shape != expected:
            raise InputError(f"checkpoint populations have shape {f.shape}, this scene needs {expected}: "
                             f"it belongs to another scene")
        _set_populations(self.solver, f.astype(self.solver.real))
        self.solver.iteration = int(state["iteration"])

    def describe(self) -> dict:
        return {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
                "blocks": int(self.forest.nblocks), "operator": self.scene.fluid.operator,
                "precision": self.precision, "backend": self.target.name, "units": self.units.describe(),
                "force_lattice": list(self.force_lattice), "bytes_per_cell": int(self.solver.bytes_per_cell),
                "unit_system": self.scene.scene.units}

    def allocated_bytes(self) -> int:
        """Bytes of the state arrays this model holds (populations, both buffers)."""
        return int(self.solver.bytes_per_cell) * int(self.forest.nblocks) * BLOCK ** 3


def _set_populations(solver, f: np.ndarray):
    """Put host populations ``f[block, q, cell]`` into both buffers of the solver."""
    setter = getattr(solver, "set_populations", None)
    if setter is not None:
        setter(f)
        return
    f = np.ascontiguousarray(f)
    for buf in solver._f:
        if hasattr(buf, "copy_to_device"):
            buf.copy_to_device(f)
        else:
            buf[...] = f


def build_model(scene: Scene, *, backend: str | None = None, precision: str | None = None):
    """The model of the components ``scene`` uses: fluid-only scenes, tier-1 and tier-2 ship scenes ([ship] + [ice])."""
    if scene.ship is not None and scene.ice is not None:
        if scene.ship.tier == 2:
            from iceresist.tier2 import Tier2Model

            return Tier2Model(scene, backend=backend, precision=precision)
        from iceresist.tier1 import Tier1Model

        return Tier1Model(scene, backend=backend, precision=precision)
    extra = scene.optional_sections()
    if extra:
        raise InputError(f"{scene.source_name}: sections {', '.join('[' + s + ']' for s in extra)} need the "
                         f"free-surface, DEM and coupling engine, which `iceresist run` does not build yet; "
                         f"remove them to run the fluid alone")
    return FluidModel(scene, backend=backend, precision=precision)
