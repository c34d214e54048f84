"""The LBM fluid on refined levels: a fluid-only scene with ``[refinement]`` (paper section 2.5).

:class:`RefinedFluidModel` builds the block octree from the scene's boxes (level 0 is the grid of ``domain.dx_m``),
reports the memory its blocks take before it allocates them (and refuses a scene that does not fit the machine),
and steps :class:`~iceresist.lbm.refinement.RefinedLBM`: one model step is one level-0 step, level l taking 2^l
steps in it. Fields are written on the level-0 grid (each level-0 cell the mean of the leaf cells inside it) and, for
ParaView, every level's leaf cells as hexahedra (``<run>.levels.xdmf``, :mod:`iceresist.io.levels`); diagnostics
sum every leaf with its own cell volume. CPU and CUDA (the conservative interface).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.errors import InputError
from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.grid.grid import Grid, several
from iceresist.grid.octree import BlockOctree
from iceresist.grid.regrid import any_in_boxes, carry_over, vorticity_magnitude
from iceresist.lattice import Q
from iceresist.lbm.refinement import RefinedLBM
from iceresist.limits import available_memory_bytes as mem_available, check_fluid, release_freed_memory
from iceresist.models.base import Model
from iceresist.models.bodies import body_mesh, half_extent
from iceresist.models.fluid import FluidModel, _set_populations, check_block_shape, forest_faces, resolve_target
from iceresist.models.probe import fluid_probe
from iceresist.scene.schema import Scene

log = logging.getLogger(__name__)

#: Face kinds that are solid walls (their boundary layers are what ``refinement.wall_band_m`` refines).
WALL_KINDS = ("wall", "moving_wall", "slip")

#: Share of the machine's available memory a refined scene may take.
MEMORY_SHARE = 0.8


def available_memory_bytes() -> int:
    """Memory the machine has available now (bytes): ``MemAvailable`` (:func:`iceresist.limits.available_memory_bytes`:
    free pages and the page cache the OS can drop; free pages alone fall after every checkpoint written); where the
    OS does not say, no limit."""
    free = mem_available()
    return (1 << 62) if free is None else free


def body_half_extents_m(scene: Scene) -> np.ndarray:
    """Half the extent (m) along x, y, z of each of the scene's bodies that the finest level must hold: the
    axis-aligned half size at the start (:func:`iceresist.models.bodies.half_extent`) or, in a regridding scene,
    where bodies turn, the radius of the bounding sphere about the centre of mass along every axis."""
    out = []
    for i, body in enumerate(scene.bodies):
        mesh = body_mesh(body, i, scene.source_name) if body.shape == "mesh" else None
        h = half_extent(body, mesh)
        if scene.refinement.regrid_every_steps is not None and body.shape != "sphere":
            h = np.full(3, float(np.linalg.norm(h)))
        out.append(h)
    return np.array(out, dtype=float).reshape(-1, 3)


def scene_body_boxes_m(scene: Scene) -> np.ndarray:
    """The box (lo, hi; (n, 2, 3) m) each of the scene's ``[[bodies]]`` takes at the start: its position plus and
    minus :func:`body_half_extents_m`."""
    centres = np.array([b.position_m for b in scene.bodies], dtype=float).reshape(-1, 3)
    h = body_half_extents_m(scene)
    return np.stack([centres - h, centres + h], axis=1)


def static_regions(scene: Scene, body_boxes_m: np.ndarray | None = None) -> list:
    """The regions of a scene's ``[refinement]`` as (lo, hi, level) in level-0 cell units: the boxes, the band
    around the still-water level, the bands along the solid faces, and ``refinement.body_band_m`` around each
    body's box in ``body_boxes_m`` ((n, 2, 3): lo and hi, m; default the scene's ``[[bodies]]`` at the start,
    :func:`scene_body_boxes_m`)."""
    ref = scene.refinement
    dx = scene.domain.dx_m or 1.0
    shape = scene.domain.shape_cells()
    boxes = [(np.asarray(b.lo_m) / dx, np.asarray(b.hi_m) / dx, b.level) for b in ref.boxes]
    if ref.surface_band_m is not None:
        depth, band = scene.free_surface.water_depth_m / dx, ref.surface_band_m / dx
        boxes.append((np.array([-np.inf, -np.inf, depth - band]), np.array([np.inf, np.inf, depth + band]),
                      ref.levels))
    if body_boxes_m is None and scene.bodies:
        body_boxes_m = scene_body_boxes_m(scene)
    if ref.body_band_m is not None and body_boxes_m is not None:
        band = ref.body_band_m / dx
        for lo, hi in np.asarray(body_boxes_m, dtype=float).reshape(-1, 2, 3) / dx:
            boxes.append((lo - band, hi + band, ref.levels))
    if ref.wall_band_m is not None:
        band = ref.wall_band_m / dx
        for a, axis in enumerate("xyz"):
            for side, n in (("min", 0.0), ("max", float(shape[a]))):
                if getattr(scene.domain.faces, f"{axis}_{side}").kind not in WALL_KINDS:
                    continue
                lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
                lo[a], hi[a] = (n - band, n + band)
                boxes.append((lo, hi, ref.levels))
    return boxes


def build_octree(scene: Scene, hot: np.ndarray | None = None, body_boxes_m: np.ndarray | None = None):
    """The octree of a scene's ``[refinement]``: level-0 blocks of ``domain.dx_m``; a block takes the highest level
    of the regions its box overlaps (:func:`static_regions`, the bodies in ``body_boxes_m``) and, where ``hot``
    (a bool array on the level-0 cells: the cells a moving criterion marks, e.g. vorticity) holds a True cell in its
    box, the finest level; then 2:1 balance."""
    ref = scene.refinement
    shape = scene.domain.shape_cells()
    periodic = tuple(getattr(scene.domain.faces, f"{a}_min").kind == "periodic" for a in "xyz")
    t = BlockOctree(tuple(n // 8 for n in shape), ref.levels, periodic=periodic)
    boxes = static_regions(scene, body_boxes_m)

    def wanted(lo, hi):
        level = np.zeros(len(lo), dtype=np.int64)
        for blo, bhi, lv in boxes:
            overlap = ((lo < bhi[None, :]) & (hi > blo[None, :])).all(axis=1)
            level = np.where(overlap, np.maximum(level, lv), level)
        if hot is not None:
            level = np.where(any_in_boxes(hot, lo, hi), ref.levels, level)
        return level

    return t.refine(wanted)


class RefinedFluidModel(Model):
    """The LBM fluid alone on the levels of a scene's ``[refinement]`` (CPU or CUDA; on CUDA the conservative
    interface, every level's state and the transfers on the device).

    ``comm``: an MPI communicator of several ranks; each rank then steps whole level-0 trees of the octree (with one
    block of every level around them as halo), split along the Morton curve in equal cells x sub-steps and split
    again after every regrid (:class:`~iceresist.parallel.levels.LevelDecomposition`); fields, level fields and checkpoints are gathered on
    rank 0 (:attr:`Model.comm`), diagnostics summed over the ranks."""

    components = ("fluid", "refinement")

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        self.scene = scene
        self.comm = several(comm)
        self.units = u = scene.units()
        if scene.domain.pad_to_blocks:
            raise InputError("domain.pad_to_blocks: a refined scene needs whole 8x8x8 blocks; give domain cells in "
                             "multiples of 8 and leave pad_to_blocks out")
        self.shape_cells = scene.domain.shape_cells()
        check_block_shape(self.shape_cells)
        self._check_limits(scene, u)
        self.backend = backend or scene.numerics.backend
        self.target = resolve_target(self.backend)
        if self.target.is_cuda and scene.refinement.scheme != "conservative":
            raise InputError("refinement.scheme: the interpolating level interface runs on the CPU only; use "
                             "scheme = \"conservative\" with backend = \"cuda\"")
        self.precision = precision or scene.numerics.precision
        self.regrid_every = scene.refinement.regrid_every_steps
        self.regrid_count = 0
        if self.comm is not None and scene.refinement.scheme != "conservative":
            raise InputError(f"mpirun -n {self.comm.size}: refinement.scheme: the interpolating level interface runs "
                             "on one process; use scheme = \"conservative\" on several ranks")
        self.octree = build_octree(scene, body_boxes_m=self.body_boxes_m())
        self.grid = self._split(self.octree)
        self.decomp, views = self.grid.decomp, self.grid.views
        self.level_bytes = self._level_bytes(views)
        share = "" if self.decomp is None else " on this rank"
        for lv, nbytes in self.level_bytes.items():
            v = views[lv]
            log.info("refinement level %d: dx %.4g m, %d leaf blocks + %d ghost blocks%s, %.3g MB", lv,
                     u.dx_m / 2 ** lv, v.nleaves, v.nghosts, share, nbytes / 1e6)
        self._check_memory(self.level_bytes)
        fl = scene.fluid
        self.force_lattice = tuple(float(u.acceleration_to_lattice(g) + u.force_density_to_lattice(f))
                                   for g, f in zip(fl.gravity_m_s2, fl.body_force_N_m3))
        self._build()
        self._count_cells()
        self.dt_s = u.dt_s

    def _check_limits(self, scene: Scene, u):
        """The fluid's stability limits (:func:`iceresist.limits.check_fluid`)."""
        check_fluid(scene, u)

    def _split(self, octree) -> Grid:
        """The levels of ``octree`` (:class:`~iceresist.grid.grid.Grid`: this process's views of them and their
        :class:`~iceresist.parallel.levels.LevelDecomposition` over the ranks, none on one process)."""
        return Grid.levels(octree, forest_faces(self.scene, self.units), self.comm)

    def _check_memory(self, level_bytes: dict):
        total = sum(level_bytes.values())
        free = available_memory_bytes()
        if total > MEMORY_SHARE * free:
            raise InputError(f"refinement.levels: the blocks need {total / 2**30:.3g} GiB, more than "
                             f"{MEMORY_SHARE:.0%} of the {free / 2**30:.3g} GiB available; use fewer levels or "
                             f"smaller refinement.boxes")

    def _count_cells(self):
        per = self.octree.blocks_per_level()
        self.cells_per_level = {lv: int(per[lv]) * CELLS for lv in self.lbm.levels}
        self.cells = int(sum(self.cells_per_level.values()))

    def _level_bytes(self, views) -> dict[int, int]:
        """Bytes each level's blocks take (leaves and ghosts): both population buffers."""
        itemsize = np.dtype(self.precision).itemsize
        return {v.level: 2 * Q * CELLS * itemsize * v.forest.nblocks for v in views if v is not None}

    def _build(self, initialize: bool = True):
        """The levels' solver (``self.lbm``) on ``self.octree``, initialised from the scene (or left for the caller
        to fill: a regrid, a pickup)."""
        scene, u, fl = self.scene, self.units, self.scene.fluid
        d = self.decomp
        self.lbm = RefinedLBM(self.octree, tau0=u.tau, force0=self.force_lattice, faces=forest_faces(scene, u),
                              operator=fl.operator, precision=self.precision, scheme=scene.refinement.scheme,
                              rescale=scene.refinement.scheme == "interpolate", target=self.target,
                              views=None if d is None else d.views)
        if d is not None:
            for lv, s in self.lbm.solvers.items():
                d.step_own(lv, s, self.target)
        if initialize:
            u0 = tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s)
            self.lbm.initialize(1.0, u0)

    # -- regridding ---------------------------------------------------------------------------------------
    def hot_cells(self) -> np.ndarray | None:
        """The level-0 cells a moving criterion marks for the finest level: vorticity |curl u| above
        ``refinement.vorticity_1_s``, from the velocity on the level-0 grid (central differences over level-0
        cells); None without that criterion."""
        if self.scene.refinement.vorticity_1_s is None:
            return None
        _, u_lat, _ = self._level0()
        threshold = self.scene.refinement.vorticity_1_s * self.units.dt_s      # per level-0 step
        return vorticity_magnitude(np.nan_to_num(u_lat)) > threshold

    def body_boxes_m(self) -> np.ndarray | None:
        """The box each body takes now ((n, 2, 3): lo and hi, m), for the band that follows them; None: the
        scene's ``[[bodies]]`` where they start (:func:`static_regions`)."""
        return None

    @property
    def level0_steps(self) -> int:
        """Level-0 steps taken (a model step is one; the ship's is a record of several)."""
        return int(self.lbm.iteration)

    def regrid(self) -> bool:
        """Build the octree again from the criteria on the current flow and bodies (:func:`build_octree`,
        :meth:`hot_cells`, :meth:`body_boxes_m`); where it changed, carry every level's populations to the new
        blocks (:func:`iceresist.grid.regrid.carry_over`) and step on from there. Returns whether the blocks
        changed."""
        octree = build_octree(self.scene, self.hot_cells(), self.body_boxes_m())
        if self._is_current(octree.level, octree.coord):
            return False
        grid = self._split(octree)
        level_bytes = self._level_bytes(grid.views)
        refused = None
        try:
            self._check_memory(level_bytes)
        except InputError as err:
            refused = str(err)
        refused = self.grid.first_given(refused)      # every rank keeps the grid if one cannot take the new one
        if refused is not None:
            log.warning("regrid at step %d skipped, the grid stays as it is: %s", self.level0_steps, refused)
            return False
        self._rebuild(octree, level_bytes, grid)
        self.regrid_count += 1
        log.info("regrid %d at step %d: leaf blocks per level %s", self.regrid_count, self.level0_steps,
                 [int(n) for n in octree.blocks_per_level()])
        return True

    def _rebuild(self, octree, level_bytes: dict, grid: Grid | None = None):
        """The levels built on ``octree`` and every level's populations carried over from the present ones
        (:func:`iceresist.grid.regrid.carry_over`; onto the same octree, a rebuild changes nothing:
        tests/test_regrid_bodies.py), then :meth:`_fill`. On several ranks (``grid``: the new split, by default
        :meth:`_split` of ``octree``) the old levels are gathered on rank 0, carried over there and the new ones dealt
        out to the ranks."""
        old_views = self.lbm.views
        old = {lv: self._populations(lv) for lv in self.lbm.levels}
        finest = self._finest_extra()
        grid = self._split(octree) if grid is None else grid
        old_decomp, decomp = self.decomp, grid.decomp
        self._adopt(octree, level_bytes, grid)
        whole = None
        if old_decomp is None:
            new = {lv: np.zeros((self.lbm.views[lv].forest.nblocks, Q, CELLS)) for lv in self.lbm.levels}
            carry_over(old_views, old, self.lbm.views, new)
        else:
            old = {lv: old_decomp.gather(lv, f) for lv, f in old.items()}
            if self.comm.rank == 0:
                whole = {lv: np.zeros((decomp.global_views[lv].forest.nblocks, Q, CELLS)) for lv in self.lbm.levels}
                carry_over(old_decomp.global_views, old, decomp.global_views, whole)
            new = {lv: decomp.scatter(lv, None if whole is None else whole[lv]) for lv in self.lbm.levels}
            old_views = old_decomp.global_views
        self._fill(new, old_views, finest, whole)
        del whole
        del old, new, finest, old_views
        release_freed_memory()      # the old levels, which reference cycles hold (iceresist.limits)

    def _populations(self, lv: int) -> np.ndarray:
        """Level ``lv``'s populations f - w (nblocks, 27, 512), host float64."""
        return self.lbm.solvers[lv].populations()

    def _finest_extra(self):
        """What a regrid carries besides the populations, taken before the levels are rebuilt (none here)."""
        return None

    def _is_current(self, level, coord) -> bool:
        """Whether the leaves (``level``, ``coord``) are those of the current octree."""
        return np.array_equal(level, self.octree.level) and np.array_equal(coord, self.octree.coord)

    def _adopt(self, octree, level_bytes: dict, grid: Grid):
        """New levels' solvers on ``octree`` (their populations to be filled; ``grid``: its levels and their split
        over the ranks), the iteration kept."""
        iteration = self.level0_steps
        self.octree = octree
        self.grid, self.decomp = grid, grid.decomp
        self.level_bytes = level_bytes
        self._build(initialize=False)
        self.lbm.iteration = iteration
        self._count_cells()

    def _fill(self, new: dict, old_views, finest, whole=None):
        """The new levels' populations (leaves and ghosts) set from ``new`` (per level, carried over from the levels
        of ``old_views``; ``finest``: :meth:`_finest_extra`, unused here; on MPI ranks ``new`` is this rank's share,
        ``old_views`` the whole levels before and ``whole`` the whole carried levels on rank 0)."""
        for lv, s in self.lbm.solvers.items():
            _set_populations(s, new[lv].astype(s.real))
            s.iteration = self.level0_steps * 2 ** lv

    # -- protocol -------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        return int(self.lbm.iteration)

    def step(self, n: int = 1):
        """``n`` level-0 steps; with ``refinement.regrid_every_steps`` a :meth:`regrid` after every step that is
        a multiple of it."""
        n = int(n)
        if not self.regrid_every:
            self.lbm.step(n)
            return
        while n > 0:
            k = min(n, self.regrid_every - self.level0_steps % self.regrid_every)
            self.lbm.step(k)
            n -= k
            if self.level0_steps % self.regrid_every == 0:
                self.regrid()

    @property
    def lattice_updates_per_step(self) -> int:
        """Cell updates in one level-0 step: level l's cells 2^l times."""
        return int(sum(n * 2 ** lv for lv, n in self.cells_per_level.items()))

    def _leaf(self, lv: int):
        """rho (nleaves, 512), u (3, nleaves, 512) in lattice units and the cell coordinates of level ``lv``'s
        leaves (on several ranks this rank's own); the free surface overrides it (the gas at the reference state)."""
        return self._own(lv, *self.lbm.leaf_fields(lv))

    def _own(self, lv: int, rho, u, xyz=None):
        """rho (nleaves, 512), u (3, nleaves, 512) and the coordinates of level ``lv``'s leaves cut to this rank's
        own leaves (all of them on one process)."""
        if self.decomp is None:
            return rho, u, xyz
        n = self.grid.own_leaves(lv)
        return rho[:n], u[:, :n], None if xyz is None else tuple(c[:n] for c in xyz)

    def _leaf_extra(self, lv: int) -> list:
        """Further per-leaf values :meth:`_level0` averages after rho and u (none here)."""
        return []

    def _level0(self):
        """Density and velocity (lattice units) on the level-0 grid, each cell the mean of the leaf cells in it, and
        the means of :meth:`_leaf_extra` (a list)."""
        shape = tuple(self.shape_cells)
        acc = None
        weight = np.zeros(shape)
        for lv in self.lbm.levels:
            rho, u, (x, y, z) = self._leaf(lv)
            values = (rho, *u, *self._leaf_extra(lv))
            if acc is None:
                acc = np.zeros((len(values), *shape))
            idx = (x.ravel() >> lv, y.ravel() >> lv, z.ravel() >> lv)
            w = 1.0 / 8 ** lv
            np.add.at(weight, idx, w)
            for k, v in enumerate(values):
                np.add.at(acc[k], idx, w * np.asarray(v).ravel())
        self.grid.reduce_arrays(acc, weight)      # every level-0 cell lies in one rank's trees: the others add zeros
        acc /= np.where(weight > 0, weight, np.nan)
        return acc[0], acc[1:4], list(acc[4:])

    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s), pressure (Pa, gauge) and flags on the level-0 grid."""
        rho_lat, u_lat, _ = self._level0()
        if not self.grid.root:
            return None
        u = self.units
        return {"rho": u.density_to_physical(rho_lat), "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                "flags": np.full(self.shape_cells, FL.FLUID, dtype=np.uint8)}

    def level_fields(self, names=None) -> list[dict]:
        """rho (kg/m^3), u (m/s) and pressure (Pa, gauge) on the leaf cells of every level, each level with its cell
        size and cell indices (:meth:`iceresist.io.hdf5.RunFile.write_level_fields`); ``names`` picks fields."""
        u = self.units
        out = []
        for lv in self.lbm.levels:
            rho, vel, (x, y, z) = self._leaf(lv)
            g = self.grid                   # the whole level on rank 0, in the order of one process
            rho, vel = g.gather_leaves(lv, rho), g.gather_leaves(lv, vel, axis=1)
            x, y, z = (g.gather_leaves(lv, c) for c in (x, y, z))
            if rho is None:
                continue
            rho = rho.ravel()
            f = {"rho": u.density_to_physical(rho), "u": u.velocity_to_physical(vel.reshape(3, -1).T),
                 "pressure": u.pressure_to_physical((rho - 1.0) / 3.0)}
            if names is not None:
                f = {k: v for k, v in f.items() if k in names}
            out.append({"level": lv, "dx_m": u.dx_m / 2 ** lv, "fields": f,
                        "cells_ijk": np.stack([x.ravel(), y.ravel(), z.ravel()], axis=-1)})
        return out

    #: The fluid model's fields, so their units too.
    field_units = staticmethod(FluidModel.field_units)

    def is_finite(self) -> bool:
        return self.grid.all(math.isfinite(self.lbm.mass()))

    def diagnostics(self) -> dict[str, float]:
        """Fluid mass (kg) and kinetic energy (J) over every leaf with its own cell volume, the largest speed."""
        u = self.units
        mass = ke = 0.0
        umax = 0.0
        for lv in self.lbm.levels:
            rho, vel, _ = self._leaf(lv)
            vol = (u.dx_m / 2 ** lv) ** 3
            speed2 = (vel ** 2).sum(axis=0)
            mass += float(u.density_to_physical(rho).sum() * vol)
            ke += float(0.5 * (u.density_to_physical(rho) * u.velocity_to_physical(1.0) ** 2 * speed2).sum() * vol)
            umax = max(umax, float(np.sqrt(speed2.max())) if speed2.size else 0.0)
        mass, ke, umax = self.grid.sum(mass), self.grid.sum(ke), self.grid.max(umax)
        out = {"mass_kg": mass, "kinetic_energy_J": ke, "max_speed_m_s": float(u.velocity_to_physical(umax)),
               "max_lattice_speed": umax}
        if self.regrid_every:
            out["leaf_cells"] = float(self.cells)
        return out

    def watchdog_probe(self) -> dict:
        rho_lat, u_lat, _ = self._level0()
        u_ref = max(float(self.units.velocity_to_lattice(self.scene.largest_speed_m_s())),
                    0.1 * self.scene.numerics.mach)
        return fluid_probe(rho_lat, u_lat, np.isfinite(rho_lat), 0.5 * rho_lat.size * u_ref ** 2)

    def state(self) -> dict:
        """Every level's populations in storage precision (bit for bit), the iteration and the block octree
        (the level and coordinates of every leaf)."""
        f = {str(lv): self.grid.gather(lv, s.populations().astype(s.real)) for lv, s in self.lbm.solvers.items()}
        if not self.grid.root:
            return None
        return {"f": f,
                "iteration": np.int64(self.level0_steps), "precision": self.precision,
                "octree_level": self.octree.level.copy(), "octree_coord": self.octree.coord.copy(),
                "regrid_count": np.int64(self.regrid_count)}

    def check_checkpoint(self, state: dict):
        """A checkpoint of another precision or another block octree is refused in one line (a regridding run
        takes the checkpoint's octree if the scene's allows it: same root blocks and at most its levels)."""
        if state.get("precision", self.precision) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        lev, coord = state.get("octree_level"), state.get("octree_coord")
        if lev is None or coord is None:
            raise InputError("the checkpoint holds no block octree: it belongs to a run without [refinement]; run "
                             "the scene again without --pickup")
        if self._is_current(lev, coord):
            return
        if self.regrid_every and self._octree_of(state) is not None:
            return
        raise InputError("the checkpoint's block octree differs from this scene's [refinement] (levels or "
                         "regions changed): run the scene again without --pickup")

    def _octree_of(self, state: dict):
        """The checkpoint's octree on this scene's root blocks, None if its leaves do not tile this domain."""
        lev = np.asarray(state["octree_level"], dtype=np.int64)
        coord = np.asarray(state["octree_coord"], dtype=np.int64)
        t = self.octree
        if lev.ndim != 1 or coord.shape != (len(lev), 3) or len(lev) == 0 or lev.max() > t.max_level:
            return None
        volume = (8.0 ** -lev.astype(float)).sum()
        if abs(volume - float(np.prod(t.root))) > 1e-9 or (coord >= (t.root[None, :] << lev[:, None])).any():
            return None
        return BlockOctree.from_leaves(t.root, t.max_level, t.periodic, lev, coord)

    def _adopt_checkpoint_octree(self, state: dict):
        """After :meth:`check_checkpoint`: a regridding run picks up on the checkpoint's last grid."""
        if not self._is_current(state["octree_level"], state["octree_coord"]):
            octree = self._octree_of(state)
            grid = self._split(octree)
            self._adopt(octree, self._level_bytes(grid.views), grid)
        self.regrid_count = int(state.get("regrid_count", self.regrid_count))

    def load_state(self, state: dict):
        self.check_checkpoint(state)
        self._adopt_checkpoint_octree(state)
        f = state.get("f", {})
        for lv, s in self.lbm.solvers.items():
            arr = np.asarray(f.get(str(lv), np.zeros(0)))
            nblocks = self.grid.global_views[lv].forest.nblocks
            if arr.shape != (nblocks, Q, CELLS):
                raise InputError(f"checkpoint populations of level {lv} have shape {arr.shape}, this scene needs "
                                 f"{(nblocks, Q, CELLS)}: it belongs to another scene or refinement")
            _set_populations(s, self.grid.level_rows(lv, arr).astype(s.real))
            s.iteration = int(state["iteration"]) * 2 ** lv
        self.lbm.iteration = int(state["iteration"])

    def describe(self) -> dict:
        per = self.octree.blocks_per_level()
        return {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
                "levels": len(per) - 1, "leaf_blocks_per_level": [int(n) for n in per],
                "cells_per_level": {str(k): v for k, v in self.cells_per_level.items()},
                "scheme": self.scene.refinement.scheme, "regrid_every_steps": self.regrid_every,
                "vorticity_1_s": self.scene.refinement.vorticity_1_s, "operator": self.scene.fluid.operator,
                "precision": self.precision, "backend": self.target.name, "units": self.units.describe(),
                "force_lattice": list(self.force_lattice), "unit_system": self.scene.scene.units,
                **self.grid.describe()}

    def allocation(self) -> dict[str, int]:
        """Bytes of the populations of every level (leaves and ghost blocks, both buffers)."""
        return {f"lbm_level{lv}": int(n) for lv, n in self.level_bytes.items()}
