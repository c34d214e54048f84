"""The fluid model: the LBM alone (:class:`FluidModel`, on one level or on the levels of a ``[refinement]``), and the
checks and set-up the other models share (faces, block shape, padding, the free surface's gravity).

A fluid-only scene gets its blocks and an LBM solver and nothing else: no phase-field arrays, no DEM, no
coupling state; a scene with ``[free_surface]`` alone gets the LBM and the phase field, no DEM, no coupling
(docs/SCENES.md, "Rules": optional sections). Both follow the contract of :class:`iceresist.models.base.Model`.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.backends.jit import resolve_target
from iceresist.errors import InputError
from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.grid.grid import Grid, several
from iceresist.grid.regrid import vorticity_magnitude
from iceresist.lattice import Q
from iceresist.lbm.refinement import RefinedLBM
from iceresist.limits import check_fluid, release_freed_memory
from iceresist.models.base import Model
from iceresist.models.probe import fluid_probe
from iceresist.scene.blocks import (build_octree, check_block_shape, check_level_memory, forest_faces, padding_solid,
                                     scene_octree)
from iceresist.scene.schema import Scene

log = logging.getLogger(__name__)

class FluidModel(Model):
    """The LBM fluid alone on the scene's grid (paper sections 2.1 and 2.5): the level-0 blocks of ``domain.dx_m``
    alone (a uniform grid: one level), or the levels of its ``[refinement]``, stepped by
    :class:`~iceresist.lbm.refinement.RefinedLBM`: one model step is one level-0 step, level l taking 2^l steps in
    it (CPU or CUDA; on CUDA the conservative interface, every level's state and the transfers on the device).

    The octree comes from the scene (:func:`~iceresist.scene.blocks.scene_octree`); its memory is reported before
    it is allocated, and a scene that does not fit the machine is refused. Fields are written on the level-0 grid
    (each level-0 cell the mean of the leaf cells inside it) and, on levels, every level's leaf cells as hexahedra
    for ParaView (``<run>.levels.xdmf``, :mod:`iceresist.io.levels`); diagnostics sum every leaf with its own cell
    volume.

    ``backend`` and ``precision`` override the scene's ``[numerics]``. ``comm``: an MPI communicator of several
    ranks; each rank then steps whole level-0 trees (with one block of every level around them as halo), split along
    the Morton curve in equal cells x sub-steps and split again after every regrid
    (:class:`~iceresist.parallel.levels.LevelDecomposition`); fields, level fields and checkpoints are gathered on
    rank 0 (:attr:`Model.comm`), diagnostics summed over the ranks.
    """

    components = ("fluid",)

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        self.scene = scene
        self.comm = several(comm)
        self.units = u = scene.units()
        #: Whether the grid is the level-0 blocks alone (no ``[refinement]``).
        self.uniform = scene.refinement is None
        if not self.uniform and scene.domain.pad_to_blocks:
            raise InputError("domain.pad_to_blocks: a refined scene needs whole 8x8x8 blocks; give domain cells in "
                             "multiples of 8 and leave pad_to_blocks out")
        self.shape_cells = scene.domain.padded_cells()
        check_block_shape(self.shape_cells)
        self._check_limits(scene, u)
        self.backend = backend or scene.numerics.backend
        self.target = resolve_target(self.backend)
        self.scheme = "conservative" if self.uniform else scene.refinement.scheme
        if self.target.is_cuda and self.scheme != "conservative":
            raise InputError("refinement.scheme: the interpolating level interface runs on the CPU only; use "
                             "scheme = \"conservative\" with backend = \"cuda\"")
        self.precision = precision or scene.numerics.precision
        self.regrid_every = None if self.uniform else scene.refinement.regrid_every_steps
        self.regrid_count = 0
        self.regrids_put_off = 0        #: regrids that changed blocks but waited (refinement.regrid_slack)
        if self.comm is not None and self.scheme != "conservative":
            raise InputError(f"mpirun -n {self.comm.size}: refinement.scheme: the interpolating level interface runs "
                             "on one process; use scheme = \"conservative\" on several ranks")
        if not self.uniform and "refinement" not in self.components:
            self.components = (*self.components, "refinement")
        self.octree = scene_octree(scene, body_boxes_m=self.body_boxes_m())
        self.grid = self._split(self.octree)
        self.decomp, views = self.grid.decomp, self.grid.views
        self.level_bytes = self._level_bytes(views)
        if not self.uniform:
            share = "" if self.decomp is None else " on this rank"
            for lv, nbytes in self.level_bytes.items():
                v = views[lv]
                log.info("refinement level %d: dx %.4g m, %d leaf blocks + %d ghost blocks%s, %.3g MB", lv,
                         u.dx_m / 2 ** lv, v.nleaves, v.nghosts, share, nbytes / 1e6)
            check_level_memory(self.level_bytes)
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
        :class:`~iceresist.parallel.levels.LevelDecomposition` over the ranks, none on one process; the padding of
        ``domain.pad_to_blocks`` solid)."""
        return Grid.levels(octree, forest_faces(self.scene, self.units), self.comm, solid=padding_solid(self.scene))

    def _count_cells(self):
        views = self.grid.global_views          # the fluid cells of every level's leaves
        self.cells_per_level = {lv: int(views[lv].forest.fluid[:views[lv].nleaves].sum()) for lv in self.lbm.levels}
        self.cells = int(sum(self.cells_per_level.values()))

    def _level_bytes(self, views) -> dict[int, int]:
        """Bytes each level's blocks take (leaves and ghosts): both population buffers."""
        itemsize = np.dtype(self.precision).itemsize
        return {v.level: 2 * Q * CELLS * itemsize * v.forest.nblocks for v in views if v is not None}

    def _build(self, initialize: bool = True):
        """The levels' solver (``self.lbm``) on ``self.octree``, initialised from the scene (or left for the caller
        to fill: a regrid, a pickup), what the model adds on them (:meth:`_on_levels`) and, on several ranks, their
        split of the steps (:meth:`_split_steps`)."""
        scene, u, fl = self.scene, self.units, self.scene.fluid
        self.lbm = RefinedLBM(self.octree, tau0=u.tau, force0=self.force_lattice, faces=forest_faces(scene, u),
                              operator=fl.operator, precision=self.precision, scheme=self.scheme,
                              rescale=self.scheme == "interpolate", target=self.target, solid=padding_solid(scene),
                              views=self.grid.views, partial=self.decomp is not None)
        if initialize:
            self.lbm.initialize(1.0, tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self._on_levels()
        if self.decomp is not None:
            self._split_steps(self.decomp)

    def _on_levels(self):
        """What the model sets up on new levels before their steps are split over the ranks (nothing here)."""

    def _split_steps(self, d):
        """On several ranks: every level steps its own leaves and swaps its halo leaves after each step."""
        for lv, s in self.lbm.solvers.items():
            d.step_own(lv, s, self.target)

    # -- regridding ---------------------------------------------------------------------------------------
    def hot_cells(self) -> np.ndarray | None:
        """The level-0 cells a moving criterion marks for the finest level: vorticity |curl u| above
        ``refinement.vorticity_1_s``, from the velocity on the level-0 grid (central differences over level-0
        cells); None without that criterion."""
        if self.uniform or self.scene.refinement.vorticity_1_s is None:
            return None
        _, u_lat, _ = self._level0()
        threshold = self.scene.refinement.vorticity_1_s * self.units.dt_s      # per level-0 step
        return vorticity_magnitude(np.nan_to_num(u_lat)) > threshold

    def body_boxes_m(self) -> np.ndarray | None:
        """The box each body takes now ((n, 2, 3): lo and hi, m), for the band that follows them; None: the
        scene's ``[[bodies]]`` where they start (:func:`~iceresist.scene.blocks.static_regions`)."""
        return None

    @property
    def level0_steps(self) -> int:
        """Level-0 steps taken (a model step is one; the ship's is a record of several)."""
        return int(self.lbm.iteration)

    def regrid(self) -> bool:
        """Build the octree again from the criteria on the current flow and bodies
        (:func:`~iceresist.scene.blocks.build_octree`, :meth:`hot_cells`, :meth:`body_boxes_m`); where it changed,
        carry every level's populations to the new blocks (:func:`iceresist.grid.regrid.carry_over`) and step on
        from there. Returns whether the blocks changed."""
        hot = self.hot_cells()
        need = build_octree(self.scene, hot, self.body_boxes_m())
        ahead = self.body_boxes_ahead_m()
        octree = need if ahead is None else build_octree(self.scene, hot, ahead)
        if self._is_current(octree.level, octree.coord):
            return False
        if self._put_off(need, octree):
            self.regrids_put_off += 1
            return False
        reason = self._rebuild_reason(need, octree, hot)
        grid = self._split(octree)
        level_bytes = self._level_bytes(grid.views)
        refused = None
        try:
            check_level_memory(level_bytes)
        except InputError as err:
            refused = str(err)
        refused = self.grid.first_given(refused)      # every rank keeps the grid if one cannot take the new one
        if refused is not None:
            log.warning("regrid at step %d skipped, the grid stays as it is: %s", self.level0_steps, refused)
            return False
        self._rebuild(octree, level_bytes, grid)
        self.regrid_count += 1
        log.info("regrid %d at step %d (%s): leaf blocks per level %s", self.regrid_count, self.level0_steps,
                 reason, [int(n) for n in octree.blocks_per_level()])
        return True

    def body_boxes_ahead_m(self) -> np.ndarray | None:
        """The boxes the bodies sweep over the next ``refinement.regrid_lookahead_steps`` level-0 steps ((n, 2, 3),
        m), which a rebuild refines; None: the boxes where they are (:meth:`body_boxes_m`)."""
        return None

    def _put_off(self, need, octree) -> bool:
        """Whether a regrid to ``octree`` may wait (``refinement.regrid_slack``): the present leaves cover ``need``
        (the criteria where the bodies are now) at its levels or finer, and their cell updates per level-0 step
        exceed those of ``octree`` (what a rebuild now would give) by at most the slack."""
        slack = self.scene.refinement.regrid_slack
        if not slack or not self.octree.covers(need):
            return False
        return self.octree.updates_per_step() <= (1.0 + slack) * octree.updates_per_step()

    def _rebuild_reason(self, need, octree, hot=None) -> str:
        """Why a regrid rebuilds the levels, for its log line: what the present leaves miss of ``need`` (the
        criteria now; ``hot``: the level-0 cells a moving criterion marks for the finest level, :meth:`hot_cells`),
        or what they cost against ``octree`` (a rebuild now)."""
        if self.octree.covers(need):
            ratio = self.octree.updates_per_step() / max(octree.updates_per_step(), 1)
            return f"the leaves cost {ratio:.2f} x a rebuild's"
        if hot is not None:
            top = self.octree.max_level
            f = 2 ** top
            nb = [int(n) // 8 for n in hot.shape]
            marked = hot.reshape(nb[0], 8, nb[1], 8, nb[2], 8).any(axis=(1, 3, 5))
            finest = (self.octree.level_map().reshape(nb[0], f, nb[1], f, nb[2], f) == top).all(axis=(1, 3, 5))
            missed = np.argwhere(marked & ~finest)
            if len(missed):
                x, y, z = (missed[0] * 8 + 4) * self.units.dx_m
                return (f"the surface or flow criteria mark {len(missed)} level-0 blocks off the finest level, the "
                        f"first about ({x:.3f}, {y:.3f}, {z:.3f}) m")
        return "the criteria reach coarser leaves"

    def _rebuild(self, octree, level_bytes: dict, grid: Grid | None = None):
        """The levels built on ``octree`` and every level's populations carried over from the present ones
        (:func:`iceresist.grid.regrid.carry_over`; onto the same octree, a rebuild changes nothing:
        tests/test_regrid_bodies.py), then :meth:`_fill`. On several ranks (``grid``: the new split, by default
        :meth:`_split` of ``octree``) the old levels are gathered on rank 0, carried over there and the new ones dealt
        out to the ranks."""
        levels, iteration, old_grid = self.lbm.levels, self.level0_steps, self.grid
        old = {lv: self._populations(lv) for lv in levels}
        finest = self._finest_extra()
        grid = self._split(octree) if grid is None else grid
        self._release_levels()
        self._adopt(octree, level_bytes, grid, iteration)
        new, whole = old_grid.carry_to(grid, old, Q)
        del old
        self._fill(new, old_grid.global_views, finest, whole)
        del whole, new, finest, old_grid
        release_freed_memory()      # the old levels, which reference cycles hold (iceresist.limits)

    def _populations(self, lv: int) -> np.ndarray:
        """Level ``lv``'s populations f - w (nblocks, 27, 512) on the host in the storage precision (on the CPU the
        level's own buffer: a regrid carries it without a copy)."""
        return self.lbm.solvers[lv].stored_populations()

    def _finest_extra(self):
        """What a regrid carries besides the populations, taken before the levels are rebuilt (none here)."""
        return None

    def _is_current(self, level, coord) -> bool:
        """Whether the leaves (``level``, ``coord``) are those of the current octree."""
        return np.array_equal(level, self.octree.level) and np.array_equal(coord, self.octree.coord)

    def _release_levels(self):
        """Before a rebuild builds the new levels: drop the present ones (what the rebuild carries is taken by then)
        and collect them, so that two sets of levels never live at once (their solvers hang in reference cycles)."""
        self.lbm = None
        release_freed_memory()

    def _adopt(self, octree, level_bytes: dict, grid: Grid, iteration: int | None = None):
        """New levels' solvers on ``octree`` (their populations to be filled; ``grid``: its levels and their split
        over the ranks), the iteration kept (``iteration``: the level-0 steps, given where the levels are gone)."""
        iteration = self.level0_steps if iteration is None else iteration
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
            s.set_populations(new[lv])
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
        """rho, u and the coordinates of level ``lv``'s leaves cut to this rank's own (:meth:`Grid.own`)."""
        rho, u = self.grid.own(lv, rho, u)
        return rho, u, None if xyz is None else self.grid.own(lv, *xyz)

    def _fluid_cells(self, lv: int, rho) -> np.ndarray:
        """Which of the leaf values ``rho`` of :meth:`_leaf` are fluid (the rest NaN: solid)."""
        return np.isfinite(rho)

    def _leaf_extra(self, lv: int) -> list:
        """Further per-leaf values :meth:`_level0` averages after rho and u (none here)."""
        return []

    def _level0(self, everywhere: bool = True):
        """Density and velocity (lattice units) on the level-0 grid, each cell the mean of the leaf cells in it (NaN
        in a solid cell), and the means of :meth:`_leaf_extra` (a list); on several ranks on every rank, or on rank 0
        alone (None on the others) unless ``everywhere``. On one level the leaves are the level-0 cells: gathered
        and laid out, nothing averaged."""
        leaves = {}
        for lv in self.lbm.levels:
            rho, u, xyz = self._leaf(lv)
            leaves[lv] = ([rho, *u, *self._leaf_extra(lv)], xyz)
        acc = self.grid.level0_means(leaves, tuple(self.shape_cells), everywhere)
        return None if acc is None else (acc[0], acc[1:4], list(acc[4:]))

    def fields(self) -> dict[str, np.ndarray]:
        """rho (kg/m^3), u (m/s, [x, y, z, 3]), pressure (Pa, gauge: c_s^2 (rho - rho0)) and flags (uint8) on the
        level-0 grid; in solid cells (``domain.pad_to_blocks``) rho0, u = 0 and pressure 0, so that the field
        writer's NaN check sees only a blow-up."""
        rows = self._flag_rows() if self.uniform else None
        dense = self._level0(everywhere=False)
        if dense is None:
            return None
        rho_lat, u_lat, _ = dense
        flags = np.full(self.shape_cells, FL.FLUID, dtype=np.uint8)
        if self.uniform:
            fo = self.grid.global_views[0].forest
            flags = np.nan_to_num(fo.to_dense(rows.astype(np.float64)), nan=FL.SOLID).astype(np.uint8)
            solid = ~np.isfinite(rho_lat) & ((flags & FL.FLUID) == 0)
            rho_lat = np.where(solid, 1.0, rho_lat)
            u_lat = np.where(solid[None], 0.0, u_lat)
        u = self.units
        return {"rho": u.density_to_physical(rho_lat), "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0), "flags": flags}

    def _flag_rows(self):
        """The cell flags of a uniform grid's blocks (nblocks, 512) as the fields show them: the forest's."""
        return self.grid.global_views[0].forest.flags

    @staticmethod
    def field_units(lattice: bool) -> dict[str, str]:
        if lattice:
            return {"rho": "lattice", "u": "lattice", "pressure": "lattice", "flags": "bits"}
        return {"rho": "kg/m^3", "u": "m/s", "pressure": "Pa", "flags": "bits"}

    def level_fields(self, names=None) -> list[dict] | None:
        """rho (kg/m^3), u (m/s) and pressure (Pa, gauge) on the leaf cells of every level, each level with its cell
        size and cell indices (:meth:`iceresist.io.hdf5.RunFile.write_level_fields`); ``names`` picks fields. None
        on a uniform grid (its fields are the level-0 fields)."""
        if self.uniform:
            return None
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

    def is_finite(self) -> bool:
        """Whether every level's fluid mass (its populations summed over its fluid cells) is finite on every rank."""
        return self.grid.all(all(math.isfinite(s.mass()) for s in self.lbm.solvers.values()))

    def diagnostics(self) -> dict[str, float]:
        """Fluid mass (kg) and kinetic energy (J) over every leaf with its own cell volume, the largest speed (m/s
        and lattice); on several ranks summed over the ranks' leaves (equal to one process's to round-off)."""
        u = self.units
        mass = ke = 0.0
        umax = 0.0
        for lv in self.lbm.levels:
            rho, vel, _ = self._leaf(lv)
            fluid = self._fluid_cells(lv, rho)
            rho = rho[fluid]
            vol = (u.dx_m / 2 ** lv) ** 3
            speed2 = (vel ** 2).sum(axis=0)[fluid]
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
        """Lattice quantities the run watchdog checks (:mod:`iceresist.watchdog`) on the level-0 grid; the reference
        kinetic energy is that of the whole fluid moving at the scene's largest speed (at least a tenth of
        numerics.mach)."""
        dense = self._level0(everywhere=False)
        probe = None
        if dense is not None:
            rho_lat, u_lat, _ = dense
            u_ref = max(float(self.units.velocity_to_lattice(self.scene.largest_speed_m_s())),
                        0.1 * self.scene.numerics.mach)
            cells = self.cells if self.uniform else rho_lat.size
            probe = fluid_probe(rho_lat, u_lat, np.isfinite(rho_lat), 0.5 * cells * u_ref ** 2)
        return self.grid.bcast(probe)

    def state(self) -> dict:
        """Every level's populations in storage precision (bit for bit, global block order), the iteration and, on
        levels, the block octree (the level and coordinates of every leaf); on several ranks gathered on rank 0
        (None on the others), so a checkpoint restarts on any number of ranks. A uniform grid's populations are
        one array (``f``), as before levels existed."""
        f = {str(lv): self.grid.gather(lv, np.array(s.stored_populations())) for lv, s in self.lbm.solvers.items()}
        if not self.grid.root:
            return None
        if self.uniform:
            return {"f": f["0"], "iteration": np.int64(self.iteration), "precision": self.precision}
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
        if self.uniform:
            return
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
        return self.grid.octree_of_leaves(state["octree_level"], state["octree_coord"])

    def _adopt_checkpoint_octree(self, state: dict):
        """After :meth:`check_checkpoint`: a regridding run picks up on the checkpoint's last grid."""
        if self.uniform:
            return
        if not self._is_current(state["octree_level"], state["octree_coord"]):
            octree = self._octree_of(state)
            grid = self._split(octree)
            self._adopt(octree, self._level_bytes(grid.views), grid)
        self.regrid_count = int(state.get("regrid_count", self.regrid_count))

    def load_state(self, state: dict):
        self.check_checkpoint(state)
        self._adopt_checkpoint_octree(state)
        f = state.get("f", {})
        if self.uniform:
            if isinstance(f, dict):
                raise InputError("the checkpoint holds refined levels: it belongs to a run with [refinement]; run the "
                                 "scene again without --pickup")
            f = {"0": f}
        for lv, s in self.lbm.solvers.items():
            arr = np.asarray(f.get(str(lv), np.zeros(0)))
            nblocks = self.grid.global_views[lv].forest.nblocks
            if arr.shape != (nblocks, Q, CELLS):
                what = "" if self.uniform else f" of level {lv}"
                raise InputError(f"checkpoint populations{what} have shape {arr.shape}, this scene needs "
                                 f"{(nblocks, Q, CELLS)}: it belongs to another scene or refinement")
            s.set_populations(self.grid.level_rows(lv, arr))
            s.iteration = int(state["iteration"]) * 2 ** lv
        self.lbm.iteration = int(state["iteration"])

    def describe(self) -> dict:
        out = {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
               "operator": self.scene.fluid.operator, "precision": self.precision, "backend": self.target.name,
               "units": self.units.describe(), "force_lattice": list(self.force_lattice),
               "unit_system": self.scene.scene.units, **self.grid.describe()}
        if self.uniform:
            return {**out, "blocks": int(self.grid.global_views[0].forest.nblocks),
                    "bytes_per_cell": int(self.lbm.solvers[0].bytes_per_cell)}
        per = self.octree.blocks_per_level()
        return {**out, "levels": len(per) - 1, "leaf_blocks_per_level": [int(n) for n in per],
                "cells_per_level": {str(k): v for k, v in self.cells_per_level.items()},
                "scheme": self.scheme, "regrid_every_steps": self.regrid_every,
                "vorticity_1_s": self.scene.refinement.vorticity_1_s}

    def allocation(self) -> dict[str, int]:
        """Bytes of the populations of every level (leaves and ghost blocks, both buffers; ``lbm`` on a uniform
        grid)."""
        if self.uniform:
            return {"lbm": int(self.level_bytes[0])}
        return {f"lbm_level{lv}": int(n) for lv, n in self.level_bytes.items()}

