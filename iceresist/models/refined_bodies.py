"""Rigid bodies in a fluid on refined levels: a scene with ``[[bodies]]`` and ``[refinement]`` (paper sections 2.3-2.5).

:class:`RefinedBodiesModel` is :class:`~iceresist.models.fluid.FluidModel` with the bodies of
:class:`~iceresist.models.bodies.BodiesModel` on its finest level: the coupling (interpolated bounce-back, momentum
exchange, refill, eqs. 16-21) runs on that level's forest at that level's own time step
(:meth:`~iceresist.lbm.refinement.RefinedLBM.set_stepper`), the DEM advances with it. Every body, with two cells to
spare, must lie inside the finest level's leaves at the start (``refinement.body_band_m`` refines around them); a
scene where one does not is refused naming ``refinement``. With ``refinement.regrid_every_steps`` the band follows
the bodies (block AMR part 2): every N steps the octree is drawn again around each body's bounding sphere where it
is, the populations carried to the new blocks and the coupling's cell owners copied block by block
(:meth:`RefinedBodiesModel.regrid`); the DEM goes on as it was. The fluid alone (no
``[free_surface]``); gravity acts on the bodies (with the buoyancy), the fluid carries the body force alone, as in
:class:`BodiesModel`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from iceresist.backends.launch import copy_into
from iceresist.coupling import FluidStructureCoupling
from iceresist.errors import InputError, StabilityError
from iceresist.grid.regrid import same_blocks
from iceresist.lbm.refinement import RefinedLBM
from iceresist.models.bodies import BodiesModel, body_mesh, check_bodies
from iceresist.models.fluid import FluidModel, forest_faces
from iceresist.models.regions import body_half_extents_m
from iceresist.parallel.levels import LevelShare


class FinestLevelBodies:
    """The bodies of a refined scene on its finest level, shared by :class:`RefinedBodiesModel` and
    :class:`~iceresist.models.refined_surface_bodies.RefinedSurfaceBodiesModel`: their checks, the DEM built at the
    finest level's scales, where they are against that level's leaves, the watchdog's probe and the description.
    Mixed in before the refined model it extends."""

    #: The DEM, wall and shape builders of the uniform-grid bodies model, shared as they are.
    _make_dem = BodiesModel._make_dem
    _add_walls = BodiesModel._add_walls
    _shapes = BodiesModel._shapes
    body_columns = BodiesModel.body_columns
    fluid_force_N = BodiesModel.fluid_force_N
    fluid_torque_N_m = BodiesModel.fluid_torque_N_m

    def _check_bodies(self):
        """The scene's bodies checked against the box (:func:`check_bodies`); names, meshes and reaches kept."""
        scene, u = self.scene, self.units
        if self.regrid_every and scene.refinement.body_band_m is None:
            raise InputError("refinement.body_band_m: a regridding scene with bodies needs the band that follows "
                             "them (e.g. four finest cells)")
        self.box_m = tuple(n * u.dx_m for n in self.shape_cells)
        self.meshes = {i: body_mesh(b, i, scene.source_name) for i, b in enumerate(scene.bodies) if b.shape == "mesh"}
        check_bodies(scene, self.box_m, self.meshes)
        self.dem_backend = "cuda" if self.target.is_cuda else "cpu"
        self.names = [b.name for b in scene.bodies]
        h = body_half_extents_m(scene)
        #: the box the finest level must hold about each body's centre of mass: (n, 2, 3) offsets lo, hi (m)
        self._reach_m = np.stack([-h, h], axis=1)

    def _make_bodies(self, gravity_m_s2):
        """The DEM (gravity ``gravity_m_s2``) with its walls and the scene's bodies at the finest level's scales
        (``units_finest``), once every body is found on that level's leaves with two cells to spare."""
        scene, u, L = self.scene, self.units, self.finest
        self._check_in_finest(np.array([b.position_m for b in scene.bodies], dtype=float), margin_cells=2.0)
        #: the scales of the finest level: cells and time steps 2^L times smaller, tau by acoustic scaling
        self.units_finest = dataclasses.replace(u, dx_m=u.dx_m / 2 ** L, dt_s=u.dt_s / 2 ** L,
                                                tau=float(self.lbm.tau[L]))
        self.dem = self._make_dem(tuple(float(g) for g in gravity_m_s2))
        self._add_walls(self.dem)
        self.geoms = []
        for (geom, shape, kinematic, velocity, material), body in zip(self._shapes(), scene.bodies):
            self.geoms.append(geom)
            self.dem.add_body(shape, position_m=tuple(float(v) for v in body.position_m), velocity_m_s=velocity,
                              kinematic=kinematic, material=material)

    def body_positions_m(self) -> np.ndarray:
        """The bodies' centres of mass now (n, 3), m."""
        return self.dem.positions[:len(self.names)]

    def body_boxes_m(self, positions_m: np.ndarray | None = None) -> np.ndarray | None:
        """The box each body takes (n, 2, 3: lo, hi, m) with its centre of mass at ``positions_m`` (default where
        it is now); None before the DEM is built (the octree of the scene's start)."""
        if positions_m is None:
            if getattr(self, "dem", None) is None:
                return None
            positions_m = self.body_positions_m()
        return np.asarray(positions_m, dtype=float)[:, None, :] + self._reach_m

    def bodies_outside_finest(self, positions_m: np.ndarray, margin_cells: float) -> list[int]:
        """The bodies whose box (:meth:`body_boxes_m` at ``positions_m``), ``margin_cells`` finest cells wider, is
        not wholly on the finest level's leaves (of every rank)."""
        d = getattr(self, "decomp", None)
        view = self.lbm.views[self.finest] if d is None else d.global_views[self.finest]
        dx = self.units.dx_m / 2 ** self.finest
        bm = view.block_map
        out = []
        for i, (blo, bhi) in enumerate(self.body_boxes_m(positions_m) / dx):
            lo = np.maximum(np.floor(blo - margin_cells).astype(np.int64) >> 3, 0)
            hi = np.minimum(np.floor(bhi + margin_cells).astype(np.int64) >> 3, np.array(bm.shape) - 1)
            blocks = bm[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1]
            if ((blocks < 0) | (blocks >= view.nleaves)).any():
                out.append(i)
        return out

    def _check_in_finest(self, positions_m: np.ndarray, margin_cells: float):
        """Refuse a scene whose bodies at ``positions_m`` do not lie on the finest level's leaves."""
        for i in self.bodies_outside_finest(positions_m, margin_cells):
            raise InputError(f"refinement: body {self.names[i]!r} (bodies[{i}]) reaches beyond the finest level "
                             f"(level {self.finest}); refine around it with refinement.body_band_m or a "
                             f"[[refinement.boxes]] box at level {self.finest}")

    # -- regridding -------------------------------------------------------------------------------------
    def regrid(self) -> bool:
        """As :meth:`FluidModel.regrid`, the band of ``refinement.body_band_m`` drawn around the bodies
        where they are. A body that left the finest level since the last regrid (it moved further than the band)
        stops the run with a StabilityError naming the two keys; after the regrid every body lies on the finest
        level with two cells to spare (asserted)."""
        pos = self.body_positions_m()
        gone = self.bodies_outside_finest(pos, margin_cells=1.0)
        if gone:
            i = gone[0]
            raise StabilityError(f"refinement.body_band_m: body {self.names[i]!r} left the finest level between "
                                 f"two regrids (step {self.level0_steps}); widen refinement.body_band_m or regrid more "
                                 f"often (refinement.regrid_every_steps = {max(1, self.regrid_every // 2)})")
        changed = super().regrid()
        if changed and self.bodies_outside_finest(pos, margin_cells=2.0):
            raise RuntimeError("regrid: a body is not on the finest level of the new octree")
        return changed

    def _finest_state(self) -> dict:
        """What the finest level holds besides its populations: its view and the coupling's state (on several ranks
        the whole level's view and the coupling's state gathered on rank 0, None on the others)."""
        share = self.coupling.decomp
        view = self.lbm.views[self.finest] if share is None else share.view
        return {"view": view, "coupling": self.coupling.state()}

    def _carry_finest(self, old: dict):
        """The coupling's cell owners (now and a step earlier) copied block by block from ``old``
        (:meth:`_finest_state` of the level before a regrid) where the two forests share a block; a block new to
        the level has no body in it (the band keeps every body on blocks that stay), so no owner. The rest of the
        coupling's state (boxes, forces, the record's load sum, step count) carries as it is. The cell flags are
        not carried: the new coupling's first refill sets them from the owners on every block a body touches."""
        d = self.decomp
        view = self.lbm.views[self.finest] if d is None else d.global_views[self.finest]
        st, error = None, None
        if old["coupling"] is not None:     # one process, or rank 0 of several: the whole level
            src, dst = same_blocks(old["view"], view)
            st = dict(old["coupling"])
            for key in ("owner", "owner_prev"):
                was = np.asarray(st[key])
                kept = np.zeros(len(was), dtype=bool)
                kept[src] = True
                if (was[~kept] >= 0).any():
                    error = f"regrid: cells a body covers ({key}) lie on finest blocks the new octree drops"
                now = np.full((view.forest.nblocks, was.shape[1]), -1, dtype=was.dtype)
                now[dst] = was[src]
                st[key] = now
        if d is not None:       # every rank takes its rows of the whole level (FluidStructureCoupling.load_state)
            st, error = d.bcast((st, error))
        if error is not None:
            raise RuntimeError(error)
        self.coupling.load_state(st)

    def _bodies_finite(self) -> bool:
        return bool(np.isfinite(self.dem.positions).all() and np.isfinite(self.coupling.fluid_force_N).all())

    def watchdog_probe(self) -> dict:
        """The fluid's probe, and the bodies that left the finest level (count, the first's index)."""
        pos = self.body_positions_m()
        if not np.isfinite(pos).all():
            return {"finite": (False, None)}
        gone = self.bodies_outside_finest(pos, margin_cells=1.0)
        return {**super().watchdog_probe(), "bodies_outside_finest": (len(gone), gone[0] if gone else None)}

    def describe(self) -> dict:
        return {**super().describe(), "box_m": list(self.box_m), "bodies_level": self.finest,
                "dem_substeps": int(self.dem.substeps_for(self.units_finest.dt_s)),
                "bodies": [{"name": b.name, "shape": b.shape, "motion": b.motion} for b in self.scene.bodies]}


class RefinedBodiesModel(FinestLevelBodies, FluidModel):
    """Boxes, spheres and convex meshes, fixed, prescribed or free, in a fluid on refined levels (module docstring)."""

    components = ("fluid", "dem", "coupling", "refinement")

    def _build(self, initialize: bool = True):
        """The levels' solver, and the coupling on its finest level. The first call also builds the DEM and its
        bodies; a later one (a regrid, a pickup onto another octree) keeps them and carries the finest level's
        cell flags and the coupling's state (:meth:`_carry_finest`)."""
        scene, u, fl = self.scene, self.units, self.scene.fluid
        first = getattr(self, "coupling", None) is None
        if first:
            self._prepare()
        old = None if first else self._finest_state()
        d = self.decomp
        self.lbm = RefinedLBM(self.octree, tau0=u.tau, force0=self.force_lattice, faces=forest_faces(scene, u),
                              operator=fl.operator, precision=self.precision, scheme=scene.refinement.scheme,
                              rescale=scene.refinement.scheme == "interpolate", target=self.target,
                              views=None if d is None else d.views)
        if initialize:
            self.lbm.initialize(1.0, tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        finest = self.lbm.levels[-1]
        if not first and finest != self.finest:
            raise RuntimeError(f"regrid: the finest level moved from {self.finest} to {finest}")
        self.finest = finest
        if first:
            self._make_bodies(fl.gravity_m_s2)
            volumes = np.array([g.volume_m3() for g in self.geoms])
            self._buoyancy_N = -u.rho0_kg_m3 * volumes[:, None] * np.asarray(fl.gravity_m_s2, float)[None, :]
        con = scene.contact
        self.coupling = FluidStructureCoupling(self.lbm.solvers[finest], self.dem, self.geoms, self.units_finest,
                                               buoyancy=True, contact_film=True if con is None else con.fluid_film)
        self.lbm.set_stepper(finest, lambda: self.coupling.step(1))
        if d is not None:
            self._split_steps(d)
        if old is not None:
            self._carry_finest(old)

    def _split_steps(self, d):
        """On several ranks: a coarser level steps its own leaves and swaps its halo leaves after each step; the
        finest steps its halo leaves too (the coupling's passes reach at most 6 cells into its one block of halo, as
        on a uniform grid: :class:`~iceresist.models.bodies.BodiesModel`), counts the links of its own leaves into
        the forces (summed over the ranks) and swaps its halo leaves' populations after each step. The cell flags
        need no swap: the replicated bodies mark their cells on the halo leaves alike on every rank."""
        finest, t = self.lbm.solvers[self.finest], self.target
        self.coupling.distribute(LevelShare(d, self.finest))
        for lv, level in self.lbm.solvers.items():
            if lv != self.finest:
                d.step_own(lv, level, t)

        def step():
            self.coupling.step(1)
            d.exchange(self.finest, finest.state, t)

        self.lbm.set_stepper(self.finest, step)

    def _prepare(self):
        """Checks and constants of the first build (a scene with a free surface is
        :class:`~iceresist.models.refined_surface_bodies.RefinedSurfaceBodiesModel`'s)."""
        scene, u, fl = self.scene, self.units, self.scene.fluid
        self._check_bodies()
        # gravity acts on the bodies (DEM, with the buoyancy); the LBM carries the driving force alone
        self.force_lattice = tuple(float(u.force_density_to_lattice(f)) for f in fl.body_force_N_m3)

    # -- values per leaf ---------------------------------------------------------------------------------
    def _leaf(self, lv: int):
        """rho and u of the leaves; the cells a body covers on the finest level at the reference state (rho0,
        u = 0), as :meth:`BodiesModel.fields` writes them."""
        rho, u, xyz = self._own(lv, *self.lbm.leaf_fields(lv))
        if lv == self.finest:
            now = self.coupling.fluid_mask()[:rho.shape[0]]
            rho = np.where(now, rho, 1.0)
            u = np.where(now[None], u, 0.0)
        return rho, u, xyz

    # -- protocol ------------------------------------------------------------------------------------------
    def diagnostics(self) -> dict[str, float]:
        """The per-body columns (:meth:`BodiesModel.body_columns`) and the fluid's over every level."""
        return {**self.body_columns(), **super().diagnostics()}

    def is_finite(self) -> bool:
        return self.grid.all(self._bodies_finite() and math.isfinite(self.lbm.mass()))

    def state(self) -> dict:
        """The levels' populations (:meth:`FluidModel.state`), the finest level's cell flags (the cells the
        bodies cover), the coupling and the DEM: a bit-for-bit restart (on several ranks the whole levels on rank 0,
        None on the others)."""
        finest = self.lbm.solvers[self.finest]
        flags = np.array(self.target.to_host(finest.flags), copy=True)
        levels, coupling = super().state(), self.coupling.state()
        flags = self.grid.gather(self.finest, flags)
        if levels is None:
            return None
        return {**levels, "flags_finest": flags, "coupling": coupling, "dem": self.dem.state()}

    def load_state(self, state: dict):
        if "coupling" not in state or "dem" not in state or "flags_finest" not in state:
            raise InputError("the checkpoint holds no bodies on refined levels: it belongs to another scene; run "
                             "again without --pickup")
        super().load_state(state)
        flags = self.grid.level_rows(self.finest, np.asarray(state["flags_finest"]))
        copy_into(self.lbm.solvers[self.finest].flags, flags.astype(np.uint8))
        self.coupling.load_state(state["coupling"])
        self.dem.load_state(state["dem"])
