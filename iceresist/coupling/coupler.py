"""The coupled LBM-DEM step: moving bodies as boundaries of the fluid, fluid forces back to the bodies.

One fluid step of :class:`FluidStructureCoupling` (paper section 2.4):

1. the body state (centre, orientation, velocity, angular velocity) is read from the DEM and put in
   lattice units;
2. cells are re-classified: covered cells become GHOST, uncovered cells are refilled, and the mass
   excess of both is handed to the fluid neighbours (:mod:`iceresist.coupling.kernels`);
3. the link pass writes the interpolated bounce-back populations (eq. 16) and sums the momentum
   exchange (eqs. 17-19) into F_s(t), M_s(t);
4. the LBM takes its fused stream-collide step;
5. F_fluid = (F_s(t) + F_s(t - dt)) / 2 and M_fluid likewise (eqs. 20-21) are handed to the DEM as
   external loads (eqs. 13-14), held over its sub-steps while it advances by dt.

A kinematic DEM body (the ship) moves at its prescribed velocity and only acts on the fluid (one-way).

Buoyancy: a fluid without a gravity body force has no hydrostatic pressure, so by default
(``buoyancy=None`` and a zero LBM force) each body also gets -rho_f V g, the buoyancy of a submerged body.
With the gravity body force in the LBM (always the case for a free surface with g > 0) the hydrostatic
pressure acts through the momentum exchange instead, and ``buoyancy=None`` adds nothing.

Units (:class:`LatticeUnits`): lattice velocity = v dt/dx, lattice force = F dt^2 / (rho_f dx^4), lattice
torque = M dt^2 / (rho_f dx^5). Positions: the centre of cell (i, j, k) lies at origin + (i + 1/2) dx.

Free surface: given a :class:`~iceresist.freesurface.fluid.FreeSurfaceFluid` instead of an
:class:`~iceresist.lbm.solver.LBMSolver`, the passes act on its flow populations and its phase field
(:mod:`iceresist.coupling.surface_kernels`): bounce-back only on links to liquid cells, phi and h refilled in
uncovered cells and the phi of covered cells handed to their neighbours (the water volume outside the
bodies is kept), phi mirrored into the bodies (neutral wetting), h bounced back at the bodies; step 4 is
the free-surface step (LBM, velocity, phase field, reflag). Bodies present at the first step are placed,
not moved in: the water in the cells they cover at the start leaves the water volume and is not handed on.
The lattice gravity of the fluid must equal the DEM gravity in lattice units, |g| dt^2 / dx.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from iceresist.backends.launch import copy_into
from iceresist.coupling.geometry import pack
from iceresist.coupling.kernels import coupling_launchers
from iceresist.errors import InputError, StabilityError
from iceresist.grid import flags as FL
from iceresist.grid.forest import BLOCK

log = logging.getLogger(__name__)


#: Cells of a body's cell box per launch row. A body whose box holds more (the hull: 0.7 M cells at the quick
#: tier-2 resolution, 78 M at the paper's) is split into slabs along z, each launched as a body row of its own
#: (:func:`tile_bodies`), so that it spreads over every CPU thread and CUDA thread block instead of one.
TILE_CELLS = 32768


def slab_counts(bint, tile_cells: int = TILE_CELLS) -> np.ndarray:
    """Slabs per body: its cell box (``bint[:, 3:9]``) over ``tile_cells``, rounded up, at most one per z-plane."""
    ext = (bint[:, 6:9].astype(np.int64) - bint[:, 3:6] + 1)
    return np.maximum(np.minimum(-(-ext.prod(axis=1) // int(tile_cells)), ext[:, 2]), 1)


def tile_bodies(body, bint, slabs):
    """Split each body's cell box into ``slabs[k]`` slabs along z: ``(body_t, bint_t, tile_body)``.

    Each slab is a row of ``body_t``/``bint_t``: a copy of its body's row whose cell box (``bint[:, 3:9]``) is
    a z-range of the body's. The slabs of a body partition its box, so every cell is visited once and the
    kernels, which index everything by the row (shape, state, owner, force row), run unchanged: the owner of a
    covered cell is its slab's row and the force rows of a body's slabs add up to the body's force.
    ``tile_body[row]`` is the body of a row; None where no body is split (rows are bodies). The rows depend on
    ``slabs`` alone, so a coupling that keeps ``slabs`` keeps the body of every row from step to step (the refill
    reads the velocity of the body that uncovered a cell from the row that covered it a step earlier).

    The CPU launcher hands each thread a contiguous range of rows (numba's static prange schedule), so the rows
    are ordered by (slab number + 1/2) / slabs of their body: a body's slabs spread evenly over the range and
    every thread gets its share of the large body.
    """
    m = np.asarray(slabs, dtype=np.int64)
    if (m == 1).all():
        return body, bint, None
    tile_body = np.repeat(np.arange(len(m)), m)
    j = np.arange(len(tile_body)) - np.repeat(np.cumsum(m) - m, m)          # slab number within its body
    nz = (bint[:, 8].astype(np.int64) - bint[:, 5] + 1)[tile_body]
    mt, lo = m[tile_body], bint[tile_body, 5].astype(np.int64)
    bint_t = bint[tile_body].copy()
    bint_t[:, 5] = lo + (j * nz) // mt                   # a slab is empty (z1 < z0) where the box has fewer planes
    bint_t[:, 8] = lo + ((j + 1) * nz) // mt - 1
    order = np.argsort((j + 0.5) / mt, kind="stable")
    return np.ascontiguousarray(body[tile_body[order]]), bint_t[order], tile_body[order]


@dataclass(frozen=True)
class LatticeUnits:
    """Cell size ``dx_m``, time step ``dt_s``, fluid density ``rho_kg_m3``, and the world position of the
    corner (cell 0, 0, 0 lower corner) of the lattice ``origin_m``."""

    dx_m: float
    dt_s: float
    rho_kg_m3: float
    origin_m: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in ("dx_m", "dt_s", "rho_kg_m3"):
            if not getattr(self, name) > 0:
                raise InputError(f"LatticeUnits {name} must be positive, got {getattr(self, name)!r}")

    @property
    def force_N(self) -> float:
        """One lattice force unit in newtons."""
        return self.rho_kg_m3 * self.dx_m ** 4 / self.dt_s ** 2

    @property
    def velocity_m_s(self) -> float:
        return self.dx_m / self.dt_s


def quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3), body -> world, of unit quaternions (n, 4) (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


class FluidStructureCoupling:
    """Couples an :class:`~iceresist.lbm.solver.LBMSolver` and a :class:`~iceresist.dem.DEMSystem`.

    ``geometries``: one shape of :mod:`iceresist.coupling.geometry` per DEM body, in body order.
    ``units``: :class:`LatticeUnits`. ``buoyancy``: add -rho_f V g to each body (default: when the LBM
    has no body force). ``debug``: fill newly covered cells with NaN, so a population the coupling failed
    to provide shows up in :meth:`check_populations`. ``contact_film``: bodies touching another body or a wall
    feel the fluid pressure on the touching face (the film closure of :mod:`iceresist.coupling.kernels`).
    """

    def __init__(self, solver, dem, geometries, units: LatticeUnits, buoyancy: bool | None = None,
                 debug: bool = False, contact_film: bool = True):
        self.surface = solver if hasattr(solver, "phase") else None
        if self.surface is not None:
            solver = self.surface.fluid
            g_dem = float(np.linalg.norm(dem.gravity)) * units.dt_s ** 2 / units.dx_m
            if not np.isclose(g_dem, self.surface.g, rtol=1e-3, atol=1e-12):
                raise InputError(f"free-surface gravity_lattice {self.surface.g:.6g} differs from the DEM gravity in "
                                 f"lattice units |g| dt^2/dx = {g_dem:.6g}; build the fluid with gravity_lattice = "
                                 "|g| dt^2 / dx")
        self.solver, self.dem, self.units = solver, dem, units
        self.target, self.real = solver.target, solver.real
        geometries = list(geometries)
        if len(geometries) != dem.n_bodies:
            raise InputError(f"coupling needs one geometry per DEM body: {len(geometries)} geometries for "
                             f"{dem.n_bodies} bodies")
        self.geometries = geometries
        self.n = len(geometries)
        kinds, pars, first, count, planes, half = pack(geometries)
        dx = units.dx_m
        self._kinds, self._first, self._count = kinds, first, count
        self._par_lat = pars / dx
        self._half_lat = half / dx
        planes = planes.copy()
        planes[:, 3] /= dx
        self._volume_m3 = np.array([g.volume_m3() for g in geometries])
        self.buoyancy = bool(np.allclose(solver.force, 0.0)) if buoyancy is None else bool(buoyancy)
        self.debug = bool(debug)

        fo = solver.forest
        self.forest = fo
        nbx, nby, nbz = fo.shape_blocks
        block_map = np.full((nbx, nby, nbz), -1, dtype=np.int32)
        block_map[fo.origin[:, 0], fo.origin[:, 1], fo.origin[:, 2]] = np.arange(fo.nblocks, dtype=np.int32)
        self._block_map_host = block_map
        self._periodic = np.array([fo.faces[a + "-"].kind == "periodic" for a in "xyz"])
        grid = np.array([*fo.shape_cells, *self._periodic.astype(int)], dtype=np.int64)
        self._shape = np.array(fo.shape_cells)
        flags0 = np.ascontiguousarray(fo.flags.astype(np.uint8))
        owner = np.full((fo.nblocks, BLOCK ** 3), -1, dtype=np.int32)
        dev = self._dev
        self._d = {"grid": dev(grid), "block_map": dev(block_map), "flags0": dev(flags0),
                   "borigin": dev(np.ascontiguousarray(fo.origin.astype(np.int64))),
                   "planes": dev(np.ascontiguousarray(planes.astype(self.real))),
                   "owner": dev(owner), "owner_prev": dev(owner.copy())}
        if self.target.is_cuda:
            self._minus_one = dev(owner.copy())
        self._k = coupling_launchers(self.target, self.real,
                                     None if self.surface is None else self.surface.phase.lat)
        self.contact_film = bool(contact_film)
        g_lat, level = (0.0, 0.0) if self.surface is None else (self.surface.g, self.surface.depth)
        self._d["film"] = dev(np.array([1.0 if self.contact_film else 0.0, g_lat, level], dtype=self.real))
        self._tile_cells = TILE_CELLS
        self._slabs = None
        self._tile_body = None
        self._placed = self.surface is None
        self._prev_boxes = None
        self._force_prev = None
        self.force_lattice = np.zeros((self.n, 3))
        self.torque_lattice = np.zeros((self.n, 3))
        self.links = np.zeros(self.n, dtype=np.int64)
        self.fluid_force_N = np.zeros((self.n, 3))
        self.fluid_torque_N_m = np.zeros((self.n, 3))
        self.active_blocks = 0
        self.event_blocks = 0
        self.iteration = 0
        log.info("coupling: %d bodies on %d blocks, buoyancy %s", self.n, fo.nblocks, self.buoyancy)

    @property
    def tile_cells(self) -> int:
        """Cells of a body's cell box per launch row (:func:`tile_bodies`). The slabs of each body are counted
        from its box at the first step after this is set and then kept."""
        return self._tile_cells

    @tile_cells.setter
    def tile_cells(self, value: int):
        self._tile_cells = int(value)
        self._slabs = None

    # ------------------------------------------------------------------ device helpers
    def _dev(self, a):
        return self.target.to_device(a)

    def _host(self, a):
        return self.target.to_host(a, copy=False)

    # ------------------------------------------------------------------ body state
    def _body_arrays(self):
        """``body`` (n, 21) and ``bint`` (n, 10) in lattice units from the DEM state."""
        u = self.units
        pos = (self.dem.positions - np.asarray(u.origin_m)) / u.dx_m
        R = quaternion_matrices(self.dem.quaternions)
        body = np.empty((self.n, 21))
        body[:, 0:3] = pos
        body[:, 3:12] = R.reshape(self.n, 9)
        body[:, 12:15] = self.dem.velocities * (u.dt_s / u.dx_m)
        body[:, 15:18] = self.dem.angular_velocities * u.dt_s
        body[:, 18:21] = self._par_lat
        ext = np.einsum("nij,nj->ni", np.abs(R), self._half_lat)
        lo = np.floor(pos - ext - 0.5).astype(np.int64) - 1
        hi = np.ceil(pos + ext - 0.5).astype(np.int64) + 1
        n = self._shape
        per = self._periodic
        lo = np.where(per, lo, np.maximum(lo, 0))
        hi = np.where(per, np.minimum(hi, lo + n - 1), np.minimum(hi, n - 1))
        bint = np.empty((self.n, 10), dtype=np.int32)
        bint[:, 0], bint[:, 1], bint[:, 2] = self._kinds, self._first, self._count
        bint[:, 3:6], bint[:, 6:9] = lo, hi
        bint[:, 9] = np.arange(self.n)
        return body.astype(self.real), bint

    def _active(self, bint):
        """Blocks the cell boxes of this and the previous step touch, dilated by one cell."""
        boxes = bint[:, 3:9].astype(np.int64)
        if self._prev_boxes is not None:
            boxes = np.concatenate([boxes, self._prev_boxes])
        self._prev_boxes = bint[:, 3:9].astype(np.int64)
        blo = (boxes[:, :3] - 1) >> 3
        bhi = (boxes[:, 3:] + 1) >> 3
        span = bhi - blo + 1
        nb = np.array(self.forest.shape_blocks)
        out = []
        small = (span <= 4).all(axis=1)
        groups = [(blo[small], bhi[small], 4)] + [(blo[i:i + 1], bhi[i:i + 1], int(span[i].max()))
                                                 for i in np.flatnonzero(~small)]
        for lo, hi, s in groups:
            if len(lo) == 0:
                continue
            off = np.stack(np.meshgrid(*(np.arange(s),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
            cand = lo[:, None, :] + off[None]
            ok = (cand <= hi[:, None, :]).all(axis=2)
            cand = cand[ok]
            for a in range(3):
                if self._periodic[a]:
                    cand[:, a] %= nb[a]
            inside = ((cand >= 0) & (cand < nb)).all(axis=1)
            cand = cand[inside]
            out.append(self._block_map_host[cand[:, 0], cand[:, 1], cand[:, 2]])
        blocks = np.unique(np.concatenate(out)) if out else np.zeros(0, dtype=np.int32)
        return blocks[blocks >= 0].astype(np.int32)

    def _near_events(self, evt):
        """Blocks with a covered or uncovered cell in their own or a neighbour block."""
        hit = np.flatnonzero(evt)
        if len(hit) == 0:
            return np.zeros(0, dtype=np.int32)
        nb = self.forest.nbr[hit].ravel()
        blocks = np.unique(np.concatenate([hit, nb[nb >= 0]]))
        return blocks.astype(np.int32)

    # ------------------------------------------------------------------ the step
    def update_boundaries(self):
        """Passes 1-4 of a coupling step (module docstring): cells, refill, mass, links and F_s(t), M_s(t)."""
        d, k, real = self._d, self._k, self.real
        body_h, bint_h = self._body_arrays()
        active_h = self._active(bint_h)
        self.active_blocks = len(active_h)
        if self._slabs is None:
            self._slabs = slab_counts(bint_h, self._tile_cells)
        body_h, bint_h, self._tile_body = tile_bodies(body_h, bint_h, self._slabs)
        rows = len(bint_h)
        body, bint, active = self._dev(body_h), self._dev(bint_h), self._dev(active_h)
        d["owner"], d["owner_prev"] = d["owner_prev"], d["owner"]
        if self.target.is_cuda:
            d["owner"].copy_to_device(self._minus_one)
        else:
            d["owner"].fill(-1)
        f, flags = self.solver.state, self.solver.flags
        k["mark"](rows, bint, body, d["planes"], d["grid"], d["block_map"], d["flags0"], d["owner"])
        if not self._placed:        # first step with a free surface: the bodies are placed, not moved in
            d["owner_prev"] = self._dev(self._host(d["owner"]).copy())
            self._placed = True
        Fx, Fy, Fz = (real(v) for v in self.solver.force)
        na = len(active_h)
        evt = self._dev(np.zeros(self.forest.nblocks, dtype=np.int32))
        if self.surface is None:
            k["refill"](na, active, d["borigin"], body, d["grid"], d["block_map"], d["flags0"], flags, d["owner"],
                        d["owner_prev"], f, evt, Fx, Fy, Fz)
        else:
            phase = self.surface.phase
            phase.solid = d["owner"]
            k["refill"](na, active, d["borigin"], body, d["grid"], d["block_map"], d["flags0"], flags, d["owner"],
                        d["owner_prev"], f, evt, Fx, Fy, Fz, phase.phi, phase.h)
        near = self._near_events(self._host(evt))
        self.event_blocks = len(near)
        if self.surface is None:
            k["redistribute"](len(near), self._dev(near), d["borigin"], d["grid"], d["block_map"], d["flags0"],
                              d["owner"], d["owner_prev"], f)
        else:
            k["redistribute"](len(near), self._dev(near), d["borigin"], d["grid"], d["block_map"], d["flags0"],
                              flags, d["owner"], d["owner_prev"], f, phase.phi, phase.h)
            k["mirror"](rows, bint, body, d["planes"], d["grid"], d["block_map"], d["flags0"], d["owner"],
                        phase.phi)
        if self.debug:
            k["poison"](na, active, d["flags0"], d["owner"], d["owner_prev"], f)
        bforce = self._dev(np.zeros((rows, 3)))
        btorque = self._dev(np.zeros((rows, 3)))
        nlinks = self._dev(np.zeros((rows, 1), dtype=np.int64))
        k["links"](rows, bint, body, d["planes"], d["grid"], d["block_map"], d["flags0"], d["owner"], f,
                   bforce, btorque, nlinks, flags, d["film"])
        self.force_lattice = self._per_body(self._host(bforce))
        self.torque_lattice = self._per_body(self._host(btorque))
        self.links = self._per_body(self._host(nlinks))[:, 0]

    def _per_body(self, rows: np.ndarray) -> np.ndarray:
        """Sums over the launch rows of each body (:func:`tile_bodies`), as a new array."""
        if self._tile_body is None:
            return rows.copy()
        out = np.zeros((self.n, rows.shape[1]), dtype=rows.dtype)
        np.add.at(out, self._tile_body, rows)
        return out

    def step(self, n: int = 1):
        """``n`` coupled steps: boundaries and forces, one LBM step, DEM over dt with F_fluid held (eqs. 20-21)."""
        u = self.units
        g = np.asarray(self.dem.gravity, dtype=float)
        for _ in range(int(n)):
            self.update_boundaries()
            (self.solver if self.surface is None else self.surface).step(1)
            f_now = np.concatenate([self.force_lattice, self.torque_lattice], axis=1)
            prev = f_now if self._force_prev is None else self._force_prev
            avg = 0.5 * (f_now + prev)
            self._force_prev = f_now
            self.fluid_force_N = avg[:, :3] * u.force_N
            self.fluid_torque_N_m = avg[:, 3:] * u.force_N * u.dx_m
            ext = self.fluid_force_N.copy()
            if self.buoyancy:
                ext -= u.rho_kg_m3 * self._volume_m3[:, None] * g[None, :]
            self.dem.set_external_all(ext, self.fluid_torque_N_m)
            self.dem.step(u.dt_s)
            self.iteration += 1

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        """What a bit-for-bit restart of the coupling needs between two steps: the covering rows of every cell
        now and a step earlier, the slabs per body (so the rows mean the same bodies), the cell boxes of the last
        step (the active blocks), F_s and M_s of the last step (eqs. 20-21) and the step count."""
        n = self.n
        return {"owner": self._host(self._d["owner"]).copy(), "owner_prev": self._host(self._d["owner_prev"]).copy(),
                "slabs": np.zeros(0, np.int64) if self._slabs is None else np.asarray(self._slabs, np.int64),
                "prev_boxes": np.zeros((0, 6), np.int64) if self._prev_boxes is None else self._prev_boxes.copy(),
                "force_prev": np.zeros((0, 6)) if self._force_prev is None else self._force_prev.copy(),
                "force_lattice": self.force_lattice.reshape(n, 3).copy(),
                "torque_lattice": self.torque_lattice.reshape(n, 3).copy(),
                "fluid_force_N": self.fluid_force_N.copy(), "fluid_torque_N_m": self.fluid_torque_N_m.copy(),
                "placed": np.int8(self._placed), "iteration": np.int64(self.iteration)}

    def load_state(self, state: dict):
        """Continue from :meth:`state` of a coupling built the same way (same forest, bodies, tile size)."""
        missing = [k for k in ("owner", "owner_prev", "slabs", "prev_boxes", "force_prev") if k not in state]
        if missing:
            raise InputError(f"coupling state lacks {', '.join(missing)}: it was not written by "
                             "FluidStructureCoupling.state()")
        copy_into(self._d["owner"], np.asarray(state["owner"], dtype=np.int32))
        copy_into(self._d["owner_prev"], np.asarray(state["owner_prev"], dtype=np.int32))
        slabs = np.asarray(state["slabs"], dtype=np.int64)
        if slabs.size not in (0, self.n):
            raise InputError(f"coupling state has slabs for {slabs.size} bodies, this scene has {self.n}: "
                             "it belongs to another scene")
        self._slabs = slabs if slabs.size else None
        boxes, fprev = np.asarray(state["prev_boxes"], np.int64), np.asarray(state["force_prev"], float)
        self._prev_boxes = boxes if boxes.size else None
        self._force_prev = fprev if fprev.size else None
        for key in ("force_lattice", "torque_lattice", "fluid_force_N", "fluid_torque_N_m"):
            if key in state:
                setattr(self, key, np.asarray(state[key], dtype=float).copy())
        self._placed = bool(state["placed"])
        self.iteration = int(state["iteration"])

    # ------------------------------------------------------------------ diagnostics
    def owners(self) -> np.ndarray:
        """The body covering each cell (nblocks, 512), -1 for none (host copy)."""
        owner = self._host(self._d["owner"]).copy()
        if self._tile_body is not None:
            owner = np.where(owner >= 0, self._tile_body[np.maximum(owner, 0)], -1).astype(owner.dtype)
        return owner

    def fluid_mask(self) -> np.ndarray:
        """Cells that are fluid now (nblocks, 512): static fluid and not covered by a body (with a free surface:
        liquid, phi >= 1/2)."""
        m = (self.forest.flags & FL.FLUID != 0) & (self.owners() < 0)
        if self.surface is not None:
            m &= (self._host(self.solver.flags) & FL.FLUID) != 0
        return m

    def water_volume(self) -> float:
        """With a free surface: sum phi over the cells not covered by a body (cells^3), the volume that the
        phase field and the coupling conserve."""
        if self.surface is None:
            raise InputError("water_volume needs a free surface (a FreeSurfaceFluid)")
        return self.surface.phase.volume()

    def fluid_mass(self) -> tuple[float, int]:
        """Sum of rho over the fluid cells now (lattice units) and the number of those cells."""
        f = self.solver.populations()
        m = self.fluid_mask()
        return float(m.sum() + f.sum(axis=1)[m].sum()), int(m.sum())

    def check_populations(self):
        """Raise StabilityError where a fluid cell holds a non-finite population (a cell left without
        populations after a body moved, or a blow-up)."""
        f = self.solver.populations()
        m = self.fluid_mask()
        bad = ~np.isfinite(f).all(axis=1) & m
        if bad.any():
            b, c = np.argwhere(bad)[0]
            raise StabilityError(f"{int(bad.sum())} fluid cells hold non-finite populations (first: block {b}, "
                                 f"cell {c}); lower the body speed (Mach) or check the refill")
