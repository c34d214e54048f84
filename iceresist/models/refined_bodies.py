"""Rigid bodies in a fluid on refined levels: a scene with ``[[bodies]]`` and ``[refinement]`` (paper sections 2.3-2.5).

:class:`RefinedBodiesModel` is :class:`~iceresist.models.refined.RefinedFluidModel` with the bodies of
:class:`~iceresist.models.bodies.BodiesModel` on its finest level: the coupling (interpolated bounce-back, momentum
exchange, refill, eqs. 16-21) runs on that level's forest at that level's own time step
(:meth:`~iceresist.lbm.refinement.RefinedLBM.set_stepper`), the DEM advances with it. Every body, with two cells to
spare, must lie inside the finest level's leaves at the start (``refinement.body_band_m`` refines around them); a
scene where one does not is refused naming ``refinement``. A body that moves out of the finest level during the run
is not followed yet (block AMR part 2). The fluid alone (no ``[free_surface]``); gravity acts on the bodies (with
the buoyancy), the fluid carries the body force alone, as in :class:`BodiesModel`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from iceresist.errors import InputError
from iceresist.models.bodies import BodiesModel, body_mesh, check_bodies, half_extent
from iceresist.models.refined import RefinedFluidModel


class RefinedBodiesModel(RefinedFluidModel):
    """Boxes, spheres and convex meshes, fixed, prescribed or free, in a fluid on refined levels (module docstring)."""

    regrids = False

    components = ("fluid", "dem", "coupling", "refinement")

    #: The DEM, wall and shape builders of the uniform-grid bodies model, shared as they are.
    _make_dem = BodiesModel._make_dem
    _add_walls = BodiesModel._add_walls
    _shapes = BodiesModel._shapes
    body_columns = BodiesModel.body_columns
    fluid_force_N = BodiesModel.fluid_force_N
    fluid_torque_N_m = BodiesModel.fluid_torque_N_m

    def _build(self):
        from iceresist.coupling import FluidStructureCoupling
        from iceresist.lbm.refinement import RefinedLBM
        from iceresist.models.fluid import forest_faces

        scene, u, fl = self.scene, self.units, self.scene.fluid
        if scene.free_surface is not None:
            raise InputError("refinement: bodies on refined levels run in a fluid without [free_surface] so far; "
                             "remove [refinement] to run them with the free surface on a uniform grid")
        self.box_m = tuple(n * u.dx_m for n in self.shape_cells)
        self.meshes = {i: body_mesh(b, i, scene.source_name) for i, b in enumerate(scene.bodies) if b.shape == "mesh"}
        check_bodies(scene, self.box_m, self.meshes)
        self.dem_backend = "cuda" if self.target.is_cuda else "cpu"
        self.names = [b.name for b in scene.bodies]
        # gravity acts on the bodies (DEM, with the buoyancy); the LBM carries the driving force alone
        self.force_lattice = tuple(float(u.force_density_to_lattice(f)) for f in fl.body_force_N_m3)
        self.lbm = RefinedLBM(self.octree, tau0=u.tau, force0=self.force_lattice, faces=forest_faces(scene, u),
                              operator=fl.operator, precision=self.precision, scheme=scene.refinement.scheme,
                              rescale=scene.refinement.scheme == "interpolate", target=self.target)
        self.lbm.initialize(1.0, tuple(float(u.velocity_to_lattice(v)) for v in fl.initial_velocity_m_s))
        self.finest = finest = self.lbm.levels[-1]
        self._check_in_finest()
        #: the scales of the finest level: cells and time steps 2^L times smaller, tau by acoustic scaling
        self.units_finest = dataclasses.replace(u, dx_m=u.dx_m / 2 ** finest, dt_s=u.dt_s / 2 ** finest,
                                                tau=float(self.lbm.tau[finest]))
        self.dem = self._make_dem(fl.gravity_m_s2)
        self._add_walls(self.dem)
        geoms = []
        for (geom, shape, kinematic, velocity, material), body in zip(self._shapes(), scene.bodies):
            geoms.append(geom)
            self.dem.add_body(shape, position_m=tuple(float(v) for v in body.position_m), velocity_m_s=velocity,
                              kinematic=kinematic, material=material)
        con = scene.contact
        self.coupling = FluidStructureCoupling(self.lbm.solvers[finest], self.dem, geoms, self.units_finest,
                                               buoyancy=True, contact_film=True if con is None else con.fluid_film)
        self.lbm.set_stepper(finest, lambda: self.coupling.step(1))
        volumes = np.array([g.volume_m3() for g in geoms])
        self._buoyancy_N = -u.rho0_kg_m3 * volumes[:, None] * np.asarray(fl.gravity_m_s2, dtype=float)[None, :]

    def _check_in_finest(self):
        """Every body's bounding box, two finest cells wider, on the finest level's leaves."""
        view = self.lbm.views[self.finest]
        dx = self.units.dx_m / 2 ** self.finest
        bm = view.block_map
        for i, body in enumerate(self.scene.bodies):
            c = np.asarray(body.position_m, dtype=float) / dx
            h = half_extent(body, self.meshes.get(i)) / dx + 2.0
            lo = np.floor(c - h).astype(np.int64) >> 3
            hi = np.floor(c + h).astype(np.int64) >> 3
            lo = np.maximum(lo, 0)
            hi = np.minimum(hi, np.array(bm.shape) - 1)
            blocks = bm[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1]
            if ((blocks < 0) | (blocks >= view.nleaves)).any():
                raise InputError(f"refinement: body {body.name!r} (bodies[{i}]) reaches beyond the finest level "
                                 f"(level {self.finest}); refine around it with refinement.body_band_m or a "
                                 f"[[refinement.boxes]] box at level {self.finest}")

    # -- values per leaf ---------------------------------------------------------------------------------
    def _leaf(self, lv: int):
        """rho and u of the leaves; the cells a body covers on the finest level at the reference state (rho0,
        u = 0), as :meth:`BodiesModel.fields` writes them."""
        rho, u, xyz = self.lbm.leaf_fields(lv)
        if lv == self.finest:
            now = self.coupling.fluid_mask()[:self.lbm.views[lv].nleaves]
            rho = np.where(now, rho, 1.0)
            u = np.where(now[None], u, 0.0)
        return rho, u, xyz

    # -- protocol ------------------------------------------------------------------------------------------
    def diagnostics(self) -> dict[str, float]:
        """The per-body columns (:meth:`BodiesModel.body_columns`) and the fluid's over every level."""
        return {**self.body_columns(), **super().diagnostics()}

    def is_finite(self) -> bool:
        bodies = bool(np.isfinite(self.dem.positions).all() and np.isfinite(self.coupling.fluid_force_N).all())
        return bodies and math.isfinite(self.lbm.mass())

    def watchdog_probe(self) -> dict:
        if not np.isfinite(self.dem.positions).all():
            return {"finite": (False, None)}
        return super().watchdog_probe()

    def state(self) -> dict:
        """The levels' populations (:meth:`RefinedFluidModel.state`), the finest level's cell flags (the cells the
        bodies cover), the coupling and the DEM: a bit-for-bit restart."""
        finest = self.lbm.solvers[self.finest]
        return {**super().state(), "flags_finest": np.array(self.target.to_host(finest.flags), copy=True),
                "coupling": self.coupling.state(), "dem": self.dem.state()}

    def load_state(self, state: dict):
        from iceresist.backends.launch import copy_into

        if "coupling" not in state or "dem" not in state or "flags_finest" not in state:
            raise InputError("the checkpoint holds no bodies on refined levels: it belongs to another scene; run "
                             "again without --pickup")
        super().load_state(state)
        copy_into(self.lbm.solvers[self.finest].flags, np.asarray(state["flags_finest"]).astype(np.uint8))
        self.coupling.load_state(state["coupling"])
        self.dem.load_state(state["dem"])

    def describe(self) -> dict:
        return {**super().describe(), "box_m": list(self.box_m), "bodies_level": self.finest,
                "dem_substeps": int(self.dem.substeps_for(self.units_finest.dt_s)),
                "bodies": [{"name": b.name, "shape": b.shape, "motion": b.motion} for b in self.scene.bodies]}
