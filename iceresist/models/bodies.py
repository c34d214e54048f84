"""Rigid bodies in a fluid: the model of a scene with ``[[bodies]]`` (boxes and spheres), without a ship.

Two set-ups, chosen by the scene:

* **fluid only** (no ``[free_surface]``): a block forest and an :class:`~iceresist.lbm.solver.LBMSolver` (the
  scene's faces, ``domain.pad_to_blocks``, ``fluid.body_force_N_m3`` as the LBM's force), a
  :class:`~iceresist.dem.DEMSystem` and a :class:`~iceresist.coupling.FluidStructureCoupling` joining them (paper
  eqs. 16-21). Gravity (``fluid.gravity_m_s2``) acts on the bodies in the DEM, and the fluid adds the buoyancy
  -rho_f V g to each (the flow carries no hydrostatic pressure: in a closed or through-flow box of one fluid the
  pressure of gravity changes nothing but the buoyancy). The set-up of the fixed sphere in a channel and of the
  sphere settling in a closed box (:mod:`iceresist.validate.cases.sphere_drag`, ``settling_sphere``).
* **free surface** (``[free_surface]``): a closed tank of walls, water at ``free_surface.water_depth_m``, and the
  bodies, all in a :class:`~iceresist.coupling.floating.FloatingBodies`: the hydrostatic pressure of the gravity
  body force is the buoyancy. The set-up of the floating cube (:mod:`iceresist.validate.cases.floating_cube`).

Motion (``bodies[].motion``): ``free`` bodies move under gravity, the fluid force and the DEM contacts (their
``density_kg_m3`` sets mass and inertia); ``fixed`` bodies stay at rest and ``prescribed`` bodies move at
``velocity_m_s`` (both kinematic: they act on the fluid and on free bodies and are not moved by either). The
domain's wall faces (``wall``, ``moving_wall``, ``slip``) are DEM contact planes; without a ``[contact]`` section
the DEM keeps its own contact law (:class:`~iceresist.dem.ContactParameters`, sub-step 0.05 of the critical step).

Units: a physical scene gives dx (``domain.dx_m``) and dt (``numerics.dt_s`` or the Mach rule of
docs/SCENES.md, "Rules"); a lattice-unit scene has dx = dt = rho0 = 1, and the bodies' sizes, positions, speeds and densities
are read in lattice units too.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.backends.launch import copy_into
from iceresist.coupling import Box, ConvexPolyhedron, FluidStructureCoupling, Sphere
from iceresist.coupling.floating import FloatingBodies
from iceresist.dem import ContactParameters, DEMSystem, box, convex_polyhedron, sphere
from iceresist.errors import InputError
from iceresist.grid import flags as FL
from iceresist.grid.grid import Grid, several
from iceresist.lbm.solver import LBMSolver
from iceresist.limits import check_fluid
from iceresist.models.base import Model, array_bytes
from iceresist.models.fluid import (BLOCK, FluidModel, check_block_shape, check_free_surface_forces,
                                    forest_faces, padding_solid, resolve_target)
from iceresist.models.probe import fluid_probe
from iceresist.models.regions import body_mesh, half_extent
from iceresist.models.surface import FreeSurfaceModel
from iceresist.scene.schema import Scene

log = logging.getLogger(__name__)

#: Face kinds that are walls for the bodies (DEM contact planes).
WALL_KINDS = ("wall", "moving_wall", "slip")
#: Per-body time-series columns, each prefixed ``<name>_``.
BODY_COLUMNS = ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "Fx_N", "Fy_N", "Fz_N", "Tx_N_m", "Ty_N_m",
                "Tz_N_m")


def _g(v) -> str:
    return f"{float(v):.6g}"


def _overlap(a, b, ma=None, mb=None) -> bool:
    """Whether bodies ``a`` and ``b`` of the scene share volume at t = 0 (a mesh body counts as its bounding box:
    the check errs on the side of refusing)."""
    ca, cb = np.asarray(a.position_m, dtype=float), np.asarray(b.position_m, dtype=float)
    ha, hb = half_extent(a, ma), half_extent(b, mb)
    if a.shape == "sphere" and b.shape == "sphere":
        return float(np.linalg.norm(ca - cb)) < a.radius_m + b.radius_m
    if a.shape != "sphere" and b.shape != "sphere":
        return bool((np.abs(ca - cb) < ha + hb).all())
    s, c, h = (a, cb, hb) if a.shape == "sphere" else (b, ca, ha)
    centre = np.asarray(s.position_m, dtype=float)
    nearest = np.clip(centre, c - h, c + h)
    return float(np.linalg.norm(centre - nearest)) < s.radius_m


def check_bodies(scene: Scene, box_m, meshes: dict | None = None) -> None:
    """Refuse bodies that reach outside the box ``box_m`` (m), overlap at t = 0, or give a velocity to a fixed
    body: an :class:`InputError` naming the key and a value that works. ``meshes``: body index -> its
    :func:`body_mesh`."""
    box_m = np.asarray(box_m, dtype=float)
    meshes = meshes or {}
    for i, b in enumerate(scene.bodies):
        c, h = np.asarray(b.position_m, dtype=float), half_extent(b, meshes.get(i))
        key = {"sphere": "radius_m", "box": "size_m", "mesh": "mesh_unit"}[b.shape]
        if b.motion == "fixed" and any(b.velocity_m_s):
            raise InputError(f"bodies[{i}].velocity_m_s: body {b.name!r} is fixed (at rest): leave velocity_m_s "
                             f"out, or set motion = \"prescribed\" to move it at {list(b.velocity_m_s)} m/s")
        for a, axis in enumerate("xyz"):
            if 2 * h[a] >= box_m[a]:
                raise InputError(f"bodies[{i}].{key}: body {b.name!r} is {_g(2 * h[a])} m across along {axis}, "
                                 f"not less than the domain's {_g(box_m[a])} m: make it smaller than that")
            if c[a] - h[a] < 0.0 or c[a] + h[a] > box_m[a]:
                fix = c.copy()
                fix[a] = min(max(c[a], h[a]), box_m[a] - h[a])
                raise InputError(f"bodies[{i}].position_m: body {b.name!r} reaches {axis} = {_g(c[a] - h[a])} .. "
                                 f"{_g(c[a] + h[a])} m, outside the domain 0 .. {_g(box_m[a])} m: use e.g. "
                                 f"position_m = [{', '.join(_g(v) for v in fix)}]")
    for j, b in enumerate(scene.bodies):
        for i in range(j):
            a = scene.bodies[i]
            if not _overlap(a, b, meshes.get(i), meshes.get(j)):
                continue
            ca, ha, hb = (np.asarray(a.position_m, dtype=float), half_extent(a, meshes.get(i)),
                          half_extent(b, meshes.get(j)))
            fix = np.asarray(b.position_m, dtype=float).copy()
            gap = 0.05 * float(min(ha.min(), hb.min()))
            ahead, behind = ca[0] + ha[0] + hb[0] + gap, ca[0] - ha[0] - hb[0] - gap
            fix[0] = ahead if ahead + hb[0] <= box_m[0] else behind
            raise InputError(f"bodies[{j}].position_m: body {b.name!r} overlaps body {a.name!r} at t = 0: move it "
                             f"clear, e.g. position_m = [{', '.join(_g(v) for v in fix)}]")


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


class BodiesModel(Model):
    """Boxes and spheres, free, fixed or prescribed, in a fluid (with or without a free surface); see the module
    docstring. ``backend`` and ``precision`` override the scene's ``[numerics]``.

    Time series (:meth:`diagnostics`): per body ``<name>_x_m`` ... ``_z_m`` (centre of mass), ``_vx_m_s`` ...,
    the fluid force ``_Fx_N`` ... (eq. 20, with the buoyancy) and torque ``_Tx_N_m`` ... (eq. 21) about the
    centre of mass; and the fluid's own columns.
    """

    def __init__(self, scene: Scene, *, backend: str | None = None, precision: str | None = None, comm=None):
        self.scene = scene
        self.comm = several(comm)
        if not scene.bodies:
            raise InputError(f"{scene.source_name}: BodiesModel needs a [[bodies]] section")
        self.free_surface = scene.free_surface is not None
        self.components = ("fluid", "free_surface", "dem", "coupling") if self.free_surface else \
            ("fluid", "dem", "coupling")
        self.backend = backend or scene.numerics.backend
        self.precision = precision or scene.numerics.precision
        self.target = resolve_target(self.backend)
        self.dem_backend = "cuda" if self.target.is_cuda else "cpu"
        box_cells = scene.domain.shape_cells()
        u0 = scene.units()
        self.box_m = tuple(n * u0.dx_m for n in box_cells)
        self.meshes = {i: body_mesh(b, i, scene.source_name) for i, b in enumerate(scene.bodies) if b.shape == "mesh"}
        check_bodies(scene, self.box_m, self.meshes)
        if self.free_surface:
            self._build_free_surface(u0)
        else:
            self._build_fluid(u0)
        self.names = [b.name for b in scene.bodies]
        self._probes = 0
        log.info("bodies: %d (%s) in %s, %d cells, dx %.4g m, dt %.4g s, tau %.6g", len(self.names),
                 ", ".join(f"{b.name} {b.shape} {b.motion}" for b in scene.bodies),
                 "water with a free surface" if self.free_surface else "a fluid", self.cells, self.units.dx_m,
                 self.dt_s, self.units.tau)

    # -- set-up -----------------------------------------------------------------------------------------
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

    def _build_fluid(self, u):
        scene = self.scene
        self.units = u
        self.shape_cells = scene.domain.padded_cells()
        check_block_shape(self.shape_cells)
        check_fluid(scene, u)
        fl = scene.fluid
        self.grid = Grid.uniform(self.shape_cells, forest_faces(scene, u), solid=padding_solid(scene), comm=self.comm)
        self.global_forest, self.forest, self.decomp = self.grid.global_forest, self.grid.forest, self.grid.decomp
        # gravity acts on the bodies (DEM) with the buoyancy -rho_f V g; the LBM carries the driving force alone
        self.force_lattice = tuple(float(u.force_density_to_lattice(f)) for f in fl.body_force_N_m3)
        self.solver = LBMSolver(self.forest, tau=u.tau, force=self.force_lattice, operator=fl.operator,
                                precision=self.precision, target=self.target)
        self.solver.initialize(1.0, tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self.dem = self._make_dem(fl.gravity_m_s2)
        self._add_walls(self.dem)
        geoms = []
        for geom, shape, kinematic, velocity, material in self._shapes():
            geoms.append(geom)
            body = self.scene.bodies[len(geoms) - 1]
            self.dem.add_body(shape, position_m=tuple(float(v) for v in body.position_m), velocity_m_s=velocity,
                              kinematic=kinematic, material=material)
        con = scene.contact
        self.coupling = FluidStructureCoupling(self.solver, self.dem, geoms, u, buoyancy=True,
                                               contact_film=True if con is None else con.fluid_film)
        if self.decomp is not None:
            self.coupling.distribute(self.decomp)
        volumes = np.array([g.volume_m3() for g in geoms])
        # the buoyancy the coupling adds to the DEM loads (its fluid force leaves it out)
        self._buoyancy_N = -u.rho0_kg_m3 * volumes[:, None] * np.asarray(fl.gravity_m_s2, dtype=float)[None, :]
        self.cells = int(self.global_forest.cells)
        self.dt_s = u.dt_s
        self.fb = None

    def _build_free_surface(self, u0):
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
                             f"{_g(math.sqrt(0.01 * u0.dx_m / g))} s")
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
        if self.fb is not None:         # free surface: FloatingBodies exchanges the halo on several ranks
            self.fb.step(int(n))
            return
        if self.decomp is None:
            self.coupling.step(int(n))
            return
        for _ in range(int(n)):
            self.coupling.step(1)
            self._exchange()

    # -- several ranks (a fluid without a free surface) ------------------------------------------------------
    def _exchange(self):
        """Every halo block takes its owner's populations and cell flags (the cells bodies cover). The coupling's
        passes (refill, redistribution, the links' second neighbour) and the LBM step reach at most 6 cells into an
        8-cell halo block from its outer side, so the cells next to this rank's blocks stay exact through a step;
        the DEM runs on every rank alike, on the forces summed over the ranks."""
        for arr in (self.solver.state, self.solver.flags):
            self.grid.exchange(arr, self.target, full=True)

    # -- bodies -----------------------------------------------------------------------------------------
    @property
    def fluid_force_N(self) -> np.ndarray:
        """Force of the fluid on each body (n, 3), N, the mean of the last two steps (eq. 20), the buoyancy
        included (in a scene without a free surface the -rho_f V g the coupling adds)."""
        return self.coupling.fluid_force_N + self._buoyancy_N

    @property
    def fluid_torque_N_m(self) -> np.ndarray:
        """Torque of the fluid on each body (n, 3), N m, about its centre of mass (eq. 21)."""
        return self.coupling.fluid_torque_N_m

    def body_columns(self) -> dict[str, float]:
        """The per-body time-series columns (:data:`BODY_COLUMNS`)."""
        pos, vel = self.dem.positions, self.dem.velocities
        force, torque = self.fluid_force_N, self.fluid_torque_N_m
        out = {}
        for k, name in enumerate(self.names):
            values = (*pos[k], *vel[k], *force[k], *torque[k])
            out.update({f"{name}_{col}": float(v) for col, v in zip(BODY_COLUMNS, values)})
        return out

    # -- fluid ------------------------------------------------------------------------------------------
    def _fluid_now(self) -> np.ndarray:
        """Cells that are fluid now (nblocks, 512): not solid, not covered by a body (free surface: liquid)."""
        return self.coupling.fluid_mask()

    def _dense_mask(self, mask_blocks) -> np.ndarray:
        return np.nan_to_num(self.forest.to_dense(mask_blocks.astype(np.float64)), nan=0.0) > 0.5

    def fields(self) -> dict[str, np.ndarray]:
        """Fluid only: rho (kg/m^3), u (m/s, [x, y, z, 3]), pressure (Pa, gauge), flags (uint8; a cell a body
        covers is GHOST); rho0, u = 0 and pressure 0 in solids and bodies (the field writer takes a NaN for a
        blow-up). Free surface: as :class:`FreeSurfaceModel` (rho0, u = 0 and pressure 0 in the gas and the
        bodies), with phi and surface (0 in a column without a crossing of phi = 1/2)."""
        u = self.units
        if not self.free_surface:
            rho_b, u_b = self.solver.macroscopic_blocks()
            g = self.grid
            parts = (g.gather_rows(rho_b), g.gather_rows(u_b, axis=1), g.gather_rows(self._fluid_now()),
                     g.gather_rows(np.asarray(self.target.to_host(self.solver.flags)).astype(np.float64)))
            if parts[0] is None:
                return None
            fo = self.global_forest
            rho_lat, u_lat = fo.to_dense(parts[0]), fo.to_dense(parts[1])
            now = np.nan_to_num(fo.to_dense(parts[2].astype(np.float64)), nan=0.0) > 0.5
            rho_lat = np.where(now, rho_lat, 1.0)
            u_lat = np.where(now[None], u_lat, 0.0)
            flags = fo.to_dense(parts[3])
            return {"rho": u.density_to_physical(rho_lat),
                    "u": u.velocity_to_physical(np.moveaxis(u_lat, 0, -1)),
                    "pressure": u.pressure_to_physical((rho_lat - 1.0) / 3.0),
                    "flags": np.nan_to_num(flags, nan=FL.SOLID).astype(np.uint8)}
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

    def field_units(self, lattice: bool) -> dict[str, str]:
        return FreeSurfaceModel.field_units(lattice) if self.free_surface else FluidModel.field_units(lattice)

    def _fluid_columns(self) -> dict[str, float]:
        """Fluid mass (kg), kinetic energy (J) and largest speed (m/s and lattice) over the cells that are fluid
        now; with a free surface also the water volume outside the bodies (m^3), its drift from t = 0 and the
        water level (m, mean height of phi = 1/2 over the columns no body reaches)."""
        u = self.units
        cell_m3 = u.dx_m ** 3
        out = {}
        if self.free_surface:
            rho_d, u_d = self.fb.fluid.macroscopic()
            vol, level = self.coupling.water_volume(), self.water_level_m()
            if rho_d is None:       # an MPI rank other than 0: rank 0's columns follow
                return None
            now = np.isfinite(rho_d)
            rho_lat, u_lat = rho_d[now], u_d[:, now]
            out.update(water_volume_m3=float(vol * cell_m3),
                       water_volume_drift=float((vol - self.volume0_cells) / self.volume0_cells),
                       water_level_m=level)
        else:
            rho_b, u_b = self.solver.macroscopic_blocks()
            now = self._fluid_now()
            g = self.grid
            rho_b, u_b, now = g.gather_rows(rho_b), g.gather_rows(u_b, axis=1), g.gather_rows(now)
            if rho_b is None:       # an MPI rank other than 0: rank 0's columns follow
                return None
            rho_lat, u_lat = rho_b[now], u_b[:, now]
        speed2 = (u_lat ** 2).sum(axis=0)
        rho_kg = u.density_to_physical(rho_lat)
        umax = float(np.sqrt(speed2.max())) if speed2.size else 0.0
        out.update(mass_kg=float(rho_kg.sum() * cell_m3),
                   kinetic_energy_J=float(0.5 * (rho_kg * u.velocity_to_physical(1.0) ** 2 * speed2).sum()
                                          * cell_m3),
                   max_speed_m_s=float(u.velocity_to_physical(umax)), max_lattice_speed=umax)
        return out

    def water_level_m(self) -> float:
        """Free surface: the mean height of phi = 1/2 over the columns no body reaches (all columns where the
        bodies reach every one), m above z = 0; on several ranks on rank 0 (None on the others)."""
        owners = self.fb.dense_owners()
        h = self.fb.fluid.surface_height()
        if h is None:
            return None
        free = (np.nan_to_num(owners, nan=-1) < 0).all(axis=2)
        sel = h[free] if free.any() else h.ravel()
        sel = sel[np.isfinite(sel)]
        return float(sel.mean()) * self.units.dx_m if sel.size else math.nan

    def diagnostics(self) -> dict[str, float]:
        """One row: the per-body columns (:meth:`body_columns`) and the fluid's (:meth:`_fluid_columns`); on several
        ranks the fluid's from the gathered blocks on rank 0, the same row on every rank."""
        self.coupling.check_link_list()
        return {**self.body_columns(), **self.grid.bcast(self._fluid_columns())}

    def is_finite(self) -> bool:
        bodies = bool(np.isfinite(self.dem.positions).all() and np.isfinite(self.coupling.fluid_force_N).all())
        if self.free_surface:
            return bodies and math.isfinite(self.coupling.water_volume())
        return self.grid.all(bodies and math.isfinite(self.solver.mass()))

    #: Every this many probes (the first included) a free-surface probe reads the populations (as tier 2).
    full_probe_every = 10

    def watchdog_probe(self) -> dict:
        """Finite bodies, and the fluid's quantities (:mod:`iceresist.watchdog`) on the cells that are fluid now;
        the reference kinetic energy is that of the whole fluid moving at the scene's largest speed (at least a
        tenth of numerics.mach)."""
        if not np.isfinite(self.dem.positions).all():
            return {"finite": (False, None)}
        u_ref = max(float(self.units.velocity_to_lattice(self.scene.largest_speed_m_s())),
                    0.1 * self.scene.numerics.mach)
        ke_ref = 0.5 * self.cells * u_ref ** 2
        if self.free_surface:
            full = self._probes % self.full_probe_every == 0
            self._probes += 1
            return self.fb.fluid.probe(full, ke_ref)
        if self.decomp is None:
            rho_lat, u_lat = self.solver.macroscopic()
            return fluid_probe(rho_lat, u_lat, self._dense_mask(self._fluid_now()), ke_ref)
        rho_b, u_b = self.solver.macroscopic_blocks()
        g = self.grid
        parts = (g.gather_rows(rho_b), g.gather_rows(u_b, axis=1), g.gather_rows(self._fluid_now()))
        probe = None
        if parts[0] is not None:
            fo = self.global_forest
            now = np.nan_to_num(fo.to_dense(parts[2].astype(np.float64)), nan=0.0) > 0.5
            probe = fluid_probe(fo.to_dense(parts[0]), fo.to_dense(parts[1]), now, ke_ref)
        return self.grid.bcast(probe)

    # -- checkpoints ------------------------------------------------------------------------------------
    def state(self) -> dict:
        """Everything a bit-for-bit restart needs: the fluid (fluid only: both population buffers in storage
        precision and the cell flags; free surface: population rows, h, phi, flags), the coupling (cell owners,
        the forces of the last step), the DEM with its contact history, and the step count."""
        if self.free_surface:
            st = self.fb.state()
            return None if st is None else {"iteration": np.int64(self.iteration), "precision": self.precision,
                                            "dem": self.dem.state(), **st,
                                            "volume0_cells": np.float64(self.volume0_cells)}
        host = self.target.to_host
        out = {"iteration": np.int64(self.iteration), "precision": self.precision,
               "coupling": self.coupling.state(), "dem": self.dem.state(),
               "f": np.array(host(self.solver._f[0]), copy=True), "f_back": np.array(host(self.solver._f[1]), copy=True),
               "flags": np.array(host(self.solver.flags), copy=True), "lbm_iteration": np.int64(self.solver.iteration)}
        for key in ("f", "f_back", "flags"):      # the whole domain in global block order, on rank 0
            out[key] = self.grid.gather_rows(out[key])
        return None if out["coupling"] is None else out

    def load_state(self, state: dict):
        if "coupling" not in state or "dem" not in state:
            raise InputError("the checkpoint holds no bodies (no coupling or DEM state): it belongs to another "
                             "scene; run again without --pickup")
        if str(state.get("precision", self.precision)) != self.precision:
            raise InputError(f"checkpoint holds {state.get('precision')} populations, this run is {self.precision}: "
                             f"restart with --precision {state.get('precision')}")
        if self.free_surface:
            if "fluid" not in state:
                raise InputError("the checkpoint holds no free-surface state: it belongs to another scene")
            self.fb.fluid.load_state(state["fluid"])
            self.volume0_cells = float(state["volume0_cells"])
        else:
            if "f" not in state:
                raise InputError("the checkpoint holds no populations of a fluid-only scene: it belongs to "
                                 "another scene")
            expected = (self.global_forest.nblocks, 27, BLOCK ** 3)
            if tuple(np.shape(state["f"])) != expected:
                raise InputError(f"checkpoint populations have shape {tuple(np.shape(state['f']))}, this scene "
                                 f"needs {expected}: it belongs to another scene")
            state = {**state, **{k: self.grid.local_rows(np.asarray(state[k])) for k in ("f", "f_back", "flags")}}
            copy_into(self.solver._f[0], np.asarray(state["f"]).astype(self.solver.real))
            copy_into(self.solver._f[1], np.asarray(state["f_back"]).astype(self.solver.real))
            copy_into(self.solver.flags, np.asarray(state["flags"]).astype(np.uint8))
            self.solver.iteration = int(state["lbm_iteration"])
        self.coupling.load_state(state["coupling"])
        self.dem.load_state(state["dem"])

    # -- identity ---------------------------------------------------------------------------------------
    def describe(self) -> dict:
        u = self.units
        out = {"components": list(self.components), "shape_cells": list(self.shape_cells), "cells": self.cells,
               "blocks": int(getattr(self, "global_forest", self.forest).nblocks),
               "operator": self.scene.fluid.operator,
               "precision": self.precision, "backend": self.target.name, "units": u.describe(),
               "unit_system": self.scene.scene.units, "box_m": list(self.box_m),
               "dem_substeps": int(self.dem.substeps_for(self.dt_s)),
               "bodies": [{"name": b.name, "shape": b.shape, "motion": b.motion,
                           "mass_kg": float(s.mass_kg) if hasattr(s, "mass_kg") else None}
                          for b, (_, s, *_) in zip(self.scene.bodies, self._shapes())]}
        if self.free_surface:
            fs = self.scene.free_surface
            out.update(gravity_lattice=self.g_lattice, water_depth_cells=fs.water_depth_m / u.dx_m,
                       h_lattice=fs.h_lattice, mobility_lattice=fs.mobility_lattice,
                       interface_width_cells=fs.interface_width_cells, f_pool="full")
        else:
            out.update(force_lattice=list(self.force_lattice), bytes_per_cell=int(self.solver.bytes_per_cell),
                       pad_to_blocks=bool(self.scene.domain.pad_to_blocks))
        return {**out, **self.grid.describe()}

    def allocation(self) -> dict[str, int]:
        """Bytes of state per component: the LBM (populations, both buffers), the phase field (free surface),
        the DEM and the coupling."""
        out = {"dem": array_bytes(self.dem), "coupling": array_bytes(self.coupling)}
        if self.free_surface:
            fl = self.fb.fluid
            out.update(lbm=array_bytes(fl.fluid, fl), phase_field=array_bytes(fl.phase))
        else:
            out["lbm"] = int(self.solver.bytes_per_cell) * int(self.forest.nblocks) * BLOCK ** 3
        return out
