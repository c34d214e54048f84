"""The fluid models: the LBM alone (:class:`FluidModel`) and water with a free surface (:class:`FreeSurfaceModel`).

A fluid-only scene gets a block forest and an LBM solver and nothing else: no phase-field arrays, no DEM, no
coupling state; a scene with ``[free_surface]`` alone gets the LBM and the phase field, no DEM, no coupling
(docs/SCENES.md, "Rules": optional sections). Both follow the contract of :class:`iceresist.models.base.Model`.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.backends import jit
from iceresist.errors import InputError
from iceresist.freesurface.fluid import FreeSurfaceFluid
from iceresist.grid import flags as FL
from iceresist.grid.flags import FLUID as FL_FLUID
from iceresist.grid.forest import Face
from iceresist.grid.grid import Grid
from iceresist.lattice import C as _C
from iceresist.lbm.solver import LBMSolver
from iceresist.limits import check_fluid
from iceresist.models.base import Model
from iceresist.models.probe import fluid_probe
from iceresist.scene.schema import Scene
from iceresist.units import Units

log = logging.getLogger(__name__)

#: D3Q27 velocities as float64 (the free surface's per-block fields).
C_F64 = _C.astype(np.float64)

#: Scene face name -> block-forest face name.
FOREST_FACE = {"x_min": "x-", "x_max": "x+", "y_min": "y-", "y_max": "y+", "z_min": "z-", "z_max": "z+"}
BLOCK = 8


def resolve_target(backend: str, key: str = "numerics.backend"):
    """The compile target of a backend name; a CUDA request without a GPU is an input error naming ``key``."""
    try:
        return jit.resolve_backend(backend)
    except (RuntimeError, ValueError) as exc:
        raise InputError(f"{key}: {exc}") from None


def forest_faces(scene: Scene, units: Units) -> dict:
    """The scene's faces as block-forest :class:`Face` values in lattice units."""
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
            use = f"{lo}" if lo == hi else f"{lo} or {hi}"
            raise InputError(f"domain: {n} cells along {axis} is not a multiple of {BLOCK} (blocks of 8x8x8 cells): "
                             f"use {use} cells (change domain.cells, or domain.size_m / domain.dx_m)")


def padding_solid(scene: Scene):
    """``solid(x, y, z)`` of the cells beyond the box that ``domain.pad_to_blocks`` adds (None where there are
    none): the grid is :meth:`~iceresist.scene.schema.Domain.padded_cells`, the box its first
    :meth:`~iceresist.scene.schema.Domain.shape_cells`."""
    n = scene.domain.shape_cells()
    if tuple(scene.domain.padded_cells()) == tuple(n):
        return None

    def outside_box(x, y, z):
        return (x >= n[0]) | (y >= n[1]) | (z >= n[2])

    return outside_box


def check_free_surface_forces(scene: Scene) -> None:
    """A free surface is driven by gravity alone, along -z: name the key otherwise."""
    fl = scene.fluid
    gx, gy, gz = fl.gravity_m_s2
    if gx != 0.0 or gy != 0.0 or not gz < 0.0:
        raise InputError(f"fluid.gravity_m_s2: the free surface needs gravity along -z, e.g. [0, 0, -9.81], "
                         f"not {list(fl.gravity_m_s2)}")
    if any(fl.body_force_N_m3):
        raise InputError("fluid.body_force_N_m3: a free-surface scene is driven by gravity alone; "
                         "leave the body force out")


class FluidModel(Model):
    """The LBM fluid alone: a uniform block forest and an :class:`~iceresist.lbm.solver.LBMSolver`.

    ``backend`` and ``precision`` override the scene's ``[numerics]``. ``comm``: an MPI communicator of several
    ranks; the forest is then split along the Morton curve (:class:`~iceresist.parallel.decomposition
    .Decomposition`), each rank steps its blocks and exchanges its halo after every step, and the fields and the
    checkpoint state are gathered on rank 0 (:attr:`Model.comm`).
    """

    components = ("fluid",)

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        self.scene = scene
        self.units = scene.units()
        u = self.units
        self.shape_cells = scene.domain.padded_cells()
        check_block_shape(self.shape_cells)
        check_fluid(scene, u)
        self.backend = backend or scene.numerics.backend
        self.precision = precision or scene.numerics.precision
        self.target = resolve_target(self.backend)
        self.grid = Grid.uniform(self.shape_cells, forest_faces(scene, u), solid=padding_solid(scene), comm=comm)
        self.global_forest, self.forest = self.grid.global_forest, self.grid.forest
        self.comm, self.decomp = self.grid.comm, self.grid.decomp
        fl = scene.fluid
        self.force_lattice = tuple(float(u.acceleration_to_lattice(g) + u.force_density_to_lattice(f))
                                   for g, f in zip(fl.gravity_m_s2, fl.body_force_N_m3))
        self.solver = LBMSolver(self.forest, tau=u.tau, force=self.force_lattice, operator=fl.operator,
                                precision=self.precision, target=self.target)
        if self.decomp is not None:
            self.solver.active_blocks = self.decomp.nowned
            self.solver.halo = self.decomp.solver_halo(self.target)
        self.solver.initialize(1.0, tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self.cells = int(self.global_forest.cells)
        self.dt_s = u.dt_s

    # -- protocol -------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return int(self.solver.iteration)

    def step(self, n: int = 1):
        self.solver.step(n)

    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s, [x, y, z, 3]), pressure (Pa, gauge: c_s^2 (rho - rho0)), flags (uint8); in solid
        cells (``domain.pad_to_blocks``) rho0, u = 0 and pressure 0, so that the field writer's NaN check sees only
        a blow-up."""
        dense = self._dense_macroscopic()
        if dense is None:
            return None
        rho_lat, u_lat = dense
        fo = self.global_forest
        solid = ~np.isfinite(rho_lat) & np.nan_to_num(fo.to_dense((~fo.fluid).astype(np.float64)),
                                                       nan=1.0).astype(bool)
        rho_lat = np.where(solid, 1.0, rho_lat)
        u_lat = np.where(solid[None], 0.0, u_lat)
        u = self.units
        flags = fo.to_dense(fo.flags.astype(np.float64))
        return {"rho": u.density_to_physical(rho_lat),
                "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": np.nan_to_num(flags, nan=FL.SOLID).astype(np.uint8)}

    @staticmethod
    def field_units(lattice: bool) -> dict[str, str]:
        if lattice:
            return {"rho": "lattice", "u": "lattice", "pressure": "lattice", "flags": "bits"}
        return {"rho": "kg/m^3", "u": "m/s", "pressure": "Pa", "flags": "bits"}

    def _dense_macroscopic(self):
        """Dense rho and u (lattice units, NaN outside the fluid) of the whole domain; on an MPI run gathered on
        rank 0, None on the other ranks."""
        if self.decomp is None:
            return self.solver.macroscopic()
        rho_b, u_b = self.solver.macroscopic_blocks()
        rho_b, u_b = self.grid.gather_rows(rho_b), self.grid.gather_rows(u_b, axis=1)
        if rho_b is None:
            return None
        return self.global_forest.to_dense(rho_b), self.global_forest.to_dense(u_b)

    def is_finite(self) -> bool:
        return self.grid.all(math.isfinite(self.solver.mass()))

    def diagnostics(self) -> dict[str, float]:
        """Fluid mass (kg), kinetic energy (J), largest speed (m/s) and largest lattice speed (u dt/dx); on an MPI
        run summed over the ranks' blocks (equal to one process's to round-off)."""
        rho_b, u_b = self.solver.macroscopic_blocks()
        n = self.solver.active_blocks
        rho_lat, u_lat = rho_b[:n], u_b[:, :n]
        fluid = np.isfinite(rho_lat)
        speed2 = (u_lat ** 2).sum(axis=0)[fluid]
        u = self.units
        cell_m3 = u.dx_m ** 3
        umax_lat = float(np.sqrt(speed2.max())) if speed2.size else 0.0
        mass = float(u.density_to_physical(rho_lat[fluid]).sum() * cell_m3)
        ke = float(0.5 * (u.density_to_physical(rho_lat[fluid]) * u.velocity_to_physical(1.0) ** 2
                          * speed2).sum() * cell_m3)
        mass, ke, umax_lat = self.grid.sum(mass), self.grid.sum(ke), self.grid.max(umax_lat)
        return {"mass_kg": mass, "kinetic_energy_J": ke, "max_speed_m_s": float(u.velocity_to_physical(umax_lat)),
                "max_lattice_speed": umax_lat}

    def watchdog_probe(self) -> dict:
        """Lattice quantities the run watchdog checks (:mod:`iceresist.watchdog`); the reference kinetic energy
        is that of the whole fluid moving at the scene's largest speed (at least a tenth of numerics.mach)."""
        dense = self._dense_macroscopic()
        probe = None
        if dense is not None:
            if getattr(self, "_fluid_dense", None) is None:
                fo = self.global_forest
                self._fluid_dense = np.nan_to_num(fo.to_dense(fo.fluid.astype(np.float64)), nan=0.0) > 0.5
            u_ref = max(float(self.units.velocity_to_lattice(self.scene.largest_speed_m_s())),
                        0.1 * self.scene.numerics.mach)
            probe = fluid_probe(*dense, self._fluid_dense, 0.5 * self.cells * u_ref ** 2)
        return self.grid.bcast(probe)

    def state(self) -> dict | None:
        """Populations in storage precision (bit for bit), in global block order, and the iteration; on an MPI
        run gathered on rank 0 (None on the other ranks), so a checkpoint restarts on any number of ranks."""
        f = self.grid.gather_rows(self.solver.populations().astype(self.solver.real))
        if f is None:
            return None
        return {"f": f, "iteration": np.int64(self.iteration), "precision": self.precision}

    def load_state(self, state: dict):
        f = np.asarray(state["f"])
        if state.get("precision", self.precision) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        expected = (self.global_forest.nblocks, 27, BLOCK ** 3)
        if f.shape != expected:
            raise InputError(f"checkpoint populations have shape {f.shape}, this scene needs {expected}: "
                             f"it belongs to another scene")
        _set_populations(self.solver, self.grid.local_rows(f).astype(self.solver.real))
        self.solver.iteration = int(state["iteration"])

    def describe(self) -> dict:
        out = {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
               "blocks": int(self.global_forest.nblocks), "operator": self.scene.fluid.operator,
               "precision": self.precision, "backend": self.target.name, "units": self.units.describe(),
               "force_lattice": list(self.force_lattice), "bytes_per_cell": int(self.solver.bytes_per_cell),
               "unit_system": self.scene.scene.units, **self.grid.describe()}
        return out

    def allocation(self) -> dict[str, int]:
        """Bytes of the state arrays this model holds: the populations, both buffers."""
        return {"lbm": int(self.solver.bytes_per_cell) * int(self.forest.nblocks) * BLOCK ** 3}


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


class FreeSurfaceModel(Model):
    """Water with a free surface under gravity (paper section 2.2): a uniform block forest and a
    :class:`~iceresist.freesurface.fluid.FreeSurfaceFluid` (cumulant LBM in the liquid, conservative
    Allen-Cahn phase field, populations only in the blocks near the water); no DEM, no coupling.

    The water starts still and hydrostatic at ``free_surface.water_depth_m``, over the whole floor or, for a
    dam break, over x < ``free_surface.column_length_m``; gravity is ``fluid.gravity_m_s2`` (along -z).
    ``backend`` and ``precision`` override the scene's ``[numerics]``.
    """

    components = ("fluid", "free_surface")

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        fs = scene.free_surface
        self.scene = scene
        self.units = u = scene.units()
        self.shape_cells = scene.shape_cells()
        check_block_shape(self.shape_cells)
        fl = scene.fluid
        check_free_surface_forces(scene)
        gz = fl.gravity_m_s2[2]
        nz = self.shape_cells[2]
        self.depth_cells = float(u.length_to_lattice(fs.water_depth_m))
        if not 0.0 < self.depth_cells < nz:
            raise InputError(f"free_surface.water_depth_m: {fs.water_depth_m} m is {self.depth_cells:g} cells, "
                             f"outside the {nz}-cell-high domain")
        self.backend = backend or scene.numerics.backend
        self.precision = precision or scene.numerics.precision
        self.target = resolve_target(self.backend)
        self.grid = Grid.uniform(self.shape_cells, forest_faces(scene, u), comm=comm)
        self.global_forest, self.forest = self.grid.global_forest, self.grid.forest
        self.comm, self.decomp = self.grid.comm, self.grid.decomp
        self.gravity_lattice = float(u.acceleration_to_lattice(-gz))
        margin = None if fs.f_pool_margin == "full" else float(fs.f_pool_margin)
        if self.comm is not None:
            margin = None      # on several ranks every block holds populations (the halo blocks of the water too)
        self.fluid = FreeSurfaceFluid(self.forest, tau=u.tau, gravity_lattice=self.gravity_lattice,
                                      depth_cells=self.depth_cells, mobility=fs.mobility_lattice,
                                      width=fs.interface_width_cells, h_lattice=fs.h_lattice, operator=fl.operator,
                                      precision=self.precision, target=self.target, f_pool_margin=margin)
        self.fluid.decomp = self.decomp
        self.fluid.initialize(surface=self.initial_surface_cells(),
                              u=tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self._exchange()
        self.volume0_cells = self.volume()
        self.cells = int(self.global_forest.cells)
        self.dt_s = u.dt_s

    # -- several ranks ----------------------------------------------------------------------------------
    def _exchange(self):
        """On several ranks: every halo block takes its owner's whole state (populations, h, phi, flags). The step's
        passes reach at most 5 cells into the halo from its outer side (the fused update, the velocity extension's
        layers, the phase field's stream and normal), so the cells next to this rank's blocks stay exact through a
        step (:meth:`Decomposition.exchange` with ``full``)."""
        for arr in self.fluid.halo_state:
            self.grid.exchange(arr, self.target, full=True)

    def volume(self) -> float:
        """Water volume sum phi (cells^3): per-block sums on the target, added up in global block order (the same
        float64 sum on any number of ranks; :meth:`FreeSurfaceFluid.volume`)."""
        return self.fluid.volume()

    def initial_surface_cells(self) -> np.ndarray:
        """Water height z_s(x, y) at t = 0 in cells, (nx, ny): the depth where there is water, 1.5 interface
        widths below the floor (phi < 1 % at the floor) where the floor is dry."""
        nx, ny, _ = self.shape_cells
        fs = self.scene.free_surface
        zs = np.full((nx, ny), self.depth_cells)
        if fs.column_length_m is not None:
            x = np.arange(nx) + 0.5
            dry = x >= self.units.length_to_lattice(fs.column_length_m)
            zs[dry, :] = -1.5 * fs.interface_width_cells
        return zs

    def surface_cells(self, phi=None) -> np.ndarray:
        """Height of the top-most crossing of phi = 1/2 in each column (nx, ny), cells above z = 0, by linear
        interpolation; 0 in a dry column, the domain height in a full one (``phi``: dense, default the fluid's)."""
        phi = self.fluid.phi() if phi is None else phi
        nz = phi.shape[2]
        cross = (phi[:, :, :-1] >= 0.5) & (phi[:, :, 1:] < 0.5)
        k = nz - 2 - np.argmax(cross[:, :, ::-1], axis=2)
        p0 = np.take_along_axis(phi, k[..., None], axis=2)[..., 0]
        p1 = np.take_along_axis(phi, (k + 1)[..., None], axis=2)[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            h = k + 0.5 + (p0 - 0.5) / (p0 - p1)
        h = np.where(cross.any(axis=2), h, 0.0)
        return np.where(phi[:, :, -1] >= 0.5, float(nz), h)

    # -- protocol -------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return int(self.fluid.iteration)

    def step(self, n: int = 1):
        if self.decomp is None:
            self.fluid.step(n)
            return
        for _ in range(int(n)):
            self.fluid.step(1)
            self._exchange()

    def _dense_state(self):
        """Dense rho and u (lattice, NaN outside the liquid), phi and flags of the whole domain (on several ranks
        gathered on rank 0; None on the others)."""
        fs = self.fluid
        f = fs.fluid.populations()
        rho = 1.0 + f.sum(axis=1)
        u = np.einsum("qa,bqc->abc", C_F64, f) / rho
        u[2] += 0.5 * fs.g
        flags = np.asarray(fs._host(fs.fluid.flags))
        liquid = (flags & FL_FLUID) != 0
        rho[~liquid] = np.nan
        u[:, ~liquid] = np.nan
        phi = fs.phase.phi_host().astype(np.float64)
        g = self.grid
        parts = [g.gather_rows(rho), g.gather_rows(u, axis=1), g.gather_rows(phi),
                 g.gather_rows(flags.astype(np.float64))]
        if parts[0] is None:
            return None
        fo = self.global_forest
        return tuple(fo.to_dense(p) for p in parts)

    def _liquid(self, dense=None):
        """Dense rho, u (lattice) with the reference state (rho0 = 1, u = 0) in the gas, and the liquid mask."""
        rho, u = (dense or self._dense_state())[:2]
        liquid = np.isfinite(rho)
        return np.where(liquid, rho, 1.0), np.where(liquid[None], u, 0.0), liquid

    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s, [x, y, z, 3]), pressure (Pa, gauge c_s^2 (rho - rho0)), flags (uint8),
        phi (1 water, 0 gas), surface (height of phi = 1/2 above z = 0 in each column, m, on every cell of
        the column). In the gas rho = rho0, u = 0 and pressure = 0, the state eq. (11) assumes there."""
        dense = self._dense_state()
        if dense is None:
            return None
        rho_lat, u_lat, _ = self._liquid(dense)
        u = self.units
        phi, flags = dense[2], dense[3]
        surface = self.surface_cells(phi)
        return {"rho": u.density_to_physical(rho_lat),
                "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": flags.astype(np.uint8),
                "phi": phi,
                "surface": np.broadcast_to(u.length_to_physical(surface)[:, :, None], self.shape_cells).copy()}

    @staticmethod
    def field_units(lattice: bool) -> dict[str, str]:
        units = FluidModel.field_units(lattice)
        units.update(phi="1", surface="lattice" if lattice else "m")
        return units

    def is_finite(self) -> bool:
        return self.grid.all(math.isfinite(self.fluid.volume()) and bool(np.isfinite(self.fluid.fluid.rows()[1]).all()))

    def watchdog_probe(self) -> dict:
        """Finite state only (:meth:`is_finite`): the free-surface scenes run below the lattice limits by
        construction (:mod:`iceresist.limits`)."""
        return {"finite": (self.is_finite(), None)}

    def diagnostics(self) -> dict[str, float]:
        """Water volume (m^3, sum phi dx^3, the quantity eqs. 4-10 conserve) and its drift from t = 0,
        liquid mass (kg), kinetic energy (J), largest speed (m/s and lattice), mean surface height (m),
        population rows in use; on several ranks from the gathered fields, the same numbers on every rank."""
        vol = self.volume()
        dense = self._dense_state()
        return self.grid.bcast(None if dense is None else self._diagnostics(dense, vol))

    def _diagnostics(self, dense, vol) -> dict[str, float]:
        rho_lat, u_lat, liquid = self._liquid(dense)
        u = self.units
        cell_m3 = u.dx_m ** 3
        speed2 = (u_lat ** 2).sum(axis=0)[liquid]
        rho_kg = u.density_to_physical(rho_lat[liquid])
        umax_lat = float(np.sqrt(speed2.max())) if speed2.size else 0.0
        surface = self.surface_cells(dense[2])
        return {"water_volume_m3": float(vol * cell_m3),
                "water_volume_drift": float((vol - self.volume0_cells) / self.volume0_cells),
                "mass_kg": float(rho_kg.sum() * cell_m3),
                "kinetic_energy_J": float(0.5 * (rho_kg * u.velocity_to_physical(1.0) ** 2 * speed2).sum()
                                          * cell_m3),
                "max_speed_m_s": float(u.velocity_to_physical(umax_lat)),
                "max_lattice_speed": umax_lat,
                "surface_mean_m": float(u.length_to_physical(surface.mean())),
                "f_rows_in_use": float(self.fluid.fluid.pool.rows_in_use)}

    def state(self) -> dict | None:
        """Everything a bit-for-bit restart needs, in storage precision: the population rows and their
        blocks, h, phi, the cell flags, the iteration and the initial water volume. On several ranks the whole
        domain in global block order, every block with its populations, on rank 0 (None on the others)."""
        st = self.fluid.state()
        if st is None:          # an MPI rank other than 0
            return None
        return {**st, "volume0_cells": np.float64(self.volume0_cells),
                "iteration": np.int64(self.iteration), "precision": self.precision}

    def load_state(self, state: dict):
        if state.get("precision", self.precision) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        self.fluid.load_state(state)
        self.volume0_cells = float(state["volume0_cells"])

    def describe(self) -> dict:
        fs = self.scene.free_surface
        pool = self.fluid.fluid.pool
        out = {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
               "blocks": int(self.global_forest.nblocks), "operator": self.scene.fluid.operator,
               "precision": self.precision, "backend": self.target.name, "units": self.units.describe(),
               "gravity_lattice": self.gravity_lattice, "water_depth_cells": self.depth_cells,
               "h_lattice": fs.h_lattice, "mobility_lattice": fs.mobility_lattice,
               "interface_width_cells": fs.interface_width_cells, "f_pool_rows": int(pool.capacity),
               "f_pool_margin": fs.f_pool_margin, "allocated_bytes": self.fluid.allocated_bytes(),
               "unit_system": self.scene.scene.units, **self.grid.describe()}
        return out

    def allocation(self) -> dict[str, int]:
        """Bytes of the state arrays this model holds: the population pool, the phase field (h, phi) and the
        velocity, flag and work arrays (:meth:`FreeSurfaceFluid.allocated_bytes`)."""
        return {k: int(v) for k, v in self.fluid.allocated_bytes().items()}
