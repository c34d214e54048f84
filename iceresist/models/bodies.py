"""Rigid bodies in a fluid: the model of a scene with ``[[bodies]]`` (boxes, spheres, convex meshes), no ship
(paper sections 2.3-2.5), on any grid.

:class:`BodiesModel` is :class:`~iceresist.models.fluid.FluidModel` (one level without ``[refinement]``, the levels
of one with it) with the bodies on its finest level: the coupling (interpolated bounce-back, momentum exchange,
refill, eqs. 16-21) of :class:`~iceresist.coupling.FluidStructureCoupling` runs on that level's forest at that level's
own time step (:meth:`~iceresist.lbm.refinement.RefinedLBM.set_stepper`), the DEM advances with it. Gravity
(``fluid.gravity_m_s2``) acts on the bodies in the DEM, and the fluid adds the buoyancy -rho_f V g to each (the flow
carries no hydrostatic pressure: in a closed or through-flow box of one fluid the pressure of gravity changes nothing
but the buoyancy); the LBM carries ``fluid.body_force_N_m3`` alone. The set-up of the fixed sphere in a channel and
of the sphere settling in a closed box (:mod:`iceresist.validate.cases.sphere_drag`, ``settling_sphere``).

On levels every body, with two cells to spare, must lie inside the finest level's leaves at the start
(``refinement.body_band_m`` refines around them); a scene where one does not is refused naming ``refinement``. With
``refinement.regrid_every_steps`` the band follows the bodies (block AMR part 2): every N steps the octree is drawn
again around each body's bounding sphere where it is, the populations carried to the new blocks and the coupling's
cell owners copied block by block (:meth:`FinestLevelBodies.regrid`); the DEM goes on as it was. Bodies in water
with a free surface are :class:`~iceresist.models.floating_bodies.FloatingBodiesModel`.

Motion (``bodies[].motion``): ``free`` bodies move under gravity, the fluid force and the DEM contacts (their
``density_kg_m3`` sets mass and inertia); ``fixed`` bodies stay at rest and ``prescribed`` bodies move at
``velocity_m_s``, with ``oscillation`` a harmonic motion on top (both kinematic: they act on the fluid and on free
bodies and are not moved by either). The domain's wall faces (``wall``, ``moving_wall``, ``slip``) are DEM contact
planes; without a ``[contact]`` section the DEM keeps its own contact law (:class:`~iceresist.dem.ContactParameters`,
sub-step 0.05 of the critical step).

Units: a physical scene gives dx (``domain.dx_m``) and dt (``numerics.dt_s`` or the Mach rule of
docs/SCENES.md, "Rules"); a lattice-unit scene has dx = dt = rho0 = 1, and the bodies' sizes, positions, speeds and
densities are read in lattice units too.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from iceresist.backends.launch import copy_into
from iceresist.coupling import Box, ConvexPolyhedron, FluidStructureCoupling, Sphere
from iceresist.dem import ContactParameters, DEMSystem, box, convex_polyhedron, sphere
from iceresist.errors import InputError, StabilityError
from iceresist.grid.regrid import same_blocks
from iceresist.models.base import array_bytes
from iceresist.models.fluid import FluidModel
from iceresist.parallel.levels import LevelShare
from iceresist.scene.blocks import body_half_extents_m, body_mesh
from iceresist.scene.checks import check_bodies

#: Face kinds that are walls for the bodies (DEM contact planes).
WALL_KINDS = ("wall", "moving_wall", "slip")
#: Per-body time-series columns, each prefixed ``<name>_``.
BODY_COLUMNS = ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "Fx_N", "Fy_N", "Fz_N", "Tx_N_m", "Ty_N_m",
                "Tz_N_m")


class BodyShapes:
    """What every model of ``[[bodies]]`` builds from the scene alike: the DEM with the scene's contact law, the
    domain's walls as contact planes, each body's geometry and DEM shape, the per-body time-series columns and the
    fluid's force and torque on them. Mixed in before the model it extends (which sets ``scene``, ``box_m``,
    ``meshes``, ``names``, ``dem_backend``, ``coupling`` and ``_buoyancy_N``)."""

    def _make_dem(self, gravity_m_s2):
        con = self.scene.contact
        if con is None:
            return DEMSystem(backend=self.dem_backend, gravity_m_s2=tuple(gravity_m_s2))
        kt = con.tangential_stiffness_ratio * con.stiffness_N_m
        return DEMSystem(backend=self.dem_backend, precision="float64", gravity_m_s2=tuple(gravity_m_s2),
                         ice_ice=ContactParameters(con.stiffness_N_m, kt, con.restitution, con.friction_ice_ice),
                         ice_ship=ContactParameters(con.stiffness_N_m, kt, con.restitution, con.friction_ice_hull),
                         safety=con.dem_safety, dashpot=con.dashpot)

    def _add_walls(self, dem):
        """The domain's wall faces as DEM planes, normals into the box."""
        L = self.box_m
        for name, face in self.scene.domain.faces.items():
            if face.kind not in WALL_KINDS:
                continue
            a = "xyz".index(name[0])
            point, normal = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
            if name.endswith("_max"):
                point[a], normal[a] = L[a], -1.0
            else:
                normal[a] = 1.0
            dem.add_wall(tuple(point), tuple(normal))

    def _shapes(self):
        """(coupling geometry, DEM shape, kinematic, velocity, material) of each body."""
        out = []
        for i, b in enumerate(self.scene.bodies):
            rho = b.density_kg_m3 if b.density_kg_m3 is not None else self.scene.rho_kg_m3
            if b.shape == "sphere":
                geom, shape = Sphere(float(b.radius_m)), sphere(float(b.radius_m), rho)
            elif b.shape == "mesh":
                v, _, fill = self.meshes[i]
                if fill < 1.0 - 1e-6:
                    raise InputError(f"bodies[{i}].mesh_file: body {b.name!r} fills {100 * fill:.1f} % of its convex "
                                     f"hull; the fluid sees a body as a convex polyhedron for now: give a convex mesh")
                spacing = b.sphere_spacing_m or 0.25 * float(np.ptp(v, axis=0).min())
                shape = convex_polyhedron(v, rho, spacing, name=b.name)
                geom = ConvexPolyhedron.of_shape(v, shape)
            else:
                size = tuple(float(v) for v in b.size_m)
                geom, shape = Box(size), box(size, rho)
            kinematic = b.motion != "free"
            velocity = (0.0, 0.0, 0.0) if b.motion == "fixed" else tuple(float(v) for v in b.velocity_m_s)
            out.append((geom, shape, kinematic, velocity, "ice" if b.motion == "free" else "structure"))
        return out

    @property
    def fluid_force_N(self) -> np.ndarray:
        """Force of the fluid on each body (n, 3), N, the mean of the last two steps (eq. 20), the buoyancy
        included (in a scene without a free surface the -rho_f V g the coupling adds)."""
        return self.coupling.fluid_force_N + self._buoyancy_N

    @property
    def fluid_torque_N_m(self) -> np.ndarray:
        """Torque of the fluid on each body (n, 3), N m, about its centre of mass (eq. 21)."""
        return self.coupling.fluid_torque_N_m

    def body_list(self) -> list[dict]:
        """Name, shape, motion and mass (kg) of each body, for :meth:`describe`."""
        return [{"name": b.name, "shape": b.shape, "motion": b.motion,
                 "mass_kg": float(s.mass_kg) if hasattr(s, "mass_kg") else None}
                for b, (_, s, *_) in zip(self.scene.bodies, self._shapes())]

    def body_columns(self) -> dict[str, float]:
        """The per-body time-series columns (:data:`BODY_COLUMNS`)."""
        pos, vel = self.dem.positions, self.dem.velocities
        force, torque = self.fluid_force_N, self.fluid_torque_N_m
        out = {}
        for k, name in enumerate(self.names):
            values = (*pos[k], *vel[k], *force[k], *torque[k])
            out.update({f"{name}_{col}": float(v) for col, v in zip(BODY_COLUMNS, values)})
        return out


class FinestLevelBodies(BodyShapes):
    """The bodies of a scene on its finest level (level 0 of a grid without ``[refinement]``), shared by
    :class:`BodiesModel` and :class:`~iceresist.models.floating_bodies.FloatingBodiesModel`: their
    checks, the DEM built at the finest level's scales, where they are against that level's leaves, the watchdog's
    probe and the description. Mixed in before the model it extends."""

    def _check_bodies(self):
        """The scene's bodies checked against the box (:func:`check_bodies`); names, meshes and reaches kept."""
        scene, u = self.scene, self.units
        if self.regrid_every and scene.refinement.body_band_m is None:
            raise InputError("refinement.body_band_m: a regridding scene with bodies needs the band that follows "
                             "them (e.g. four finest cells)")
        self.box_m = tuple(n * u.dx_m for n in scene.domain.shape_cells())   # the walls: padding left out
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
        scene = self.scene
        self._check_in_finest(np.array([b.position_m for b in scene.bodies], dtype=float), margin_cells=2.0)
        self._set_finest_units()
        self.dem = self._make_dem(tuple(float(g) for g in gravity_m_s2))
        self._add_walls(self.dem)
        self.geoms = []
        for (geom, shape, kinematic, velocity, material), body in zip(self._shapes(), scene.bodies):
            self.geoms.append(geom)
            self.dem.add_body(shape, position_m=tuple(float(v) for v in body.position_m), velocity_m_s=velocity,
                              kinematic=kinematic, material=material)

    def _set_finest_units(self):
        """``units_finest``: the scales of the finest level, cells and time steps 2^L times smaller, tau by acoustic
        scaling (the bodies and their coupling step there)."""
        u, L = self.units, self.finest
        self.units_finest = dataclasses.replace(u, dx_m=u.dx_m / 2 ** L, dt_s=u.dt_s / 2 ** L,
                                                tau=float(self.lbm.tau[L]))

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

    def body_boxes_ahead_m(self) -> np.ndarray | None:
        """Each body's box swept from where it is to where its present velocity takes it in
        ``refinement.regrid_lookahead_steps`` level-0 steps ((n, 2, 3), m); None without a look-ahead."""
        steps = self.scene.refinement.regrid_lookahead_steps
        if not steps or getattr(self, "dem", None) is None:
            return None
        now = self.body_positions_m()
        later = now + self.dem.velocities[:len(now)] * steps * self.units.dt_s
        return np.stack([np.minimum(now, later) + self._reach_m[:, 0], np.maximum(now, later) + self._reach_m[:, 1]],
                        axis=1)

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

    def _rebuild_reason(self, need, octree, hot=None) -> str:
        """As :meth:`FluidModel._rebuild_reason`, first naming the bodies whose band (``refinement.body_band_m``
        about their box) reaches beyond the finest level's leaves, the first with its centre (m)."""
        band = self.scene.refinement.body_band_m
        pos = self.body_positions_m()
        out = [] if band is None or self.octree.covers(need) else \
            self.bodies_outside_finest(pos, margin_cells=band / (self.units.dx_m / 2 ** self.finest))
        if not out:
            return super()._rebuild_reason(need, octree, hot)
        x, y, z = pos[out[0]]
        return (f"{len(out)} bodies' band beyond the finest leaves, {self.names[out[0]]!r} at "
                f"({x:.3f}, {y:.3f}, {z:.3f}) m")

    def _release_levels(self):
        """Take what the new finest level carries (:meth:`_finest_state`), then drop the coupling with the levels."""
        self._carried_finest = self._finest_state()
        self.coupling = None
        super()._release_levels()

    def _carried_or_finest_state(self) -> dict:
        """What :meth:`_release_levels` took before a rebuild, else (a pickup onto another octree) the levels' now."""
        carried = self.__dict__.pop("_carried_finest", None)
        return self._finest_state() if carried is None else carried

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

    def _couple(self):
        """The coupled step of the finest level (:meth:`FluidStructureCoupling.step`), the oscillating bodies'
        velocities set for it first (:meth:`_drive_oscillations`)."""
        self._drive_oscillations()
        self.coupling.step(1)

    def _drive_oscillations(self):
        """Each prescribed body with ``oscillation`` moves over the coming step at its prescribed velocity at the
        step's middle (``velocity_m_s`` plus :meth:`~iceresist.scene.schema.Oscillation.velocity_m_s`): its centre
        follows the prescribed path to second order in the step."""
        t_s = self.dem.time_s + 0.5 * self.units_finest.dt_s
        for i, b in enumerate(self.scene.bodies):
            if b.oscillation is not None:
                self.dem.set_prescribed_velocity(i, np.add(b.velocity_m_s, b.oscillation.velocity_m_s(t_s)))

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
                "bodies": self.body_list()}

    def allocation(self) -> dict[str, int]:
        """Bytes of state per component: the fluid's (:meth:`FluidModel.allocation`), the DEM and the coupling."""
        return {**super().allocation(), "dem": array_bytes(self.dem), "coupling": array_bytes(self.coupling)}


class BodiesModel(FinestLevelBodies, FluidModel):
    """Boxes, spheres and convex meshes, fixed, prescribed or free, in a fluid on any grid (module docstring).
    ``backend`` and ``precision`` override the scene's ``[numerics]``; ``comm``: several MPI ranks.

    Time series (:meth:`diagnostics`): per body ``<name>_x_m`` ... ``_z_m`` (centre of mass), ``_vx_m_s`` ...,
    the fluid force ``_Fx_N`` ... (eq. 20, with the buoyancy) and torque ``_Tx_N_m`` ... (eq. 21) about the
    centre of mass; and the fluid's own columns over the cells that are fluid now.
    """

    components = ("fluid", "dem", "coupling")

    def _build(self, initialize: bool = True):
        """The levels' solver with the coupling on its finest level (:meth:`_on_levels`). The first call also builds
        the DEM and its bodies; a later one (a regrid, a pickup onto another octree) keeps them and carries the finest
        level's cell flags and the coupling's state (:meth:`_carry_finest`)."""
        first = getattr(self, "dem", None) is None
        if first:
            self._prepare()
        old = None if first else self._carried_or_finest_state()
        super()._build(initialize)
        if old is not None:
            self._carry_finest(old)

    def _on_levels(self):
        """The coupling on the finest level, stepping it; on the first build the DEM and the bodies too."""
        u, fl, finest = self.units, self.scene.fluid, self.lbm.levels[-1]
        first = getattr(self, "dem", None) is None
        if not first and finest != self.finest:
            raise RuntimeError(f"regrid: the finest level moved from {self.finest} to {finest}")
        self.finest = finest
        if first:
            self._make_bodies(fl.gravity_m_s2)
            volumes = np.array([g.volume_m3() for g in self.geoms])
            self._buoyancy_N = -u.rho0_kg_m3 * volumes[:, None] * np.asarray(fl.gravity_m_s2, float)[None, :]
        con = self.scene.contact
        self.coupling = FluidStructureCoupling(self.lbm.solvers[finest], self.dem, self.geoms, self.units_finest,
                                               buoyancy=True, contact_film=True if con is None else con.fluid_film)
        self.lbm.set_stepper(finest, self._couple)

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
            self._couple()
            d.exchange(self.finest, finest.state, t)

        self.lbm.set_stepper(self.finest, step)

    def _prepare(self):
        """Checks and constants of the first build (a scene with a free surface is
        :class:`~iceresist.models.floating_bodies.FloatingBodiesModel`'s)."""
        u, fl = self.units, self.scene.fluid
        self._check_bodies()
        # gravity acts on the bodies (DEM, with the buoyancy); the LBM carries the driving force alone
        self.force_lattice = tuple(float(u.force_density_to_lattice(f)) for f in fl.body_force_N_m3)

    # -- values per leaf ---------------------------------------------------------------------------------
    def _leaf(self, lv: int):
        """rho and u of the leaves; the cells a body covers on the finest level at the reference state (rho0,
        u = 0), as the fields show them."""
        rho, u, xyz = self._own(lv, *self.lbm.leaf_fields(lv))
        if lv == self.finest:
            now = self.coupling.fluid_mask()[:rho.shape[0]]
            rho = np.where(now, rho, 1.0)
            u = np.where(now[None], u, 0.0)
        return rho, u, xyz

    def _fluid_cells(self, lv: int, rho) -> np.ndarray:
        """The leaf cells that are fluid now: on the finest level neither solid nor covered by a body."""
        if lv != self.finest:
            return super()._fluid_cells(lv, rho)
        return self.coupling.fluid_mask()[:rho.shape[0]]

    def _flag_rows(self):
        """The finest level's cell flags now, a cell a body covers GHOST (the whole level on rank 0)."""
        flags = np.asarray(self.target.to_host(self.lbm.solvers[self.finest].flags))
        return self.grid.gather(self.finest, flags)

    # -- protocol ------------------------------------------------------------------------------------------
    def diagnostics(self) -> dict[str, float]:
        """The per-body columns (:meth:`BodyShapes.body_columns`) and the fluid's over every level, the cells the
        bodies cover left out."""
        self.coupling.check_link_list()
        return {**self.body_columns(), **super().diagnostics()}

    def is_finite(self) -> bool:
        return self.grid.all(self._bodies_finite() and math.isfinite(self.lbm.mass()))

    def state(self) -> dict:
        """The levels' populations (:meth:`FluidModel.state`), the finest level's cell flags (the cells the
        bodies cover; ``flags`` on one level, as before levels existed, else ``flags_finest``), the coupling and the
        DEM: a bit-for-bit restart (on several ranks the whole levels on rank 0, None on the others)."""
        flags = self._flag_rows()
        levels, coupling = super().state(), self.coupling.state()
        if levels is None:
            return None
        return {**levels, self._flags_key: np.array(flags, copy=True), "coupling": coupling, "dem": self.dem.state()}

    @property
    def _flags_key(self) -> str:
        return "flags" if self.uniform else "flags_finest"

    def load_state(self, state: dict):
        if "coupling" not in state or "dem" not in state or self._flags_key not in state:
            raise InputError("the checkpoint holds no bodies (no coupling or DEM state) on this grid: it belongs to "
                             "another scene; run again without --pickup")
        super().load_state(state)
        flags = self.grid.level_rows(self.finest, np.asarray(state[self._flags_key]))
        copy_into(self.lbm.solvers[self.finest].flags, flags.astype(np.uint8))
        self.coupling.load_state(state["coupling"])
        self.dem.load_state(state["dem"])
