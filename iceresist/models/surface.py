"""Water with a free surface under gravity (paper section 2.2): a scene with ``[free_surface]``, on one level or on
the levels of its ``[refinement]`` (section 2.5).

:class:`FreeSurfaceModel` is :class:`~iceresist.models.fluid.FluidModel` with
:class:`~iceresist.freesurface.refined.RefinedFreeSurface` as its solver: the surface in the finest level (on levels
the scene's boxes or ``refinement.surface_band_m`` must put it there; a scene whose coarser levels reach the surface
is refused naming ``refinement.regions``), the coarser levels all water. The water starts still and hydrostatic at
``free_surface.water_depth_m``, over the whole floor or, for a dam break on one level, over x <
``free_surface.column_length_m``; gravity is ``fluid.gravity_m_s2`` (along -z). Fields on the level-0 grid add phi,
flags and the surface height; on levels every level's leaves go to ParaView as for the fluid alone, with phi.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.errors import InputError
from iceresist.freesurface.hlattice import h_lattice
from iceresist.freesurface.probe import COLUMNS as PROBE_COLUMNS
from iceresist.freesurface.reach import SurfaceReach
from iceresist.freesurface.refined import PHI_BULK_TOL, RefinedFreeSurface
from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.lattice import Q
from iceresist.limits import check_fluid
from iceresist.models.fluid import FluidModel
from iceresist.scene.blocks import check_block_shape, forest_faces
from iceresist.scene.checks import check_free_surface_forces

#: Column of each quantity in a row of the probe (:mod:`iceresist.freesurface.probe`).
_ROW = {name: i for i, name in enumerate(PROBE_COLUMNS)}


class FreeSurfaceModel(FluidModel):
    """Water with a free surface on the scene's grid (CPU or CUDA; module docstring); on several MPI ranks (``comm``)
    each takes its share of the levels (:class:`RefinedFreeSurface` with a ``decomp``), the finest level's halo
    blocks swapping their whole state (populations, h, phi, flags) after each step. On one level and one process the
    populations live only in the blocks near the water (``free_surface.f_pool_margin``).
    ``backend`` and ``precision`` override the scene's ``[numerics]``."""

    components = ("fluid", "free_surface")
    #: Whether one level on one process keeps populations only in the blocks near the water
    #: (``free_surface.f_pool_margin``).
    pool_populations = True

    def __init__(self, scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        check_block_shape(scene.shape_cells())        # no padding under a free surface
        super().__init__(scene, backend=backend, precision=precision, comm=comm)

    def _check_limits(self, scene, u):
        """On levels, the fluid's stability limits (:func:`iceresist.limits.check_fluid`); one level runs below the
        lattice limits by construction (:mod:`iceresist.limits`)."""
        if not self.uniform:
            check_fluid(scene, u)

    @property
    def fluid(self):
        """The finest level's :class:`~iceresist.freesurface.fluid.FreeSurfaceFluid` (on one level, the water)."""
        return self.fs.surface

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
        if fs.column_length_m is not None and not self.uniform:
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
        self.fs.initialize(surface=self.initial_surface_cells() if self.uniform else None,
                           u=tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self.volume0_cells = self.water_volume_cells()

    def _levels(self, cls):
        scene, u, fl, fs = self.scene, self.units, self.scene.fluid, self.scene.free_surface
        # pooled populations on one level and one process; on levels, and on several ranks, every block holds them
        pooled = self.pool_populations and self.uniform and self.comm is None and fs.f_pool_margin != "full"
        return cls(self.octree, tau0=u.tau, gravity0=self.gravity0, depth0=self.depth0, mobility=fs.mobility_lattice,
                   width=fs.interface_width_cells, h_lattice=fs.h_lattice, operator=fl.operator,
                   precision=self.precision, target=self.target, faces=forest_faces(scene, u), decomp=self.decomp,
                   f_pool_margin=float(fs.f_pool_margin) if pooled else None, views=self.grid.views)

    def initial_surface_cells(self) -> np.ndarray:
        """Water height z_s(x, y) at t = 0 in level-0 cells, (nx, ny): the depth where there is water, 1.5 interface
        widths below the floor (phi < 1 % at the floor) where the floor is dry (a dam break)."""
        nx, ny, _ = self.shape_cells
        fs = self.scene.free_surface
        zs = np.full((nx, ny), self.depth0)
        if fs.column_length_m is not None:
            x = np.arange(nx) + 0.5
            dry = x >= self.units.length_to_lattice(fs.column_length_m)
            zs[dry, :] = -1.5 * fs.interface_width_cells
        return zs

    def _release_levels(self):
        self.fs = None
        super()._release_levels()

    def _finest_extra(self) -> dict:
        """The finest level's phase field, flags and iteration before a regrid (:meth:`FreeSurfaceFluid.state`
        without the populations, which :meth:`_populations` gives)."""
        return self.fs.surface.state(populations=False)

    def _fill(self, new: dict, old_views, finest: dict, whole=None):
        """The carried populations and, with them, the finest level's phase field and flags
        (:meth:`RefinedFreeSurface.carry_from`; on MPI ranks :meth:`RefinedFreeSurface.carry_split`)."""
        if self.decomp is None:
            self.fs.carry_from(new, finest, old_views[self.finest])
        else:
            self.fs.carry_split(new, whole, finest, old_views[self.finest])

    def _populations(self, lv: int) -> np.ndarray:
        """Level ``lv``'s populations f - w (nblocks, 27, 512) on the host in the storage precision."""
        return self._pool(lv).stored_populations()

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
        reached = np.flatnonzero(self._surface_reach(1.0 - PHI_BULK_TOL))
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

    def _surface_reach(self, bulk: float, owner=None) -> np.ndarray:
        """Whether each of the finest level's leaf blocks (this rank's own on several ranks) holds a cell less
        liquid than ``bulk`` (not covered by a body where ``owner``, the coupling's owners on the target, is given):
        reduced on the target, one byte a block read (:mod:`iceresist.freesurface.reach`)."""
        phi = self.fs.surface.phase.phi
        reach = getattr(self, "_reach", None)
        if reach is None or reach.nblocks != phi.shape[0]:    # built again after a regrid
            self._reach = reach = SurfaceReach(self.target, phi.shape[0], self.fs.surface.real)
        return reach.blocks(self.grid.own_leaves(self.finest), phi, bulk, owner)

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

    # -- one level: the whole domain's cells -------------------------------------------------------------
    def _dense_state(self):
        """Dense rho and u (lattice, NaN outside the liquid), phi and flags of a grid of one level (on several ranks
        gathered on rank 0; None on the others)."""
        fs = self.fluid
        rho, u = self.lbm.solvers[0].macroscopic_blocks()
        flags = np.asarray(fs._host(fs.fluid.flags))
        liquid = (flags & FL.FLUID) != 0
        rho[~liquid] = np.nan
        u[:, ~liquid] = np.nan
        phi = fs.phase.phi_host().astype(np.float64)
        g = self.grid
        parts = [g.gather(0, rho), g.gather(0, np.moveaxis(u, 1, 0)), g.gather(0, phi),
                 g.gather(0, flags.astype(np.float64))]
        if parts[0] is None:
            return None
        parts[1] = np.moveaxis(parts[1], 0, 1)
        fo = g.global_views[0].forest
        return tuple(fo.to_dense(p) for p in parts)

    @staticmethod
    def _liquid(dense):
        """Dense rho, u (lattice) with the reference state (rho0 = 1, u = 0) in the gas, and the liquid mask."""
        rho, u = dense[:2]
        liquid = np.isfinite(rho)
        return np.where(liquid, rho, 1.0), np.where(liquid[None], u, 0.0), liquid

    @staticmethod
    def column_heights(phi) -> np.ndarray:
        """Height of the top-most crossing of phi = 1/2 in each column (nx, ny) of a dense ``phi``, cells above
        z = 0, by linear interpolation; 0 in a dry column, the domain height in a full one."""
        nz = phi.shape[2]
        cross = (phi[:, :, :-1] >= 0.5) & (phi[:, :, 1:] < 0.5)
        k = nz - 2 - np.argmax(cross[:, :, ::-1], axis=2)
        p0 = np.take_along_axis(phi, k[..., None], axis=2)[..., 0]
        p1 = np.take_along_axis(phi, (k + 1)[..., None], axis=2)[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            h = k + 0.5 + (p0 - 0.5) / (p0 - p1)
        h = np.where(cross.any(axis=2), h, 0.0)
        return np.where(phi[:, :, -1] >= 0.5, float(nz), h)

    def _uniform_fields(self) -> dict[str, np.ndarray] | None:
        dense = self._dense_state()
        if dense is None:
            return None
        rho_lat, u_lat, _ = self._liquid(dense)
        u = self.units
        phi, flags = dense[2], dense[3]
        surface = self.column_heights(phi)
        return {"rho": u.density_to_physical(rho_lat),
                "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": flags.astype(np.uint8),
                "phi": phi,
                "surface": np.broadcast_to(u.length_to_physical(surface)[:, :, None], self.shape_cells).copy()}

    def _dense_phi(self):
        """Dense phi (nx, ny, nz) of a grid of one level (on several ranks on rank 0; None on the others)."""
        fs = self.fluid
        phi = self.grid.gather(0, fs.phase.phi_host().astype(np.float64))
        return None if phi is None else self.grid.global_views[0].forest.to_dense(phi)

    def _uniform_diagnostics(self, probe: dict, phi, vol) -> dict[str, float]:
        """The records of one level from the block sums of the full probe (:meth:`FreeSurfaceFluid.probe`: mass,
        kinetic energy and the fastest cell over the liquid, reduced on the target, no dense field of the flow), the
        dense ``phi`` (the surface) and the volume ``vol`` (cells). NaN where the probe found a bad value."""
        u = self.units
        cell_m3 = u.dx_m ** 3
        if "mass" in probe:
            mass, ke, umax_lat = probe["mass"], probe["kinetic_energy"], probe["max_lattice_speed"][0]
        else:
            mass = ke = umax_lat = float("nan")
        surface = self.column_heights(phi)
        return {"water_volume_m3": float(vol * cell_m3),
                "water_volume_drift": float((vol - self.volume0_cells) / self.volume0_cells),
                "mass_kg": float(u.density_to_physical(mass) * cell_m3),
                "kinetic_energy_J": float(u.density_to_physical(ke) * u.velocity_to_physical(1.0) ** 2 * cell_m3),
                "max_speed_m_s": float(u.velocity_to_physical(umax_lat)),
                "max_lattice_speed": float(umax_lat),
                "surface_mean_m": float(u.length_to_physical(surface.mean())),
                "f_rows_in_use": float(self.fluid.fluid.pool.rows_in_use)}

    # -- protocol ------------------------------------------------------------------------------------------
    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s), pressure (Pa, gauge c_s^2 (rho - rho0)), flags, phi (1 water, 0 gas) and surface
        (height of phi = 1/2 above z = 0 in each column, m, on every cell of the column) on the level-0 grid; in the
        gas rho = rho0, u = 0 and pressure = 0, the state eq. (11) assumes there. One level: the cells themselves and
        their flags, the surface 0 in a dry column and the domain height in a full one. Levels: each level-0 cell the
        mean of the leaf cells in it, flags FLUID where phi >= 1/2 and GAS elsewhere, the surface the mean of the
        finest columns."""
        if self.uniform:
            return self._uniform_fields()
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

    @staticmethod
    def field_units(lattice: bool) -> dict[str, str]:
        units = FluidModel.field_units(lattice)
        units.update(phi="1", surface="lattice" if lattice else "m")
        return units

    def level_fields(self, names=None) -> list[dict] | None:
        out = super().level_fields(None)
        if out is None:
            return None
        phis = {lv: self.grid.gather_leaves(lv, self._leaf_extra(lv)[0]) for lv in self.lbm.levels}
        for entry in out:
            entry["fields"]["phi"] = phis[entry["level"]].ravel()
            if names is not None:
                entry["fields"] = {k: v for k, v in entry["fields"].items() if k in names}
        return out

    def water_volume_cells(self) -> float:
        """The water volume in level-0 cells (:meth:`RefinedFreeSurface.volume`); on levels the finest level's
        from the phase field's per-block sums on the target (:meth:`PhaseField.volume_per_block`, as one level's),
        not phi of every cell."""
        if self.uniform:
            return self.fs.volume()
        return self.fs.volume(self.fs.surface.phase.volume_per_block())

    def is_finite(self) -> bool:
        """Whether the water volume and every level's state are finite on every rank: on one level its population
        rows; on levels the probe's rows of every level's leaves (:meth:`RefinedFreeSurface.leaf_rows`: a bad
        density, velocity or phi on a liquid cell, a mass that is not finite), reduced on the target."""
        volume = self.water_volume_cells()      # on several ranks a collective call, taken by every rank
        if self.uniform:
            rows = (self._pool(lv).rows()[1] for lv in self.lbm.levels)
            return self.grid.all(math.isfinite(volume) and all(bool(np.isfinite(f).all()) for f in rows))
        ok = math.isfinite(volume)
        for lv in self.lbm.levels:
            r = self.fs.leaf_rows(lv, self.grid.own_leaves(lv))
            ok = ok and not (r[:, _ROW["n_bad"]].sum() or r[:, _ROW["n_bad_phi"]].sum())
            ok = ok and math.isfinite(float(r[:, _ROW["mass"]].sum()))
        return self.grid.all(ok)

    def _pool(self, lv: int):
        """Level ``lv``'s population rows (:class:`~iceresist.freesurface.pool.PopulationPool`'s owner)."""
        level = self.lbm.solvers[lv]
        return level.fs.fluid if lv == self.finest else level.fluid

    def watchdog_probe(self) -> dict:
        """On one level the finite state alone (:meth:`is_finite`: the free-surface scenes run below the lattice
        limits by construction, :mod:`iceresist.limits`); on levels also the fluid's lattice quantities."""
        if self.uniform:
            return {"finite": (self.is_finite(), None)}
        return super().watchdog_probe()

    def diagnostics(self) -> dict[str, float]:
        """Water volume (m^3, sum phi dx^3: :meth:`RefinedFreeSurface.volume`, the quantity eqs. 4-10 conserve) and
        its drift, liquid mass (kg) and kinetic energy (J) over every level's liquid leaves with their own cell
        volumes, the largest speed (m/s and lattice), the mean surface height (m); one level adds the population rows
        in use, a regridding run the leaf cells. On several ranks the same numbers on every rank. Reduced per block
        on the target (the probe's rows, :meth:`RefinedFreeSurface.leaf_rows`; the liquid of the finest level its
        FLUID cells), so a record reads rows and the surface map, not fields of cells."""
        if self.uniform:
            vol = self.fs.volume()
            probe = self.fluid.probe(True)
            phi = self._dense_phi()
            return self.grid.bcast(None if phi is None else self._uniform_diagnostics(probe, phi, vol))
        u = self.units
        mass = ke = speed2 = 0.0
        for lv in self.lbm.levels:   # the probe's rows of each level's leaves, reduced on the target
            rows = self.fs.leaf_rows(lv, self.grid.own_leaves(lv))
            vol = (u.dx_m / 2 ** lv) ** 3
            if rows[:, _ROW["n_bad"]].sum() or rows[:, _ROW["n_bad_phi"]].sum():
                mass = ke = speed2 = float("nan")       # as on one level: NaN where the probe found a bad value
            mass += float(rows[:, _ROW["mass"]].sum()) * vol
            ke += float(rows[:, _ROW["kinetic_energy"]].sum()) * vol
            liquid = rows[:, _ROW["n_liquid"]] > 0
            if liquid.any():
                speed2 = max(speed2, float(rows[liquid, _ROW["speed2_max"]].max()))
        umax = math.sqrt(speed2) if speed2 == speed2 else speed2
        mass = float(u.density_to_physical(self.grid.sum(mass)))
        ke = float(u.density_to_physical(self.grid.sum(ke)) * u.velocity_to_physical(1.0) ** 2)
        umax = self.grid.max(umax)
        v = self.water_volume_cells()
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
        """Everything a bit-for-bit restart needs, in storage precision: the finest level's free surface
        (:meth:`FreeSurfaceFluid.state`: population rows and their blocks, h, phi, cell flags), every coarser level's
        populations, the iteration, the initial volume and, on levels, the block octree; on several ranks the whole
        domain in global block order on rank 0 (None on the others). One level keeps the surface's keys at the top
        (the layout before levels existed)."""
        coarse = {str(lv): self.lbm.solvers[lv].fluid.rows()[1] for lv in self.lbm.levels[:-1]}
        surface = self.fs.surface.state()
        coarse = {k: self.grid.gather(int(k), f) for k, f in coarse.items()}  # whole levels on rank 0
        if not self.grid.root:
            return None
        if self.uniform:
            return {**surface, "volume0_cells": np.float64(self.volume0_cells),
                    "iteration": np.int64(self.level0_steps), "precision": self.precision}
        return {"f": coarse, "surface": surface, "iteration": np.int64(self.level0_steps),
                "volume0_cells": np.float64(self.volume0_cells), "precision": self.precision,
                "octree_level": self.octree.level.copy(), "octree_coord": self.octree.coord.copy(),
                "regrid_count": np.int64(self.regrid_count)}

    def load_state(self, state: dict):
        self.check_checkpoint(state)
        if self.uniform:
            self.fs.surface.load_state(state)
        else:
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
        if self.uniform:
            pool = self.fluid.fluid.pool
            return {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
                    "blocks": int(self.grid.global_views[0].forest.nblocks), "operator": self.scene.fluid.operator,
                    "precision": self.precision, "backend": self.target.name, "units": self.units.describe(),
                    "gravity_lattice": self.gravity0, "water_depth_cells": self.depth0,
                    "h_lattice": fs.h_lattice, "mobility_lattice": fs.mobility_lattice,
                    "interface_width_cells": fs.interface_width_cells, "f_pool_rows": int(pool.capacity),
                    "f_pool_margin": fs.f_pool_margin, "allocated_bytes": self.fluid.allocated_bytes(),
                    "unit_system": self.scene.scene.units, **self.grid.describe()}
        return {**super().describe(), "water_depth_cells": self.depth0, "gravity_lattice_level0": self.gravity0,
                "h_lattice": fs.h_lattice, "interface_width_cells": fs.interface_width_cells,
                "surface_level": self.finest}

    def allocation(self) -> dict[str, int]:
        """Bytes of the state arrays: on one level the population pool, the phase field (h, phi) and the velocity,
        flag and work arrays (:meth:`FreeSurfaceFluid.allocated_bytes`); on levels each level's blocks."""
        if self.uniform:
            return {k: int(v) for k, v in self.fluid.allocated_bytes().items()}
        return {f"level{lv}": int(n) for lv, n in self.level_bytes.items()}
