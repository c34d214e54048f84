"""Water with a free surface on refined levels: a scene with ``[free_surface]`` and ``[refinement]`` (paper sections
2.2 and 2.5).

:class:`RefinedFreeSurfaceModel` is :class:`~iceresist.models.fluid.FluidModel` with
:class:`~iceresist.freesurface.refined.RefinedFreeSurface` as its solver: the surface in the finest level (the
scene's boxes or ``refinement.surface_band_m`` must put it there; a scene whose coarser levels reach the surface is
refused naming ``refinement.regions``), the coarser levels all water. Fields on the level-0 grid add phi, flags and
the surface height; every level's leaves go to ParaView as for the fluid alone, with phi. The water starts still and
hydrostatic at ``free_surface.water_depth_m``.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.errors import InputError
from iceresist.freesurface.hlattice import h_lattice
from iceresist.freesurface.refined import PHI_BULK_TOL, RefinedFreeSurface
from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.lattice import Q
from iceresist.models.fluid import FluidModel, FreeSurfaceModel, check_free_surface_forces, forest_faces


class RefinedFreeSurfaceModel(FluidModel):
    """Water with a free surface on the levels of a scene's ``[refinement]`` (CPU or CUDA); on several MPI ranks
    (``comm``) each takes its share of the levels (:class:`RefinedFreeSurface` with a ``decomp``)."""

    components = ("fluid", "free_surface", "refinement")


    def _level_bytes(self, views) -> dict[int, int]:
        """Bytes each level's blocks take: both population buffers, and on the finest level the phase field (h in
        two buffers, phi) and the velocity, flags and work arrays of the free surface."""
        item = np.dtype(self.precision).itemsize
        finest = max(v.level for v in views if v is not None)
        qh = h_lattice(self.scene.free_surface.h_lattice).q
        out = {}
        for v in views:
            if v is None:
                continue
            n = v.forest.nblocks
            out[v.level] = 2 * Q * CELLS * item * n
            if v.level == finest:
                out[v.level] += n * CELLS * (item * (2 * qh + 1 + 3) + 3) + n
        return out

    def _build(self, initialize: bool = True):
        """The levels with the surface on the finest (:class:`RefinedFreeSurface`), the water still and
        hydrostatic at ``free_surface.water_depth_m`` (or, ``initialize`` False, left for a regrid or a pickup to
        fill)."""
        scene, u, fl, fs = self.scene, self.units, self.scene.fluid, self.scene.free_surface
        if not initialize:
            finest = self.finest
            self.fs = self._levels(RefinedFreeSurface)
            self.lbm = self.fs.lbm
            if self.fs.finest != finest:
                raise RuntimeError(f"regrid: the finest level moved from {finest} to {self.fs.finest}")
            return
        if fs.column_length_m is not None:
            raise InputError("free_surface.column_length_m: a dam break's dry floor lies outside the finest level; "
                             "run it without [refinement]")
        check_free_surface_forces(scene)
        self.depth0 = float(u.length_to_lattice(fs.water_depth_m))
        nz = self.shape_cells[2]
        if not 0.0 < self.depth0 < nz:
            raise InputError(f"free_surface.water_depth_m: {fs.water_depth_m} m is {self.depth0:g} cells, outside "
                             f"the {nz}-cell-high domain")
        self.gravity0 = float(u.acceleration_to_lattice(-fl.gravity_m_s2[2]))
        self.fs = self._levels(RefinedFreeSurface)
        self.lbm = self.fs.lbm
        self.finest = self.fs.finest
        self.fs.initialize(u=tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self.volume0_cells = self.fs.volume()

    def _levels(self, cls):
        scene, u, fl, fs = self.scene, self.units, self.scene.fluid, self.scene.free_surface
        return cls(self.octree, tau0=u.tau, gravity0=self.gravity0, depth0=self.depth0, mobility=fs.mobility_lattice,
                   width=fs.interface_width_cells, h_lattice=fs.h_lattice, operator=fl.operator,
                   precision=self.precision, target=self.target, faces=forest_faces(scene, u), decomp=self.decomp)

    def _finest_extra(self) -> dict:
        """The finest level's free-surface state before a regrid (:meth:`FreeSurfaceFluid.state`)."""
        return self.fs.surface.state()

    def _fill(self, new: dict, old_views, finest: dict, whole=None):
        """The carried populations and, with them, the finest level's phase field and flags
        (:meth:`RefinedFreeSurface.carry_from`; on MPI ranks :meth:`RefinedFreeSurface.carry_split`)."""
        if self.decomp is None:
            self.fs.carry_from(new, finest, old_views[self.finest])
        else:
            self.fs.carry_split(new, whole, finest, old_views[self.finest])

    def _populations(self, lv: int) -> np.ndarray:
        """Level ``lv``'s populations f - w (nblocks, 27, 512), host float64."""
        level = self.lbm.solvers[lv]
        return (level.fs.fluid if lv == self.finest else level.fluid).populations()

    # -- regridding ---------------------------------------------------------------------------------------
    def hot_cells(self) -> np.ndarray:
        """The level-0 cells of :meth:`FluidModel.hot_cells` and those within one finest block of a finest
        leaf block the surface reaches (a cell with phi below 1 - ``PHI_BULK_TOL``, :meth:`_surface_reach`). The
        static band of ``refinement.surface_band_m`` lies about the still-water level; a wave or a piece of ice
        pushed down can carry the surface beyond it, onto blocks that are finest only because a body's band covered
        them. This keeps those blocks and their neighbours on the finest level when the body moves on, so the
        surface stays a block clear of the level's edge as at the start (:meth:`RefinedFreeSurface.initialize`);
        without it the regrid stops in :func:`carried_surface`."""
        hot = super().hot_cells()
        shape = tuple(int(n) for n in self.shape_cells)
        mark = np.zeros(shape, dtype=np.uint8)
        L_ = self.finest
        reached = np.flatnonzero(self._surface_reach(1.0 - PHI_BULK_TOL).any(axis=1))
        if reached.size:
            edge = max(8 >> L_, 1)                  # a finest block, in level-0 cells
            origin = self.lbm.views[L_].forest.origin[reached] * 8
            lo = np.maximum((origin >> L_) - edge, 0)
            hi = np.minimum(((origin + 8) >> L_) + edge, np.array(shape))
            for (x0, y0, z0), (x1, y1, z1) in zip(lo, hi):
                mark[x0:x1, y0:y1, z0:z1] = 1
        self.grid.reduce_arrays(mark, op="max")
        mark = mark.astype(bool)
        return mark if hot is None else hot | mark

    def _surface_reach(self, bulk: float) -> np.ndarray:
        """The finest level's leaf cells (this rank's own on several ranks) less liquid than ``bulk``."""
        return self._phi_leaves() < bulk

    # -- values per leaf ---------------------------------------------------------------------------------
    def _phi_leaves(self) -> np.ndarray:
        """phi of the finest level's leaves (this rank's own on several ranks)."""
        n = self.grid.own_leaves(self.finest)
        return np.asarray(self.target.to_host(self.fs.surface.phase.phi), dtype=np.float64)[:n]

    def _leaf(self, lv: int):
        """rho and u of the leaves with the gas at the reference state (rho0 = 1, u = 0), as
        :meth:`FreeSurfaceModel.fields` writes it (this rank's own leaves on several ranks)."""
        rho, u, xyz = self._own(lv, *self.lbm.leaf_fields(lv))
        if lv == self.finest:
            gas = self._phi_leaves() < 0.5
            rho = np.where(gas, 1.0, rho)
            u = np.where(gas[None], 0.0, u)
        return rho, u, xyz

    def _leaf_extra(self, lv: int) -> list:
        """phi of the leaves (1 on the coarser levels: all water)."""
        if lv == self.finest:
            return [self._phi_leaves()]
        return [np.ones((self.grid.own_leaves(lv), CELLS))]

    def surface_cells(self, covered_as_water: bool = False) -> np.ndarray:
        """Height of phi = 1/2 over each level-0 column (nx, ny), level-0 cells: the mean of the finest level's
        columns in it (NaN where none has a surface); ``covered_as_water``: a body's cells count as water
        (:meth:`FreeSurfaceFluid.surface_height`); None on MPI ranks other than 0."""
        import warnings

        h = self.fs.surface.surface_height(covered_as_water)
        if h is None:
            return None
        h = h / 2 ** self.finest
        s = 2 ** self.finest
        nx, ny = h.shape[0] // s, h.shape[1] // s
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)     # a column of columns without a surface
            return np.nanmean(h.reshape(nx, s, ny, s), axis=(1, 3))

    # -- protocol ------------------------------------------------------------------------------------------
    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s), pressure (Pa, gauge), flags (FLUID where phi >= 1/2, else GAS), phi and surface (m)
        on the level-0 grid, each cell the mean of the leaf cells in it (:meth:`FreeSurfaceModel.fields`)."""
        rho_lat, u_lat, (phi,) = self._level0()
        surface = self.surface_cells()
        if surface is None:         # an MPI rank other than 0
            return None
        u = self.units
        surface = u.length_to_physical(surface)
        return {"rho": u.density_to_physical(rho_lat), "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": np.where(phi >= 0.5, FL.FLUID, FL.GAS).astype(np.uint8), "phi": phi,
                "surface": np.broadcast_to(surface[:, :, None], self.shape_cells).copy()}

    field_units = staticmethod(FreeSurfaceModel.field_units)

    def level_fields(self, names=None) -> list[dict]:
        out = super().level_fields(None)
        phis = {lv: self.grid.gather_leaves(lv, self._leaf_extra(lv)[0]) for lv in self.lbm.levels}
        for entry in out:
            entry["fields"]["phi"] = phis[entry["level"]].ravel()
            if names is not None:
                entry["fields"] = {k: v for k, v in entry["fields"].items() if k in names}
        return out

    def is_finite(self) -> bool:
        return self.grid.all(math.isfinite(self.fs.volume()) and math.isfinite(self.lbm.mass()))

    def diagnostics(self) -> dict[str, float]:
        """Water volume (m^3, :meth:`RefinedFreeSurface.volume`) and its drift, liquid mass (kg) and kinetic energy
        (J) over every level's liquid leaves with their own cell volumes, the largest speed, the mean surface
        height (m); a regridding run adds the leaf cells."""
        u = self.units
        mass = ke = umax = 0.0
        for lv in self.lbm.levels:
            rho, vel, _ = self._own(lv, *self.lbm.leaf_fields(lv))
            liquid = self._leaf_extra(lv)[0] >= 0.5
            vol = (u.dx_m / 2 ** lv) ** 3
            speed2 = (vel ** 2).sum(axis=0)[liquid]
            rho_kg = u.density_to_physical(rho[liquid])
            mass += float(rho_kg.sum() * vol)
            ke += float(0.5 * (rho_kg * u.velocity_to_physical(1.0) ** 2 * speed2).sum() * vol)
            if speed2.size:
                umax = max(umax, float(np.sqrt(speed2.max())))
        mass, ke, umax = self.grid.sum(mass), self.grid.sum(ke), self.grid.max(umax)
        v = self.fs.volume()
        surface = self.surface_cells()
        surface_mean = self.grid.bcast(None if surface is None else float(np.nanmean(surface)))
        out = {"water_volume_m3": float(v * u.dx_m ** 3),
               "water_volume_drift": float((v - self.volume0_cells) / self.volume0_cells),
               "mass_kg": mass, "kinetic_energy_J": ke, "max_speed_m_s": float(u.velocity_to_physical(umax)),
               "max_lattice_speed": umax,
               "surface_mean_m": float(u.length_to_physical(surface_mean))}
        if self.regrid_every:
            out["leaf_cells"] = float(self.cells)
        return out

    def state(self) -> dict:
        """Every coarser level's populations, the finest level's free surface (populations, h, phi, flags), the
        iteration, the initial volume and the block octree: a bit-for-bit restart."""
        coarse = {str(lv): self.lbm.solvers[lv].fluid.rows()[1] for lv in self.lbm.levels[:-1]}
        surface = self.fs.surface.state()
        coarse = {k: self.grid.gather(int(k), f) for k, f in coarse.items()}  # whole levels on rank 0
        if not self.grid.root:
            return None
        return {"f": coarse, "surface": surface, "iteration": np.int64(self.level0_steps),
                "volume0_cells": np.float64(self.volume0_cells), "precision": self.precision,
                "octree_level": self.octree.level.copy(), "octree_coord": self.octree.coord.copy(),
                "regrid_count": np.int64(self.regrid_count)}

    def load_state(self, state: dict):
        self.check_checkpoint(state)
        if "surface" not in state:
            raise InputError("checkpoint holds no free surface on levels: it belongs to another scene")
        self._adopt_checkpoint_octree(state)
        for lv in self.lbm.levels[:-1]:
            level = self.lbm.solvers[lv]
            f = np.asarray(state["f"].get(str(lv), np.zeros(0)))
            n = level.forest.nblocks
            whole = self.grid.global_views[lv].forest.nblocks
            if f.shape != (whole, Q, CELLS):
                raise InputError(f"checkpoint populations of level {lv} have shape {f.shape}, this scene needs "
                                 f"{(whole, Q, CELLS)}: it belongs to another scene or refinement")
            f = self.grid.level_rows(lv, f)
            level.fluid.set_rows(np.arange(n), f.astype(level.fluid.real), n)
            level.fluid.iteration = int(state["iteration"]) * 2 ** lv
        self.fs.surface.load_state(state["surface"])
        self.lbm.iteration = int(state["iteration"])
        self.volume0_cells = float(state["volume0_cells"])

    def describe(self) -> dict:
        fs = self.scene.free_surface
        return {**super().describe(), "water_depth_cells": self.depth0, "gravity_lattice_level0": self.gravity0,
                "h_lattice": fs.h_lattice, "interface_width_cells": fs.interface_width_cells,
                "surface_level": self.finest}

    def allocation(self) -> dict[str, int]:
        return {f"level{lv}": int(n) for lv, n in self.level_bytes.items()}
