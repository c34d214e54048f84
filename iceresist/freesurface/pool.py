"""Populations only where the water is: a pool of f rows for the blocks that need them (paper section 2.2).

The cumulant LBM runs only in the liquid (phi >= 1/2); a block wholly in the gas carries the phase
field (h, phi) but no populations f. The free-surface solver therefore keeps f in a *pool* of rows
``f[row, q, cell]`` and a map ``fslot[block]`` (int32; -1 for a block that holds none). The fused
stream-collide reads f through the map (:func:`iceresist.lbm.stream.pooled_source`).

A block needs a row when it is *wet* (some cell has phi >= 1/2) or is one of the 26 neighbours of a
wet block: a liquid cell pulls from its neighbours, and a gas block next to the water is where the
water arrives next. :meth:`FPool.update` runs once per step, after the phase field moved and before
the cells are reflagged: rows of blocks no longer needed go back to the free list, blocks newly
needed take a free row, which is filled with the equilibrium at the reference density rho0 = 1 and the
extended velocity (eq. 12 with rho0, the state eq. (11) assumes for the gas side of the surface), so no
population is ever undefined. The pool holds the rows needed at the start plus a margin
(``margin`` times the wet blocks at the start); when the water needs more, the update raises
:class:`~iceresist.errors.InputError` naming ``free_surface.f_pool_margin`` and changes nothing.
``margin=None`` gives every block a row for the whole run (the full box; the map is the identity).
"""

from __future__ import annotations

import logging
import math
from functools import lru_cache

import numpy as np

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.backends.launch import CellLauncher
from iceresist.errors import InputError, StabilityError
from iceresist.freesurface import kernel_key
from iceresist.grid.forest import CELLS
from iceresist.lbm.codegen import compile_source
from iceresist.lbm.solver import CUMULANT_MODULES, collide_builder, equilibrium_minus_w
from iceresist.lbm.stream import (POOL_ARGS, POOL_U_ARGS, block_namespace, cell_device, pooled_source,
                                  stream_collide_block_source, stream_collide_source, stream_namespace)

log = logging.getLogger(__name__)

#: Default extra rows, as a fraction of the wet blocks at the start.
DEFAULT_MARGIN = 0.25


@lru_cache(maxsize=None)
def pooled_fused_launcher(target, precision: str, operator: str, velocity: bool = False) -> CellLauncher:
    """The free-surface fused stream-collide with f indexed through ``fslot`` (args ``POOL_ARGS``);
    per cell on CUDA, per block on the CPU (:func:`~iceresist.lbm.stream.stream_collide_block_source`: an
    all-liquid block gathered line by line and collided across its 512 cells, which vectorises).
    ``velocity`` (CPU only): the update also writes the velocity ``u`` of every cell (args ``POOL_U_ARGS``), which
    saves the separate pass that reads the populations again. On CUDA the fused update has no registers to spare
    for it (in float64 it spilled), so the velocity stays a pass of its own there."""
    real = jit.real_type(precision)
    collide = collide_builder(operator)(target, real)
    args = POOL_U_ARGS if velocity else POOL_ARGS
    if target.is_cuda:
        if velocity:
            raise ValueError("the CUDA f update does not write the velocity (its own pass does)")
        fn = compile_source(pooled_source(stream_collide_source(free_surface=True)),
                            "stream_collide_cell", stream_namespace(target, real, collide), cell_device(target))
        return CellLauncher(target, fn, args, label="f_update")
    key = kernel_key(target, f"f_update|{precision}|{operator}|velocity={bool(velocity)}",
                     CUMULANT_MODULES if operator == "cumulant" else ())
    # the vectorised block form: an all-liquid block gathered line by line and collided across its cells
    src = pooled_source(stream_collide_block_source(free_surface=True, velocity=velocity))
    head, body = src.split("\n", 1)
    fn = compile_source(f"{head}\n    sb = fslot[b]\n{body}", "stream_collide_block",
                        block_namespace(target, real, collide), cell_device(target))
    return CellLauncher(target, fn, args, per_block=True, label="f_update", cache_key=key)


def build_pool_cells(target, real):
    """Compile ``(wet_cell, fill_cell)``.

    * ``wet_cell(b, c, phi, wet)``: ``wet[b] = 1`` where phi >= 1/2 (``wet`` zeroed before);
    * ``fill_cell(i, c, blocks, fslot, fa, fb, u)``: both buffers of block ``blocks[i]`` get
      f - w = f^eq(1, u) - w (eq. 12 at rho0 = 1, ``u[block, 3, cell]``).
    """
    cx, cy, cz = (np.ascontiguousarray(L.C[:, a].astype(real)) for a in range(3))  # real: no float64 in fp32
    w = L.W.astype(real)
    half, c3, c45, c15 = (real(v) for v in (0.5, 3.0, 4.5, 1.5))
    int8, int64 = np.int8, np.int64
    dev = target.device

    @dev
    def wet_cell(b, c, phi, wet):
        if phi[b, c] >= half:
            wet[b] = int8(1)

    @dev
    def fill_cell(i, c, blocks, fslot, fa, fb, u):
        b = int64(blocks[i])
        s = int64(fslot[b])
        ux = u[b, 0, c]
        uy = u[b, 1, c]
        uz = u[b, 2, c]
        uu = ux * ux + uy * uy + uz * uz
        for q in range(27):
            cu = cx[q] * ux + cy[q] * uy + cz[q] * uz
            v = w[q] * (c3 * cu + c45 * cu * cu - c15 * uu)
            fa[s, q, c] = v
            fb[s, q, c] = v

    return wet_cell, fill_cell


@lru_cache(maxsize=None)
def pool_launchers(target, precision: str):
    wet, fill = build_pool_cells(target, jit.real_type(precision))
    k = kernel_key(target, f"pool|{precision}")
    return (CellLauncher(target, wet, ("phi", "wet"), label="pool_wet", cache_key=k),
            CellLauncher(target, fill, ("blocks", "fslot", "fa", "fb", "u"), label="pool_fill", cache_key=k))


def needed_blocks(wet: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """Blocks that need f: wet ones and their 26 neighbours (``nbr[block, q]``, -1 outside), bool (nblocks,)."""
    wet = np.asarray(wet, dtype=bool)
    inside = nbr >= 0
    near = np.zeros(nbr.shape, dtype=bool)
    near[inside] = wet[nbr[inside]]
    return wet | near.any(axis=1)


class FPool:
    """Host book-keeping of the pool: the map ``fslot[block]`` and the free rows (module docstring).

    ``nbr``: the forest's neighbour table ``nbr[block, q]``; ``margin``: extra rows as a fraction of the
    wet blocks when :meth:`start` sizes the pool, or None for one row per block (the full box).
    """

    def __init__(self, nbr: np.ndarray, margin: float | None = DEFAULT_MARGIN):
        if margin is not None and not margin >= 0:
            raise InputError(f"free_surface.f_pool_margin must be >= 0 (a fraction of the wet blocks), not {margin}")
        self.nbr = np.asarray(nbr, dtype=np.int64)
        self.nblocks = int(self.nbr.shape[0])
        self.margin = None if margin is None else float(margin)
        # the full box: every block its own row for good; a pool: no rows until :meth:`start` sizes it
        self.fslot = np.arange(self.nblocks, dtype=np.int32) if margin is None else np.full(self.nblocks, -1,
                                                                                             dtype=np.int32)
        self.capacity = self.nblocks if margin is None else 0
        self.grown = 0   #: times the pool had to grow during the run
        self._free: list[int] = []

    @property
    def full(self) -> bool:
        """True where every block holds a row for the whole run (``margin=None``)."""
        return self.margin is None

    @property
    def rows_in_use(self) -> int:
        return int((self.fslot >= 0).sum())

    def start(self, wet: np.ndarray) -> None:
        """Size the pool from the wet blocks at the start and give the needed blocks rows 0, 1, ... in block
        order."""
        if self.full:
            return
        need = needed_blocks(wet, self.nbr)
        n_wet = int(np.count_nonzero(wet))
        self.capacity = min(self.nblocks, int(need.sum()) + math.ceil(self.margin * n_wet))
        self.assign(need)
        log.info("f pool: %d rows for %d blocks (%d wet, %d needed)", self.capacity, self.nblocks, n_wet,
                 int(need.sum()))

    def assign(self, need: np.ndarray) -> None:
        """Rows 0, 1, ... to the blocks ``need`` (bool or block ids) in block order, none elsewhere."""
        blocks = np.flatnonzero(need) if np.asarray(need).dtype == bool else np.sort(np.asarray(need, np.int64))
        self._check(len(blocks))
        self.fslot = np.full(self.nblocks, -1, dtype=np.int32)
        self.fslot[blocks] = np.arange(len(blocks), dtype=np.int32)
        self._free = list(range(self.capacity - 1, len(blocks) - 1, -1))

    def _check(self, n: int) -> None:
        if n > self.capacity:
            raise InputError(f"free_surface.f_pool_margin: the water needs populations in {n} blocks but the "
                             f"pool holds {self.capacity} (margin {self.margin} of the wet blocks at the start); "
                             f"raise free_surface.f_pool_margin, or set it to \"full\"")

    def grow(self, n: int, n_wet: int) -> bool:
        """Make room for ``n`` needed blocks: the capacity rises to ``n`` plus the margin of the ``n_wet``
        wet blocks now (at least 1/4 of them, at most every block); the new rows join the free list.
        Returns True when the capacity changed (the caller then enlarges its buffers, keeping the rows)."""
        if n <= self.capacity:
            return False
        old = self.capacity
        self.capacity = min(self.nblocks, n + math.ceil(max(self.margin, DEFAULT_MARGIN) * n_wet))
        self._free = list(range(self.capacity - 1, old - 1, -1)) + self._free
        self.grown += 1
        log.info("f pool: grown from %d to %d rows (%d blocks need populations)", old, self.capacity, n)
        return True

    def update(self, wet: np.ndarray) -> np.ndarray:
        """Release the rows of blocks no longer needed, give rows to blocks newly needed; returns the block
        ids (int64) that took a row, whose populations the caller must fill. When the water needs more rows
        than the pool holds, the pool grows first (:meth:`grow`; the caller compares ``capacity``)."""
        if self.full:
            return np.zeros(0, dtype=np.int64)
        need = needed_blocks(wet, self.nbr)
        has = self.fslot >= 0
        release = np.flatnonzero(has & ~need)
        acquire = np.flatnonzero(need & ~has)
        self.grow(int(need.sum()), int(np.count_nonzero(wet)))
        self._free.extend(int(r) for r in self.fslot[release])
        self.fslot[release] = -1
        for b in acquire:
            self.fslot[b] = self._free.pop()
        return acquire.astype(np.int64)


class PooledLBM:
    """The free-surface LBM with its populations in a pool of rows (module docstring); the role that
    :class:`~iceresist.lbm.solver.LBMSolver` plays for a single-phase fluid.

    ``force``: the acceleration g (lattice units; the body force of a cell is rho g); ``margin``: see
    :class:`FPool`. ``state`` is the pool buffer the next step pulls from, ``f[row, q, cell]``; ``fslot``
    the map on the target; ``pool`` the host book-keeping.
    """

    def __init__(self, forest, *, tau: float, force, operator: str = "cumulant", precision: str = "float32",
                 target=jit.cpu, margin: float | None = DEFAULT_MARGIN):
        if not tau > 0.5:
            raise StabilityError(f"tau = {tau} must exceed 1/2 (lattice viscosity (tau - 1/2)/3 > 0); "
                                 "raise the viscosity or coarsen the time step")
        self.forest = forest
        self.tau = float(tau)
        self.force = tuple(float(v) for v in force)
        self.operator = operator
        self.precision = precision
        self.real = jit.real_type(precision)
        self.target = target
        self.iteration = 0
        self.cells = forest.cells
        self.pool = FPool(forest.nbr, margin)
        #: Blocks the step updates, the forest's first ones (on refined levels the leaves, not the ghost blocks,
        #: whose update no one reads: :class:`~iceresist.lbm.refinement.RefinedLBM`).
        self.active_blocks = forest.nblocks
        self._launch = pooled_fused_launcher(target, precision, operator)
        self._wet_cells, self._fill = pool_launchers(target, precision)
        real = self.real
        tables = dict(nbr_key=forest.nbr_key.astype(np.int32), link_bc=forest.link_bc.astype(np.int32),
                      flags=forest.flags.astype(np.uint8), bc_kind=forest.bc_kind.astype(np.int32),
                      bc_u=forest.bc_velocity.astype(real), bc_rho=forest.bc_density.astype(real))
        self._tables = {k: self._to_device(np.ascontiguousarray(v)) for k, v in tables.items()}
        self._scalars = (real(1.0 / self.tau), *(real(v) for v in self.force))
        self._wet = self._to_device(np.zeros(forest.nblocks, np.int8))
        self.fslot = self._to_device(self.pool.fslot.copy())
        self._f = [self._to_device(np.zeros((self.pool.capacity, L.Q, CELLS), real)) for _ in range(2)]

    def _to_device(self, a):
        return self.target.to_device(a)

    def _host(self, a) -> np.ndarray:
        return self.target.to_host(a)

    @property
    def state(self):
        """The pool buffer the next step pulls from, ``f[row, q, cell]`` (row ``fslot[block]``)."""
        return self._f[0]

    @property
    def flags(self):
        """The cell-flag table the fused kernel reads (a device array on CUDA)."""
        return self._tables["flags"]

    @property
    def allocated_bytes(self) -> int:
        """Bytes of the two population buffers (the pool rows) and the map."""
        return 2 * self.pool.capacity * L.Q * CELLS * np.dtype(self.real).itemsize + 4 * self.forest.nblocks

    # ------------------------------------------------------------------ rows
    def wet_blocks(self, phi) -> np.ndarray:
        """Host bool (nblocks,): blocks with a cell of phi >= 1/2 (``phi[block, cell]`` on the target)."""
        if self.target.is_cuda:
            self._wet.copy_to_device(np.zeros(self.forest.nblocks, np.int8))
        else:
            self._wet[:] = 0
        self._wet_cells(self.forest.nblocks, phi, self._wet)
        return self._host(self._wet).astype(bool)

    def _upload_map(self):
        if self.target.is_cuda:
            self.fslot.copy_to_device(self.pool.fslot)
        else:
            self.fslot = self.pool.fslot

    def update_rows(self, phi, u) -> int:
        """Move rows to follow the water (:meth:`FPool.update`) and fill the new ones with f^eq(1, u) - w
        (``u[block, 3, cell]``, the extended velocity); returns the number of rows taken."""
        if self.pool.full:
            return 0
        acquired = self.pool.update(self.wet_blocks(phi))
        if self.pool.capacity > self._f[0].shape[0]:
            self._enlarge(self.pool.capacity)
        self._upload_map()
        if len(acquired):
            self._fill(len(acquired), self._to_device(acquired), self.fslot, self._f[0], self._f[1], u)
        return len(acquired)

    def _enlarge(self, capacity: int):
        """Both population buffers with ``capacity`` rows, the old rows copied unchanged (a rare event:
        the water spread over more blocks than the pool's margin allowed)."""
        bufs = []
        for buf in self._f:
            old = self._host(buf)
            new = np.zeros((capacity, L.Q, CELLS), self.real)
            new[:old.shape[0]] = old
            bufs.append(self._to_device(new))
        self._f = bufs

    # ------------------------------------------------------------------ state
    def initialize(self, rho, u, wet: np.ndarray):
        """Size the pool from ``wet`` (bool per block) and set the equilibrium of the dense density ``rho``
        (nx, ny, nz) and uniform velocity ``u`` (3 numbers) in the blocks that hold a row."""
        self.pool.start(wet)
        fo = self.forest
        blocks = np.flatnonzero(self.pool.fslot >= 0)
        rho_b = fo.from_dense(np.broadcast_to(np.asarray(rho, dtype=float), fo.shape_cells))[blocks]
        ux, uy, uz = (float(v) for v in u)
        feq = equilibrium_minus_w(rho_b, ux, uy, uz).transpose(1, 0, 2)   # (blocks, 27, 512)
        feq[np.broadcast_to(~fo.fluid[blocks][:, None, :], feq.shape)] = 0.0
        host = np.zeros((self.pool.capacity, L.Q, CELLS), self.real)
        host[self.pool.fslot[blocks]] = feq
        self._f = [self._to_device(host.copy()) for _ in range(2)]
        self._upload_map()
        self.iteration = 0

    def step(self, n: int, phi, half_width, u=None):
        """Advance ``n`` fused stream-collide steps with the phase field ``phi[block, cell]`` and W / 2
        (lattice units) placing the surface inside the cell (eq. 11); the buffers swap after each. ``u``
        (``[block, 3, cell]``, optional): written with each cell's velocity j / rho - F / 2 of the new populations,
        0 outside the liquid (the CPU block form only)."""
        t = self._tables
        nb = self.active_blocks
        launch = self._launch if u is None else pooled_fused_launcher(self.target, self.precision, self.operator,
                                                                       velocity=True)
        extra = () if u is None else (u,)
        for _ in range(int(n)):
            src, dst = self._f
            launch(nb, src, dst, t["nbr_key"], t["link_bc"], t["flags"], t["bc_kind"], t["bc_u"],
                   t["bc_rho"], *self._scalars, phi, half_width, self.fslot, *extra)
            self._f = [dst, src]
            self.iteration += 1

    def synchronize(self):
        """Wait for the device (CUDA); a no-op on the CPU."""
        self.target.synchronize()

    def populations(self) -> np.ndarray:
        """Host copy of f - w per block, (nblocks, 27, 512) float64, 0 in blocks without a row."""
        return self.stored_populations().astype(np.float64)

    def stored_populations(self) -> np.ndarray:
        """f - w per block on the host in the storage precision, (nblocks, 27, 512), 0 in blocks without a row: in
        the full box on the CPU the buffer the next step pulls from itself (no copy; what a regrid carries)."""
        if self.pool.full:
            return self.target.to_host(self._f[0], copy=False)
        rows = self._host(self._f[0])
        out = np.zeros((self.forest.nblocks, L.Q, CELLS), self.real)
        has = self.pool.fslot >= 0
        out[has] = rows[self.pool.fslot[has]]
        return out

    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(block ids holding a row, their populations f - w (n, 27, 512) in storage precision): the state
        a checkpoint needs."""
        blocks = np.flatnonzero(self.pool.fslot >= 0)
        return blocks, self._host(self._f[0])[self.pool.fslot[blocks]]

    def set_rows(self, blocks: np.ndarray, f: np.ndarray, capacity: int | None = None, take: bool = False):
        """Give ``blocks`` rows (in block order) holding ``f`` (n, 27, 512) in both buffers, in a pool of
        ``capacity`` rows (default: the present size); the inverse of :meth:`rows`. ``take``: ``f`` (C-contiguous in
        the storage precision, a row for every block in order) may become a buffer itself on the CPU (a regrid's
        carried level, which no one reads after)."""
        blocks = np.asarray(blocks, dtype=np.int64)
        nb = self.forest.nblocks
        if f.shape != (len(blocks), L.Q, CELLS) or (blocks.size and (blocks.min() < 0 or blocks.max() >= nb)):
            raise InputError(f"checkpoint populations of shape {f.shape} for {len(blocks)} blocks do not fit this "
                             f"scene's {nb} blocks: it belongs to another scene")
        if self.pool.full:
            if len(blocks) != nb:
                raise InputError(f"checkpoint holds populations of {len(blocks)} blocks, this run keeps all {nb} "
                                 f"(free_surface.f_pool_margin = \"full\"): restart with the margin of the first run")
        else:
            if capacity is not None:
                self.pool.capacity = int(min(nb, capacity))
            self.pool.assign(blocks)
        slots = self.pool.fslot[blocks]
        if take and len(blocks) == self.pool.capacity and np.array_equal(slots, np.arange(len(blocks))):
            host = np.ascontiguousarray(f, dtype=self.real)
        else:
            host = np.zeros((self.pool.capacity, L.Q, CELLS), self.real)
            host[slots] = f
        self._f = [self._to_device(host), self._to_device(host.copy())]
        self._upload_map()
