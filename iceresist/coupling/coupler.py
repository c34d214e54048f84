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

Units (:class:`iceresist.units.Units`, of which the coupling reads dx, dt and rho0): lattice velocity = v dt/dx, lattice force = F dt^2 / (rho_f dx^4), lattice
torque = M dt^2 / (rho_f dx^5). Positions: the centre of cell (i, j, k) lies at ``origin_m`` + (i + 1/2) dx.

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

import numpy as np

from iceresist.backends.launch import copy_into
from iceresist.coupling.bodystate import body_state_launchers
from iceresist.coupling.geometry import pack
from iceresist.coupling.kernels import coupling_launchers
from iceresist.errors import InputError, StabilityError
from iceresist.grid import flags as FL
from iceresist.grid.forest import BLOCK
from iceresist.units import Units

log = logging.getLogger(__name__)


#: Cells of a body's cell box per launch row on the CPU. A body whose box holds more (the hull: 0.7 M cells at the
#: quick tier-2 resolution, 78 M at the paper's) is split into runs of its cells, each launched as a row of its own
#: (:func:`tile_rows`), so that it spreads over every CPU thread instead of one.
TILE_CELLS = 32768

#: The same on CUDA, where a row is one thread block of ``BODY_THREADS`` (128) threads: 16 cells per thread, so
#: that the hull spreads over hundreds of blocks (with 32 768 the quick case's hull was 25 blocks sweeping 240-360
#: cells per thread while the rest of the GPU idled: 75 % of the coupled step on an H200).
TILE_CELLS_CUDA = 2048
#: Threads of the CUDA links pass over its list of cells (each strides over the list): enough to fill a GPU, and few
#: under the CUDA simulator, where every thread is a Python thread.
LIST_THREADS = 1 << 18
LIST_THREADS_SIMULATED = 256


def slab_counts(bint, tile_cells: int = TILE_CELLS) -> np.ndarray:
    """Runs (launch rows) per body: its cell box (``bint[:, 3:9]``) over ``tile_cells``, rounded up, at least one."""
    ext = np.maximum(bint[:, 6:9].astype(np.int64) - bint[:, 3:6] + 1, 0)
    return np.maximum(-(-ext.prod(axis=1) // int(tile_cells)), 1)


def tile_rows(slabs) -> np.ndarray:
    """The launch rows ``(rows, 3)`` int64 of bodies split into ``slabs[k]`` runs: (body, run, runs).

    Each row is a run of its body's cell box, cells counted x fastest
    (:func:`iceresist.coupling.bodystate.build_body_state` gives row j of m the cells j N // m to (j + 1) N // m of
    the box's N); the runs of a body partition its box, so every cell is visited once and the kernels, which index
    everything by the row (shape, state, owner, force row), run unchanged: the owner of a covered cell is its run's
    row and the force rows of a body's runs add up to the body's force. The rows depend on ``slabs`` alone, so a
    coupling that keeps ``slabs`` keeps the body of every row from step to step (the refill reads the velocity of
    the body that uncovered a cell from the row that covered it a step earlier).

    The CPU launcher hands each thread a contiguous range of rows (numba's static prange schedule), so the rows
    are ordered by (run number + 1/2) / runs of their body: a body's runs spread evenly over the range and
    every thread gets its share of the large body.
    """
    m = np.asarray(slabs, dtype=np.int64)
    body = np.repeat(np.arange(len(m)), m)
    j = np.arange(len(body)) - np.repeat(np.cumsum(m) - m, m)          # run number within its body
    order = np.argsort((j + 0.5) / m[body], kind="stable")
    return np.ascontiguousarray(np.stack([body[order], j[order], m[body[order]]], axis=1), dtype=np.int64)


class FluidStructureCoupling:
    """Couples an :class:`~iceresist.lbm.solver.LBMSolver` and a :class:`~iceresist.dem.DEMSystem`.

    ``geometries``: one shape of :mod:`iceresist.coupling.geometry` per DEM body, in body order.
    ``units``: :class:`~iceresist.units.Units` of the lattice; ``origin_m``: world position of the lower corner of cell (0, 0, 0). ``buoyancy``: add -rho_f V g to each body (default: when the LBM
    has no body force). ``debug``: fill newly covered cells with NaN, so a population the coupling failed
    to provide shows up in :meth:`check_populations`. ``contact_film``: bodies touching another body or a wall
    feel the fluid pressure on the touching face (the film closure of :mod:`iceresist.coupling.kernels`).
    """

    def __init__(self, solver, dem, geometries, units: Units, buoyancy: bool | None = None,
                 debug: bool = False, contact_film: bool = True, origin_m=(0.0, 0.0, 0.0)):
        self.origin_m = tuple(float(v) for v in origin_m)
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
        #: The forest's first blocks whose links count into the forces (all; an MPI rank's own blocks, its halo
        #: after them: :meth:`distribute`), the decomposition (None: one process) and ``after_boundaries()``, called
        #: between the boundary passes and the LBM step (None: nothing; on several ranks with a free surface the
        #: halo exchange).
        self.nowned = fo.nblocks
        self.decomp = None
        self.after_boundaries = None
        nbx, nby, nbz = fo.shape_blocks
        block_map = np.full((nbx, nby, nbz), -1, dtype=np.int32)
        block_map[fo.origin[:, 0], fo.origin[:, 1], fo.origin[:, 2]] = np.arange(fo.nblocks, dtype=np.int32)
        self._periodic = np.array([fo.faces[a + "-"].kind == "periodic" for a in "xyz"])
        grid = np.array([*fo.shape_cells, *self._periodic.astype(int)], dtype=np.int64)
        flags0 = np.ascontiguousarray(fo.flags.astype(np.uint8))
        owner = np.full((fo.nblocks, BLOCK ** 3), -1, dtype=np.int32)
        g = np.asarray(dem.gravity, dtype=float)
        buoy = units.rho0_kg_m3 * self._volume_m3[:, None] * g[None, :] if self.buoyancy else np.zeros((self.n, 3))
        n, nb = self.n, fo.nblocks
        dev = self._dev
        self._d = {"grid": dev(grid), "block_map": dev(block_map), "flags0": dev(flags0),
                   "borigin": dev(np.ascontiguousarray(fo.origin.astype(np.int64))),
                   "planes": dev(np.ascontiguousarray(planes.astype(self.real))),
                   "owner": dev(owner), "owner_prev": dev(owner.copy()),
                   # body state (module bodystate): per-body constants, boxes, loads
                   "shape_int": dev(np.stack([kinds, first, count], axis=1).astype(np.int32)),
                   "par_lat": dev(np.ascontiguousarray(self._par_lat, dtype=np.float64)),
                   "half_lat": dev(np.ascontiguousarray(self._half_lat, dtype=np.float64)),
                   "conv": dev(np.array([*np.asarray(self.origin_m, dtype=float), dx, units.dt_s / dx,
                                         units.dt_s], dtype=np.float64)),
                   "nblocks3": dev(np.array([nbx, nby, nbz], dtype=np.int64)),
                   "nbr": dev(np.ascontiguousarray(fo.nbr)),
                   "load_scale": dev(np.array([units.force_to_physical(1.0), dx], dtype=np.float64)),
                   "buoy": dev(np.ascontiguousarray(buoy, dtype=np.float64)),
                   "box": dev(np.zeros((n, 6), np.int64)), "box_prev": dev(np.zeros((n, 6), np.int64)),
                   "now": dev(np.zeros((n, 6))), "fprev": dev(np.zeros((n, 6))), "fluid": dev(np.zeros((n, 6))),
                   "fluid_sum": dev(np.zeros((n, 6))), "links": dev(np.zeros(n, np.int64)),
                   "active": dev(np.zeros(nb, np.int8)), "changed": dev(np.zeros(nb, np.int8)),
                   "evt": dev(np.zeros(nb, np.int32)),
                   "near": dev(np.zeros(nb, np.int32)),
                   # the CUDA link list's count (kernels.LIST_ARGS); its rows are sized by _lay_out_rows
                   "ncells": dev(np.zeros(2, np.int64))}
        self._k = coupling_launchers(self.target, self.real,
                                     None if self.surface is None else self.surface.phase.lat)
        self._s = body_state_launchers(self.target, self.real)
        self.contact_film = bool(contact_film)
        g_lat, level = (0.0, 0.0) if self.surface is None else (self.surface.g, self.surface.depth)
        self._d["film"] = dev(np.array([1.0 if self.contact_film else 0.0, g_lat, level], dtype=self.real))
        self._tile_cells = TILE_CELLS_CUDA if self.target.is_cuda else TILE_CELLS
        self._slabs = None
        self._rows = None           # host copy of the launch rows (tile_rows); None: to be laid out
        self._placed = self.surface is None
        self._boxes_valid = False   # box holds the cell boxes of a step taken (the active blocks of the next)
        self._fprev_valid = False   # fprev holds F_s, M_s of a step taken (eqs. 20-21)
        self._classified = False    # the refill has set the flags of every active block once (then: changed ones)
        self.iteration = 0
        log.info("coupling: %d bodies on %d blocks, buoyancy %s", self.n, fo.nblocks, self.buoyancy)

    @property
    def tile_cells(self) -> int:
        """Cells of a body's cell box per launch row (:func:`tile_rows`). The runs of each body are counted
        from its box at the first step after this is set and then kept."""
        return self._tile_cells

    @tile_cells.setter
    def tile_cells(self, value: int):
        self._tile_cells = int(value)
        self._slabs = None
        self._rows = None

    def distribute(self, decomp):
        """Run on the rank-local forest of ``decomp`` (a :class:`~iceresist.parallel.decomposition.Decomposition`,
        the forest this coupling was built on being its ``local``): the links count into the forces on the rank's
        own blocks only, F_s, M_s and the link counts are summed over the ranks after the links pass (one small
        Allreduce per step), and :meth:`state` gathers the cell owners on rank 0."""
        self.decomp = decomp
        self.nowned = int(decomp.nowned)

    def _sum_over_ranks(self):
        """F_s, M_s (n, 6) and the link counts (n,) of this rank's blocks summed over the ranks, in place (one small
        read and write per step; every rank gets the same sums, so the replicated DEM stays one)."""
        from mpi4py import MPI

        for name in ("now", "links"):
            host = np.ascontiguousarray(self.target.to_host(self._d[name]))
            total = np.empty_like(host)
            self.decomp.comm.Allreduce(host, total, op=MPI.SUM)
            copy_into(self._d[name], total)

    # ------------------------------------------------------------------ device helpers
    def _dev(self, a):
        return self.target.to_device(a)

    def _host(self, a):
        return self.target.to_host(a, copy=False)

    # ------------------------------------------------------------------ launch rows
    @property
    def _tile_body(self):
        """The body of each launch row, or None where every body is one row."""
        if self._rows is None or self._rows.shape[0] == self.n:
            return None
        return self._rows[:, 0]

    def _body_rows(self, rows_d, nrows, body, bint, box, has_prev=False):
        """Each launch row's body in lattice units and its box (``body``, ``bint``, ``box``), and ``active`` on the
        blocks its box of now and (``has_prev``) of the last step touch: one launch."""
        dem, d = self.dem, self._d
        self._s["body_rows"](nrows, rows_d, dem.device("pos"), dem.device("quat"), dem.device("vel"),
                             dem.device("omega"), d["shape_int"], d["par_lat"], d["half_lat"], d["conv"], d["grid"],
                             body, bint, box, d["box_prev"], np.int64(has_prev), d["nblocks3"], d["block_map"],
                             d["active"])

    def link_list_capacity(self) -> int:
        """Cells the CUDA link list holds (:func:`iceresist.coupling.kernels.build_link_list`): the most cells of
        the bodies' cell boxes in any orientation, each box at most 2 |h| + 5 cells along an axis (h the half
        extents in cells) and no longer than the domain; the covered cells a links pass visits are a part of them."""
        n = np.asarray(self.forest.shape_cells, dtype=np.int64)
        side = 2 * np.ceil(np.linalg.norm(self._half_lat, axis=1)).astype(np.int64) + 5
        return int(np.minimum(side[:, None], n[None, :]).prod(axis=1).sum())

    def check_link_list(self):
        """Raise where a links pass since the start found more cells than the CUDA link list holds (they were left
        out of it): cannot happen with :meth:`link_list_capacity`; the models check it once a record, with the
        watchdog's probe or the diagnostics (one read of two numbers)."""
        if not self.target.is_cuda:
            return
        over = int(self._host(self._d["ncells"])[1])
        if over:
            raise RuntimeError(f"the coupling's link list of {self.link_list_capacity()} cells overflowed by {over} "
                               "cells: their links were left out (an engine fault; please report it with the scene)")

    def _lay_out_rows(self):
        """The launch rows and the arrays sized by them; the slabs per body (where not set) from the cell boxes
        of the bodies now (one read of the boxes, at the first step or after :attr:`tile_cells` changed)."""
        n, dev, real = self.n, self._dev, self.real
        if self._slabs is None:
            ident = dev(tile_rows(np.ones(n, np.int64)))
            bint = dev(np.zeros((n, 12), np.int32))
            self._body_rows(ident, n, dev(np.zeros((n, 21), real)), bint, dev(np.zeros((n, 6), np.int64)))
            self._slabs = slab_counts(self._host(bint), self._tile_cells)
        rows = tile_rows(self._slabs)
        r = len(rows)
        order = np.argsort(rows[:, 0], kind="stable")
        ptr = np.zeros(n + 1, np.int64)
        ptr[1:] = np.cumsum(np.bincount(rows[:, 0], minlength=n))
        d = self._d
        d["rows"], d["row_ptr"], d["row_idx"] = dev(rows), dev(ptr), dev(order.astype(np.int64))
        d["body"], d["bint"] = dev(np.zeros((r, 21), real)), dev(np.zeros((r, 12), np.int32))
        d["bforce"], d["btorque"] = dev(np.zeros((r, 3))), dev(np.zeros((r, 3)))
        d["nlinks"] = dev(np.zeros((r, 1), np.int64))
        if self.target.is_cuda and "cells" not in d:
            cap = self.link_list_capacity()
            d["cells"], d["svals"] = dev(np.zeros((cap, 2), np.int32)), dev(np.zeros(cap, real))
        self._rows = rows

    # ------------------------------------------------------------------ the step
    def update_boundaries(self, sums: bool = True):
        """Passes 1-4 of a coupling step (module docstring): cells, refill, mass, links and F_s(t), M_s(t).
        ``sums=False`` (one process): the links' rows are left for :meth:`step` to sum with the fluid loads in
        one launch."""
        d, k, s, real, t = self._d, self._k, self._s, self.real, self.target
        if self._rows is None:
            self._lay_out_rows()
        rows, nb = len(self._rows), self.forest.nblocks
        d["box"], d["box_prev"] = d["box_prev"], d["box"]
        d["owner"], d["owner_prev"] = d["owner_prev"], d["owner"]
        # the step's resets in one launch: active blocks, the cells' owners now, the blocks' cover events, the
        # count of the link list (its overflow count kept)
        t.fill4(d["active"], 0, d["owner"], -1, d["evt"], 0, d["ncells"][:1], 0)
        self._body_rows(d["rows"], rows, d["body"], d["bint"], d["box"], has_prev=self._boxes_valid)
        self._boxes_valid = True
        body, bint, active = d["body"], d["bint"], d["active"]
        f, flags = self.solver.state, self.solver.flags
        listed = (d["cells"], d["svals"], d["ncells"]) if t.is_cuda else ()
        k["mark"](rows, bint, body, d["planes"], d["grid"], d["block_map"], d["flags0"], d["owner"], *listed)
        if not self._placed:        # first step with a free surface: the bodies are placed, not moved in
            t.copy(d["owner_prev"], d["owner"])
            self._placed = True
        Fx, Fy, Fz = (real(v) for v in self.solver.force)
        evt = d["evt"]
        # On the CPU the refill visits only the active blocks where a cell changed cover (a body's box holds many
        # blocks where none did: the quick hull's 1 600); on CUDA, where the step is bound by its launches, the
        # refill's threads of the other blocks return at once instead.
        visit = active
        if not t.is_cuda:
            s["changed_blocks"](nb, active, d["owner"], d["owner_prev"], np.int64(not self._classified),
                                d["changed"])
            visit = d["changed"]
        self._classified = True
        if self.surface is None:
            k["refill"](nb, visit, d["borigin"], body, d["grid"], d["block_map"], d["flags0"], flags, d["owner"],
                        d["owner_prev"], f, evt, Fx, Fy, Fz)
        else:
            phase = self.surface.phase
            phase.solid = d["owner"]
            k["refill"](nb, visit, d["borigin"], body, d["grid"], d["block_map"], d["flags0"], flags, d["owner"],
                        d["owner_prev"], f, evt, Fx, Fy, Fz, phase.phi, phase.h, phase.valid)
        s["near_events"](nb, evt, d["nbr"], d["near"])
        if self.surface is None:
            k["redistribute"](nb, d["near"], d["near"], d["borigin"], d["grid"], d["block_map"], d["flags0"],
                              d["owner"], d["owner_prev"], f)
        else:
            k["redistribute"](nb, d["near"], d["near"], d["borigin"], d["grid"], d["block_map"], d["flags0"], flags,
                              d["owner"], d["owner_prev"], f, phase.phi, phase.h, phase.valid)
        if self.debug:
            k["poison"](nb, active, d["flags0"], d["owner"], d["owner_prev"], f)
        # with a free surface the same walk mirrors phi into the covered cells near the surface
        mirror = () if self.surface is None else (self.surface.phase.phi,)
        if t.is_cuda:       # the list: a fixed number of threads striding over it
            n = min(len(d["svals"]), LIST_THREADS_SIMULATED if t.simulator else LIST_THREADS)
            walk = (n, np.int64(n), d["ncells"], d["cells"], d["svals"])
        else:
            walk = (rows,)
        k["links"](*walk, bint, body, d["planes"], d["grid"], d["block_map"], d["flags0"], d["owner"], f,
                   d["bforce"], d["btorque"], d["nlinks"], flags, d["film"], np.int64(self.nowned), *mirror)
        if not sums:
            return
        s["row_sums"](self.n, *self._row_args())
        if self.decomp is not None:
            self._sum_over_ranks()

    def _row_args(self) -> tuple:
        d = self._d
        return d["row_ptr"], d["row_idx"], d["bforce"], d["btorque"], d["nlinks"], d["now"], d["links"]

    def step(self, n: int = 1, accumulate_contacts: bool = False):
        """``n`` coupled steps: boundaries and forces, one LBM step, DEM over dt with F_fluid held (eqs. 20-21);
        ``accumulate_contacts`` is handed to :meth:`DEMSystem.step` (``accumulate``).

        The body state, the loads and the flags of the blocks to visit stay on the target: a step moves no array
        between host and device."""
        d, dem = self._d, self.dem
        one = self.decomp is None
        for _ in range(int(n)):
            # one process: the rows' sums wait for the fluid loads (one launch); several: summed over the ranks
            self.update_boundaries(sums=not one)
            if self.after_boundaries is not None:
                self.after_boundaries()
            (self.solver if self.surface is None else self.surface).step(1)
            loads = (np.int64(self._fprev_valid), d["fprev"], d["load_scale"], d["buoy"], dem.device("ext"),
                     d["fluid"], d["fluid_sum"])
            if one:
                self._s["row_loads"](self.n, *self._row_args(), *loads)
            else:
                self._s["fluid_loads"](self.n, d["now"], *loads)
            self._fprev_valid = True
            dem.external_loads_changed()
            dem.step(self.units.dt_s, accumulate=accumulate_contacts)
            self.iteration += 1

    # ------------------------------------------------------------------ results (host copies)
    def _read(self, name) -> np.ndarray:
        return np.array(self._host(self._d[name]), dtype=float)

    @property
    def force_lattice(self) -> np.ndarray:
        """F_s(t) of each body (n, 3) from the last links pass (eq. 18), lattice units."""
        return self._read("now")[:, :3]

    @property
    def torque_lattice(self) -> np.ndarray:
        """M_s(t) of each body (n, 3) about its centre of mass (eq. 19), lattice units."""
        return self._read("now")[:, 3:]

    @property
    def links(self) -> np.ndarray:
        """Boundary links of each body (n,) in the last links pass."""
        return np.array(self._host(self._d["links"]), dtype=np.int64)

    @property
    def fluid_force_N(self) -> np.ndarray:
        """F_fluid of each body (n, 3), N: the mean of F_s over the last two steps (eq. 20). With gravity in the fluid the
        hydrostatic buoyancy is part of it; the -rho_f V g added otherwise (``buoyancy``) is not."""
        return self._read("fluid")[:, :3] if self._fprev_valid else np.zeros((self.n, 3))

    @property
    def fluid_torque_N_m(self) -> np.ndarray:
        """M_fluid of each body (n, 3), N m, about its centre of mass (eq. 21)."""
        return self._read("fluid")[:, 3:] if self._fprev_valid else np.zeros((self.n, 3))

    def reset_fluid_load_sum(self):
        """Start the sum of :meth:`take_fluid_load_sum` anew, on the target."""
        self.target.fill(self._d["fluid_sum"], 0.0)

    def take_fluid_load_sum(self) -> np.ndarray:
        """F_fluid and M_fluid (n, 6), N and N m, summed over the steps since the last call, and the sum restarted
        (a record's mean with one read per record)."""
        out = self._read("fluid_sum")
        self.reset_fluid_load_sum()
        return out

    @property
    def active_blocks(self) -> int:
        """Blocks the cell boxes of the last step and the one before touch (the refill's blocks)."""
        return int(np.count_nonzero(self._host(self._d["active"])))

    @property
    def event_blocks(self) -> int:
        """Blocks with a cell covered or uncovered in the last step in their own or a neighbour block."""
        return int(np.count_nonzero(self._host(self._d["near"])))

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        """What a bit-for-bit restart of the coupling needs between two steps: the covering rows of every cell
        now and a step earlier, the slabs per body (so the rows mean the same bodies), the cell boxes of the last
        step (the active blocks), F_s and M_s of the last step (eqs. 20-21), the running sum of
        :meth:`take_fluid_load_sum` and the step count. On several ranks
        the cell owners of the whole domain in global block order, on rank 0 (None on the other ranks)."""
        d, n = self._d, self.n
        now, fluid = self._read("now"), self._read("fluid")
        owner, owner_prev = self._host(d["owner"]).copy(), self._host(d["owner_prev"]).copy()
        if self.decomp is not None:
            owner, owner_prev = self.decomp.gather_rows(owner), self.decomp.gather_rows(owner_prev)
            if owner is None:
                return None
        return {"owner": owner, "owner_prev": owner_prev,
                "slabs": np.zeros(0, np.int64) if self._slabs is None else np.asarray(self._slabs, np.int64),
                "prev_boxes": (np.array(self._host(d["box"]), np.int64) if self._boxes_valid
                               else np.zeros((0, 6), np.int64)),
                "force_prev": self._read("fprev") if self._fprev_valid else np.zeros((0, 6)),
                "force_lattice": now[:, :3].reshape(n, 3).copy(), "torque_lattice": now[:, 3:].reshape(n, 3).copy(),
                "fluid_force_N": fluid[:, :3].copy(), "fluid_torque_N_m": fluid[:, 3:].copy(),
                "fluid_load_sum": self._read("fluid_sum"),
                "placed": np.int8(self._placed), "iteration": np.int64(self.iteration)}

    def load_state(self, state: dict):
        """Continue from :meth:`state` of a coupling built the same way (same forest, bodies, tile size)."""
        missing = [k for k in ("owner", "owner_prev", "slabs", "prev_boxes", "force_prev") if k not in state]
        if missing:
            raise InputError(f"coupling state lacks {', '.join(missing)}: it was not written by "
                             "FluidStructureCoupling.state()")
        d = self._d
        owner, owner_prev = np.asarray(state["owner"]), np.asarray(state["owner_prev"])
        if self.decomp is not None:     # the whole domain's (any number of ranks wrote it): this rank's rows
            owner, owner_prev = self.decomp.local_rows(owner), self.decomp.local_rows(owner_prev)
        copy_into(d["owner"], owner.astype(np.int32))
        copy_into(d["owner_prev"], owner_prev.astype(np.int32))
        if self.surface is not None:            # the phase field's solid cells, as the last boundary pass left them
            self.surface.phase.solid = d["owner"]
        slabs = np.asarray(state["slabs"], dtype=np.int64)
        if slabs.size not in (0, self.n):
            raise InputError(f"coupling state has slabs for {slabs.size} bodies, this scene has {self.n}: "
                             "it belongs to another scene")
        self._slabs = slabs if slabs.size else None
        self._rows = None
        boxes, fprev = np.asarray(state["prev_boxes"], np.int64), np.asarray(state["force_prev"], float)
        self._boxes_valid = bool(boxes.size)
        if boxes.size:
            copy_into(d["box"], boxes)
        self._fprev_valid = bool(fprev.size)
        if fprev.size:
            copy_into(d["fprev"], fprev)
        if "force_lattice" in state and "torque_lattice" in state:
            copy_into(d["now"], np.concatenate([np.asarray(state["force_lattice"], float).reshape(self.n, 3),
                                                np.asarray(state["torque_lattice"], float).reshape(self.n, 3)], axis=1))
        if "fluid_force_N" in state and "fluid_torque_N_m" in state:
            copy_into(d["fluid"], np.concatenate([np.asarray(state["fluid_force_N"], float),
                                                  np.asarray(state["fluid_torque_N_m"], float)], axis=1))
        if "fluid_load_sum" in state:
            copy_into(d["fluid_sum"], np.asarray(state["fluid_load_sum"], float).reshape(self.n, 6))
        self._placed = bool(state["placed"])
        self.iteration = int(state["iteration"])

    # ------------------------------------------------------------------ diagnostics
    @property
    def owner_array(self):
        """The launch row covering each cell (nblocks, 512), -1 for none, where it lives (on the target): what a
        reduction on the target reads; :meth:`owners` gives the bodies on the host."""
        return self._d["owner"]

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
        return self.surface.volume()

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
