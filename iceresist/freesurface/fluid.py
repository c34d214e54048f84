"""The free-surface fluid: cumulant LBM in the liquid, phase field for the surface (paper section 2.2).

One time step (:meth:`FreeSurfaceFluid.step`):

1. fused stream-collide of the liquid (phi >= 1/2) with the body force rho g;
   populations pulled from a GAS cell follow eq. (11) with the hydrostatic density of the
   link midpoint below the sub-cell phi = 1/2 surface (:mod:`iceresist.lbm.stream`,
   ``free_surface=True``); gas cells are skipped like solids;
2. liquid velocity u = (sum c f* ) / rho - g / 2 (half-force shift), on the CPU written by the fused
   update of step 1 as it writes the populations, extended into the gas layer by layer
   (:mod:`iceresist.freesurface.extension`);
3. one step of the conservative Allen-Cahn LBM advected by that velocity (eqs. 4-10,
   :class:`~iceresist.freesurface.phasefield.PhaseField`);
4. move the population rows to follow the water (:mod:`iceresist.freesurface.pool`: blocks wholly
   in the gas and not next to the water hold no f);
5. reflag from the new phi: GAS where phi < 1/2 (the FLUID bit cleared), NEAR_SURFACE
   on liquid cells with a gas neighbour, the wall flags of the forest kept; a cell a moving body covers
   (GHOST, set by :mod:`iceresist.coupling`) stays GHOST until the coupling uncovers it. A cell
   turning from gas to liquid has no populations: it gets the equilibrium (eq. 12) at
   the extended velocity and the hydrostatic density 1 + 3 g s below the surface,
   s = (W / 2) artanh(2 phi - 1), the same rule step 1 applies at the link midpoints.

All-liquid cells keep the short path of the fused kernel.
"""

from __future__ import annotations

import logging
import math
from functools import lru_cache

import numpy as np

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.backends.launch import BlockLauncher, CellLauncher, copy_into
from iceresist.errors import InputError
from iceresist.freesurface import kernel_key
from iceresist.freesurface.bulk import FrozenBulk
from iceresist.freesurface.columns import SurfaceColumns
from iceresist.freesurface.extension import build_extension_cell, extend_velocity, extension_launcher
from iceresist.freesurface.layout import HALO1_SIDE, HAS_GAS, HAS_LIQUID, build_halo_or, build_neighbour
from iceresist.freesurface.phasefield import PhaseField
from iceresist.freesurface.pool import DEFAULT_MARGIN, PooledLBM
from iceresist.freesurface.probe import FluidProbe
from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.lbm.stream import TANH_CLIP

log = logging.getLogger(__name__)

cuda = jit.cuda_api()   # cuda.syncthreads_or in the CUDA block phases (a module global, for the simulator)



def build_surface_cells(target, real):
    """Compile ``(velocity_cell, reflag_cell, turn_liquid)``.

    * ``velocity_cell(b, c, f, fslot, flags, u, gx, gy, gz)``: u of a liquid cell from its post-collision
      populations f - w (pool row ``fslot[b]``) with the half-force shift of the force rho g removed;
      0 elsewhere;
    * ``reflag_cell(b, c, phi, base, flags, f, fslot, u, nbr, g, half_width, near)``: the flags of step 5 (module
      docstring), GHOST cells left as they are; in a block with no gas in reach (``near[b]`` without
      :data:`HAS_GAS`, :func:`build_block_phases`) a liquid cell has no gas neighbour and was not gas, so it
      takes its base flags without looking at its neighbours; a cell turning liquid gets f - w = f^eq(rho, u) - w with the hydrostatic
      rho = 1 + 3 g s, s = (W / 2) artanh(2 phi - 1) its depth below the phi = 1/2 surface (the rule
      of the link density in :func:`iceresist.lbm.stream.stream_collide_source`);
    * ``turn_liquid(b, c, phi, f, fslot, u, g, half_width)``: that equilibrium, written into the cell's row.
    """
    neighbour, _ = build_neighbour(target)
    cx, cy, cz = (np.ascontiguousarray(L.C[:, a]) for a in range(3))  # int64: neighbour offsets
    ex, ey, ez = (np.ascontiguousarray(L.C[:, a].astype(real)) for a in range(3))  # real: c_q . (...) sums
    w = L.W.astype(real)
    zero, one, half, two, c3, c45, c15 = (real(v) for v in (0.0, 1.0, 0.5, 2.0, 3.0, 4.5, 1.5))
    tclip = real(TANH_CLIP)
    fluid, gas, near_surface, ghost = (np.uint8(FL.FLUID), np.uint8(FL.GAS), np.uint8(FL.NEAR_SURFACE),
                                       np.uint8(FL.GHOST))
    int64 = np.int64
    has_gas = np.int8(HAS_GAS)
    dev = target.device

    @dev
    def velocity_cell(b, c, f, fslot, flags, u, gx, gy, gz):
        b = int64(b)
        if flags[b, c] & fluid:
            s = int64(fslot[b])
            rho = one
            jx = zero
            jy = zero
            jz = zero
            for q in range(27):
                fq = f[s, q, c]
                rho += fq
                jx += ex[q] * fq
                jy += ey[q] * fq
                jz += ez[q] * fq
            u[b, 0, c] = jx / rho - half * gx
            u[b, 1, c] = jy / rho - half * gy
            u[b, 2, c] = jz / rho - half * gz
        else:
            u[b, 0, c] = zero
            u[b, 1, c] = zero
            u[b, 2, c] = zero

    @dev
    def turn_liquid(b, c, phi, f, fslot, u, g, half_width):
        """Gas -> liquid: f - w = f^eq(rho, u) - w at the hydrostatic density below the surface and the extended
        velocity."""
        ux = u[b, 0, c]
        uy = u[b, 1, c]
        uz = u[b, 2, c]
        uu = ux * ux + uy * uy + uz * uz
        s = int64(fslot[b])
        t = min(two * phi[b, c] - one, tclip)
        drho = c3 * g * half_width * math.atanh(t)
        for q in range(27):
            cu = ex[q] * ux + ey[q] * uy + ez[q] * uz
            f[s, q, c] = w[q] * (drho + (one + drho) * (c3 * cu + c45 * cu * cu - c15 * uu))

    @dev
    def reflag_cell(b, c, phi, base, flags, f, fslot, u, nbr, g, half_width, near):
        b = int64(b)
        if flags[b, c] & ghost:
            return  # covered by a body: the coupling owns the cell (it is not water whatever phi says)
        bf = base[b, c]
        if (bf & fluid) == 0 or (near[b] & has_gas) == 0:
            flags[b, c] = bf
            return
        if phi[b, c] < half:
            flags[b, c] = gas
            return
        if flags[b, c] & gas:
            turn_liquid(b, c, phi, f, fslot, u, g, half_width)
        z = c // 64
        y = (c // 8) % 8
        x = c % 8
        near = False
        for q in range(1, 27):
            bn, cn = neighbour(nbr, b, x, y, z, cx[q], cy[q], cz[q])
            if bn >= 0:
                if (base[bn, cn] & fluid) and phi[bn, cn] < half:
                    near = True
        if near:
            flags[b, c] = bf | near_surface
        else:
            flags[b, c] = bf

    return velocity_cell, reflag_cell, turn_liquid




def build_block_phases(target, real):
    """Compile ``(phases_block, near_block)``, per-block passes that let the surface passes skip the blocks far
    from the surface (71 % of the blocks of the quick tier-2 case lie wholly in the water):

    * ``phases_block(b, phi, flags, phases)``: ``phases[b]`` = :data:`HAS_GAS` if a cell of b has phi < 1/2 or
      the GAS flag, | :data:`HAS_LIQUID` if a cell has phi >= 1/2;
    * ``near_block(b, phases, nbr, near)``: ``near[b]`` = the bits of b and of its 26 neighbour blocks (every
      cell a surface pass of b reads, at most 3 cells away, lies in them).
    """
    half = real(0.5)
    gas = np.uint8(FL.GAS)
    has_gas, has_liquid, none = np.int8(HAS_GAS), np.int8(HAS_LIQUID), np.int8(0)
    int64 = np.int64

    def phases_block(b, phi, flags, phases):
        b = int64(b)
        m = none
        for c in range(CELLS):
            if phi[b, c] >= half:
                m |= has_liquid
            else:
                m |= has_gas
            if flags[b, c] & gas:
                m |= has_gas
        phases[b] = m

    def near_block(b, phases, nbr, near):
        b = int64(b)
        m = phases[b]
        for q in range(1, 27):
            bn = nbr[b, q]
            if bn >= 0:
                m |= phases[bn]
        near[b] = m

    return target.device(phases_block), target.device(near_block)


def build_phases_cell(target, real):
    """CUDA: ``phases_cell(b, c, phi, flags, phases)``, ``phases_block`` with a thread per cell: the block's 512
    threads OR their cell's bits together (``cuda.syncthreads_or``) and thread 0 writes ``phases[b]``; every thread
    of the block must call it (a cell launcher does)."""
    half = real(0.5)
    gas = np.uint8(FL.GAS)
    has_gas, has_liquid, none = np.int8(HAS_GAS), np.int8(HAS_LIQUID), np.int8(0)
    int64 = np.int64

    def phases_cell(b, c, phi, flags, phases):
        b = int64(b)
        liquid = phi[b, c] >= half
        any_liquid = cuda.syncthreads_or(1 if liquid else 0)
        any_gas = cuda.syncthreads_or(1 if (not liquid or (flags[b, c] & gas) != 0) else 0)
        if c == 0:
            m = none
            if any_liquid:
                m |= has_liquid
            if any_gas:
                m |= has_gas
            phases[b] = m

    return target.device(phases_cell)


@lru_cache(maxsize=None)
def block_phase_launchers(target, precision: str):
    """``(phases, near)`` launchers of :func:`build_block_phases`; on CUDA the phases with a thread per cell
    (:func:`build_phases_cell`), not a thread walking a block's 512 cells."""
    real = jit.real_type(precision)
    phases, near = build_block_phases(target, real)
    k = kernel_key(target, f"block_phases|{precision}")
    phases_launch = (CellLauncher(target, build_phases_cell(target, real), ("phi", "flags", "phases"),
                                  label="block_phases") if target.is_cuda else
                     BlockLauncher(target, phases, ("phi", "flags", "phases"), label="block_phases", cache_key=k))
    return (phases_launch,
            BlockLauncher(target, near, ("phases", "nbr", "near"), label="block_phases_near", cache_key=k))


def build_velocity_block(real):
    """Compile the CPU block form ``velocity_block(b, f, fslot, flags, u, gx, gy, gz)`` of ``velocity_cell``
    (:func:`build_surface_cells`): the sums over the 27 populations run across the 512 cells of the block at once
    (vectorised), each cell's in the order of the cell form, so u is the same bit for bit (a product c_q f_q
    with c_q in {-1, 0, 1} is exact; the zero terms are left out)."""
    e = np.ascontiguousarray(L.C.T.astype(np.int64))       # e[a, q]: component a of c_q
    zero, one, half = real(0.0), real(1.0), real(0.5)
    fluid = np.uint8(FL.FLUID)
    int64 = np.int64

    def velocity_block(b, f, fslot, flags, u, gx, gy, gz):
        b = int64(b)
        s = int64(fslot[b])
        if s < 0:       # no population row: no liquid cell in the block
            for a in range(3):
                for c in range(CELLS):
                    u[b, a, c] = zero
            return
        rho = np.empty(CELLS, real)
        j = np.empty((3, CELLS), real)
        for c in range(CELLS):
            rho[c] = one
        for a in range(3):
            for c in range(CELLS):
                j[a, c] = zero
        for q in range(27):
            for c in range(CELLS):
                rho[c] += f[s, q, c]
            for a in range(3):
                if e[a, q] > 0:
                    for c in range(CELLS):
                        j[a, c] += f[s, q, c]
                elif e[a, q] < 0:
                    for c in range(CELLS):
                        j[a, c] -= f[s, q, c]
        for c in range(CELLS):
            if flags[b, c] & fluid:
                u[b, 0, c] = j[0, c] / rho[c] - half * gx
                u[b, 1, c] = j[1, c] / rho[c] - half * gy
                u[b, 2, c] = j[2, c] / rho[c] - half * gz
            else:
                u[b, 0, c] = zero
                u[b, 1, c] = zero
                u[b, 2, c] = zero

    return jit.cpu.device(velocity_block)


def build_reflag_block(real, turn_liquid):
    """Compile the CPU block form ``reflag_block(b, phi, base, flags, f, fslot, u, nbr, g, half_width, near)`` of
    ``reflag_cell`` (:func:`build_surface_cells`): the same flags and the same populations of cells turning liquid,
    cell by cell. A block with gas in reach copies the gas mask ((base & FLUID) and phi < 1/2) of itself and a
    halo of one cell into a 10^3 scratch row by row (three runs per row, one block look-up each; outside the
    domain: no gas), ORs it over the 26 neighbour offsets across the 512 cells (vectorised), then sets each cell's
    flags as the cell form does."""
    neighbour, _ = build_neighbour(jit.cpu)
    half = real(0.5)
    fluid, gas, near_surface, ghost = (np.uint8(FL.FLUID), np.uint8(FL.GAS), np.uint8(FL.NEAR_SURFACE),
                                       np.uint8(FL.GHOST))
    int64, int8 = np.int64, np.int8
    has_gas = np.int8(HAS_GAS)
    side = HALO1_SIDE
    halo_or = build_halo_or()

    def reflag_block(b, phi, base, flags, f, fslot, u, nbr, g, half_width, near):
        b = int64(b)
        if (near[b] & has_gas) == 0:        # no gas in reach: every cell takes its base flags (GHOST kept)
            for c in range(CELLS):
                if (flags[b, c] & ghost) == 0:
                    flags[b, c] = base[b, c]
            return
        gm = np.empty(side ** 3, int8)
        for pz in range(side):
            for py in range(side):
                row = 1 + side * (py + side * pz)   # scratch index of the row's cell x = 0
                for run in range(3):
                    if run == 0:
                        bn, cn = neighbour(nbr, b, 0, py - 1, pz - 1, -1, 0, 0)
                        x0 = -1
                        n = 1
                    elif run == 1:
                        bn, cn = neighbour(nbr, b, 0, py - 1, pz - 1, 0, 0, 0)
                        x0 = 0
                        n = 8
                    else:
                        bn, cn = neighbour(nbr, b, 8, py - 1, pz - 1, 0, 0, 0)
                        x0 = 8
                        n = 1
                    if bn >= 0:
                        for x in range(n):
                            gm[row + x0 + x] = int8(1) if ((base[bn, cn + x] & fluid) != 0
                                                           and phi[bn, cn + x] < half) else int8(0)
                    else:
                        for x in range(n):
                            gm[row + x0 + x] = int8(0)
        nm = np.empty(CELLS, int8)
        halo_or(gm, nm)
        for c in range(CELLS):
            fl = flags[b, c]
            if fl & ghost:
                continue    # covered by a body: the coupling owns the cell
            bf = base[b, c]
            if (bf & fluid) == 0:
                flags[b, c] = bf
                continue
            if phi[b, c] < half:
                flags[b, c] = gas
                continue
            if fl & gas:
                turn_liquid(b, c, phi, f, fslot, u, g, half_width)
            flags[b, c] = bf | near_surface if nm[c] else bf

    return jit.cpu.device(reflag_block)


@lru_cache(maxsize=None)
def surface_launchers(target, precision: str, vector: bool = True):
    """``(velocity, reflag)`` launchers; on the CPU in their block forms (:func:`build_velocity_block`,
    :func:`build_reflag_block`) unless ``vector=False``."""
    real = jit.real_type(precision)
    vel, reflag, turn_liquid = build_surface_cells(target, real)
    vel_args = ("f", "fslot", "flags", "u", "gx", "gy", "gz")
    reflag_args = ("phi", "base", "flags", "f", "fslot", "u", "nbr", "g", "half_width", "near")
    k = kernel_key(target, f"surface|{precision}|vector={bool(vector)}")
    if vector and not target.is_cuda:
        return (CellLauncher(target, build_velocity_block(real), vel_args, per_block=True, label="velocity",
                             cache_key=k),
                CellLauncher(target, build_reflag_block(real, turn_liquid), reflag_args, per_block=True,
                             label="reflag", cache_key=k))
    return (CellLauncher(target, vel, vel_args, label="velocity", cache_key=k),
            CellLauncher(target, reflag, reflag_args, label="reflag", cache_key=k))


@lru_cache(maxsize=None)
def velocity_layer0_launcher(target, precision: str) -> CellLauncher:
    """CUDA: the velocity pass and the velocity extension's layer 0 in one launch, ``velocity_cell`` then
    ``extend_cell(..., layer=0, ...)`` of :mod:`iceresist.freesurface.extension` on each cell (both read and write
    the cell alone): args ``(f, fslot, flags, u, gx, gy, gz, phi, dist, nbr, near)``."""
    real = jit.real_type(precision)
    vel, _, _ = build_surface_cells(target, real)
    extend_cell = build_extension_cell(target, real)
    layer0 = np.int64(0)

    def velocity_layer0(b, c, f, fslot, flags, u, gx, gy, gz, phi, dist, nbr, near):
        vel(b, c, f, fslot, flags, u, gx, gy, gz)
        extend_cell(b, c, phi, u, dist, nbr, layer0, near)

    return CellLauncher(target, target.device(velocity_layer0),
                        ("f", "fslot", "flags", "u", "gx", "gy", "gz", "phi", "dist", "nbr", "near"), label="velocity")


class FreeSurfaceFluid:
    """Liquid with a free surface under gravity on a :class:`~iceresist.grid.BlockForest` (paper section 2.2).

    ``tau``: relaxation time of the liquid (lattice units); ``gravity_lattice``: g (lattice units,
    acting along -z); ``depth_cells``: still-water level z_s (cells from the bottom of the domain;
    the cell k spans k..k+1); ``mobility``, ``width``, ``h_lattice``: the phase field (eqs. 9-10);
    ``operator``, ``precision``, ``target`` as in :class:`~iceresist.lbm.solver.LBMSolver`;
    ``f_pool_margin``: spare population rows as a fraction of the wet blocks at the start, or None for
    populations in every block (:mod:`iceresist.freesurface.pool`). ``fluid`` is the
    :class:`~iceresist.freesurface.pool.PooledLBM`; its ``fslot`` maps a block to its row of ``fluid.state``.
    ``frozen_bulk``: the phase field runs only in the blocks that reach the interface
    (:mod:`iceresist.freesurface.bulk`); False runs it in every block.
    """

    def __init__(self, forest, *, tau: float, gravity_lattice: float, depth_cells: float, mobility: float = 0.05,
                 width: float = 3.0, h_lattice: str = "D3Q15", operator: str = "cumulant",
                 precision: str = "float32", target=jit.cpu, f_pool_margin: float | None = DEFAULT_MARGIN,
                 frozen_bulk: bool = True):
        if not gravity_lattice >= 0:
            raise InputError(f"free_surface.gravity_lattice must be >= 0 (lattice units), not {gravity_lattice}")
        if not 0 < depth_cells < forest.shape_cells[2]:
            raise InputError(f"free_surface.depth_cells must lie inside the domain (0, {forest.shape_cells[2]}), "
                             f"not {depth_cells}")
        self.forest = forest
        self.g = float(gravity_lattice)
        self.depth = float(depth_cells)
        self.target = target
        self.real = jit.real_type(precision)
        self.fluid = PooledLBM(forest, tau=tau, force=(0.0, 0.0, -self.g), operator=operator, precision=precision,
                               target=target, margin=f_pool_margin)
        self.phase = PhaseField(forest, mobility=mobility, width=width, h_lattice=h_lattice, precision=precision,
                                target=target)
        self._vel, self._reflag = surface_launchers(target, precision)
        self._ext = extension_launcher(target, precision)
        self._vel0 = velocity_layer0_launcher(target, precision) if target.is_cuda else None
        self.nblocks = forest.nblocks
        self._base = self._to_target(np.ascontiguousarray(forest.flags.astype(np.uint8)))
        self._u = self._to_target(np.zeros((self.nblocks, 3, CELLS), self.real))
        self._dist = self._to_target(np.zeros((self.nblocks, CELLS), np.int8))
        self._phases_launch, self._near_launch = block_phase_launchers(target, precision)
        self._phases = self._to_target(np.zeros(self.nblocks, np.int8))
        self._near = self._to_target(np.zeros(self.nblocks, np.int8))
        self._probe = None  # the watchdog's FluidProbe, made at the first probe()
        self._columns = None  # the surface height map's SurfaceColumns, made at the first surface_height()
        self._bulk = (FrozenBulk(self.phase, exchange=self._exchange_blocks, split=lambda: self.decomp is not None)
                      if frozen_bulk else None)
        #: The :class:`~iceresist.parallel.decomposition.Decomposition` of a fluid split over MPI ranks (set by its
        #: owner), or None. On several ranks the dense views (:meth:`phi`, :meth:`macroscopic`, :meth:`velocity`,
        #: :meth:`liquid`, :meth:`surface_height`) are the whole domain's on rank 0 and None on the other ranks
        #: (every rank must call them), and :meth:`volume` and :meth:`probe` are the whole domain's on every rank.
        self.decomp = None
        self.iteration = 0

    def _to_target(self, a):
        return self.target.to_device(a)

    def _host(self, a) -> np.ndarray:
        return self.target.to_host(a)

    def dense(self, per_block: np.ndarray, axis: int = 0):
        """Dense array of a per-block array (blocks along ``axis``): the whole domain gathered on rank 0 where the
        fluid is split over ranks (None on the others)."""
        if self.decomp is None:
            return self.forest.to_dense(per_block)
        whole = self.decomp.gather_rows(per_block, axis=axis)
        return None if whole is None else self.decomp.forest.to_dense(whole)

    # ------------------------------------------------------------------ state
    def initialize(self, surface=None, u=(0.0, 0.0, 0.0)):
        """Still water in hydrostatic balance under the surface z_s(x, y) (``surface``: dense (nx, ny) heights in
        cells, default the flat ``depth_cells``), moving with the uniform velocity ``u`` (lattice units).

        phi = 1/2 + 1/2 tanh(2 (z_s - z) / W) (the profile of eq. 4), z the cell centre;
        rho = exp(3 g (z_s - z)), the solution of c_s^2 d(rho)/dz = -rho g (equal to
        1 + 3 g (z_s - z) to first order), rho = 1 at the surface, the gas density rho0 of eq. (11).
        """
        nx, ny, nz = self.forest.shape_cells
        zs = np.full((nx, ny), self.depth) if surface is None else np.asarray(surface, dtype=float)
        if zs.shape != (nx, ny):
            raise InputError(f"surface must be an array of shape ({nx}, {ny}) (heights in cells), got {zs.shape}")
        z = np.arange(nz) + 0.5
        s = zs[:, :, None] - z[None, None, :]
        phi = 0.5 + 0.5 * np.tanh(2.0 * s / self.phase.width)
        rho = np.exp(3.0 * self.g * np.maximum(s, 0.0))
        phi_b = np.ascontiguousarray(self.forest.from_dense(phi), dtype=self.real)
        self.fluid.initialize(rho, tuple(float(v) for v in u), wet=(phi_b >= self.real(0.5)).any(axis=1))
        # flags from phi (the forest's flags carry no GAS bit yet: no cell counts as newly liquid)
        phi_t = self._to_target(phi_b)
        self._reflag(self.nblocks, phi_t, self._base, self.fluid.flags, self.fluid.state, self.fluid.fslot, self._u,
                     self.phase.nbr, *self._surface_scalars(), self._block_phases(phi_t))
        self._velocity()
        self.phase.initialize(phi_b, self._u)
        self.iteration = 0

    def _velocity(self):
        """The liquid's velocity from the populations, then extended into the gas."""
        self._extend(self._velocity_pass())

    def _velocity_pass(self) -> int:
        """The liquid's velocity ``_u`` from the populations by a pass of its own (0 outside the liquid); on CUDA
        with the extension's layer 0 in the same launch (where it covers every block). Returns the first layer of
        the extension still to run."""
        g, zero = self.real(self.g), self.real(0.0)
        f, fslot, flags = self.fluid.state, self.fluid.fslot, self.fluid.flags
        if self._vel0 is not None and self.fluid.active_blocks == self.nblocks:
            self._vel0(self.nblocks, f, fslot, flags, self._u, zero, zero, -g, self.phase.phi, self._dist,
                       self.phase.nbr, self._near)
            return 1
        self._vel(self.fluid.active_blocks, f, fslot, flags, self._u, zero, zero, -g)
        return 0

    def _extend(self, first_layer: int = 0):
        """The liquid's velocity ``_u`` extended into the gas near the surface from layer ``first_layer`` on
        (:mod:`~iceresist.freesurface.extension`)."""
        extend_velocity(self._ext, self.nblocks, self.phase.phi, self._u, self._dist, self.phase.nbr,
                        near=self._block_phases(self.phase.phi), first=first_layer)

    def _exchange_blocks(self, per_block):
        """On several ranks: the halo blocks of a per-block int8 array on the target take their owners' values."""
        if self.decomp is not None:
            self.decomp.exchange(per_block.reshape(-1, 1), self.target, full=True)

    def _block_phases(self, phi):
        """``near`` per block (:func:`build_block_phases`) from ``phi`` and the current flags, on the target."""
        self._phases_launch(self.nblocks, phi, self.fluid.flags, self._phases)
        self._near_launch(self.nblocks, self._phases, self.phase.nbr, self._near)
        return self._near

    def _surface_scalars(self):
        """(g, W / 2) in the real type: the inputs of the sub-cell surface density."""
        return self.real(self.g), self.real(0.5 * self.phase.width)

    def _stream_collide(self) -> int:
        """Steps 1-2: the fused update of the liquid with the current phi, the buffers swapped, and the liquid's
        velocity ``_u`` from the new populations: on the CPU written by the update itself (``POOL_U_ARGS``), on
        CUDA by a pass of its own (with the extension's layer 0). Returns the first extension layer to run."""
        half_width = self.real(0.5 * self.phase.width)
        if self.target.is_cuda:
            self.fluid.step(1, self.phase.phi, half_width)
            return self._velocity_pass()
        self.fluid.step(1, self.phase.phi, half_width, u=self._u)
        return 0

    def step(self, n: int = 1):
        """Advance ``n`` time steps (module docstring, steps 1-5)."""
        for _ in range(int(n)):
            self._extend(self._stream_collide())
            if self._bulk is None:
                self.phase.step(self._u)
            else:
                self._bulk.step(self._u, self._near)   # _near: the phase bits _extend() just found
            self.fluid.update_rows(self.phase.phi, self._u)
            self._reflag(self.nblocks, self.phase.phi, self._base, self.fluid.flags, self.fluid.state,
                         self.fluid.fslot, self._u, self.phase.nbr, *self._surface_scalars(),
                         self._block_phases(self.phase.phi))
            self.iteration += 1

    # ------------------------------------------------------------------ diagnostics
    def allocated_bytes(self) -> dict[str, int]:
        """Bytes of the state arrays by part: ``f`` (the population pool, both buffers, and its map),
        ``phase`` (h, both buffers, and phi, every block), ``other`` (velocity, flags, work arrays)."""
        item = np.dtype(self.real).itemsize
        nb = self.nblocks
        return {"f": int(self.fluid.allocated_bytes),
                "phase": int(nb * CELLS * item * (2 * self.phase.lat.q + 1)),
                "other": int(nb * CELLS * (3 * item + 1 + 1 + 1) + nb),
                }

    @property
    def halo_state(self) -> tuple:
        """The arrays a halo block takes whole from its owner on another rank (per block: the populations, h, phi,
        the cell flags), in the order every rank sends them."""
        return self.fluid.state, self.phase.h, self.phase.phi, self.fluid.flags

    def phi(self) -> np.ndarray:
        """Dense phi (nx, ny, nz), float64."""
        return self.dense(self.phase.phi_host().astype(np.float64))

    def state(self, populations: bool = True) -> dict:
        """Everything a bit-for-bit restart of the fluid needs, in storage precision: the population rows and
        their blocks, h, phi, the cell flags (GHOST marks of bodies included) and the iteration. On several ranks
        the whole domain in global block order, every block with its populations, on rank 0 (None on the others),
        so that a checkpoint restarts on any number of ranks. ``populations`` False: the phase field, flags and
        iteration alone (what a regrid carries besides the populations it takes level by level)."""
        h, phi, flags = self._host(self.phase.h), self._host(self.phase.phi), np.asarray(self._host(self.fluid.flags))
        valid = np.asarray(self._host(self.phase.valid))
        if not populations:
            if self.decomp is not None:
                h, phi, valid, flags = (self.decomp.gather_rows(a) for a in (h, phi, valid, flags))
                if h is None:
                    return None
            return {"h": h, "phi": phi, "h_valid": valid, "flags": flags, "iteration": np.int64(self.iteration)}
        blocks, f = self.fluid.rows()
        if self.decomp is None:
            return {"f_blocks": blocks.astype(np.int64), "f": f, "f_rows": np.int64(self.fluid.pool.capacity),
                    "h": h, "phi": phi, "h_valid": valid, "flags": flags, "iteration": np.int64(self.iteration)}
        d = self.decomp
        # every block holds a row: block order
        f, h, phi, valid, flags = (d.gather_rows(a) for a in (f, h, phi, valid, flags))
        if f is None:
            return None
        n = d.forest.nblocks
        return {"f_blocks": np.arange(n, dtype=np.int64), "f": f, "f_rows": np.int64(n), "h": h, "phi": phi,
                "h_valid": valid, "flags": flags, "iteration": np.int64(self.iteration)}

    def load_state(self, state: dict, take: bool = False):
        """Continue from :meth:`state` of a fluid built the same way (same forest, h lattice, precision); ``take``:
        its populations may become the fluid's buffer (:meth:`PooledLBM.set_rows`; a regrid's carried level)."""
        if "h" not in state or "f_blocks" not in state:
            raise InputError("checkpoint holds no free-surface state: it belongs to another scene")
        # h holds the state of every block in a checkpoint written before the frozen bulk
        state = {**state, "h_valid": np.asarray(state.get("h_valid", np.ones(len(state["h"]), np.int8)))}
        if self.decomp is not None:     # the whole domain's (written on any number of ranks): this rank's blocks
            d, n = self.decomp, self.decomp.forest.nblocks
            f_blocks, f = np.asarray(state["f_blocks"]), np.asarray(state["f"])
            if f.shape[0] != len(f_blocks) or (len(f_blocks) and f_blocks.max() >= n):
                raise InputError("checkpoint populations do not fit this scene's blocks: it belongs to another scene")
            whole = np.zeros((n,) + f.shape[1:], dtype=f.dtype)      # blocks without a row lie in the gas
            whole[f_blocks] = f
            nl = len(d.global_ids)
            state = {**state, "f_blocks": np.arange(nl, dtype=np.int64), "f": d.local_rows(whole),
                     "f_rows": np.int64(nl), **{k: d.local_rows(np.asarray(state[k])) for k in ("h", "phi", "h_valid", "flags")}}
        self.load_rows(state, take)

    def load_rows(self, state: dict, take: bool = False):
        """:meth:`load_state` of this process's own blocks (on several ranks its share, as the rows are here)."""
        h = np.asarray(state["h"])
        if h.shape != tuple(self.phase.h.shape):
            raise InputError(f"checkpoint phase field has shape {h.shape}, this scene needs "
                             f"{tuple(self.phase.h.shape)}: it belongs to another scene (or another "
                             f"free_surface.h_lattice)")
        self.fluid.set_rows(np.asarray(state["f_blocks"]), np.asarray(state["f"]).astype(self.real, copy=False),
                            int(state["f_rows"]), take=take)
        copy_into(self.phase.h, h.astype(self.real, copy=False))
        copy_into(self.phase.phi, np.asarray(state["phi"]).astype(self.real, copy=False))
        copy_into(self.phase.valid, np.asarray(state["h_valid"]).astype(np.int8, copy=False))
        copy_into(self.fluid.flags, np.asarray(state["flags"]).astype(np.uint8, copy=False))
        self.iteration = self.fluid.iteration = int(state["iteration"])

    def volume(self) -> float:
        """Water volume sum phi (cells^3, the quantity eqs. 4-10 conserve), float64: per-block sums on the target,
        added up in global block order (the same sum on any number of ranks)."""
        per_block = self.phase.volume_per_block()
        if self.decomp is None:
            return float(per_block.sum())
        whole = self.decomp.gather_rows(per_block)
        return self.decomp.bcast(None if whole is None else float(whole.sum()))

    def macroscopic(self):
        """Density (nx, ny, nz) and velocity (3, nx, ny, nz) of the liquid, lattice units, float64, NaN in gas
        and solid."""
        f = self.fluid.populations()
        rho = 1.0 + f.sum(axis=1)
        j = np.einsum("qa,bqc->abc", L.C.astype(np.float64), f)
        u = j / rho
        u[2] += 0.5 * self.g
        liquid = (self._host(self.fluid.flags) & FL.FLUID) != 0
        rho[~liquid] = np.nan
        u[:, ~liquid] = np.nan
        rho, u = self.dense(rho), self.dense(u, axis=1)
        return (None, None) if rho is None else (rho, u)

    def probe(self, full: bool, kinetic_energy_ref: float = 0.0) -> dict:
        """The watchdog's quantities (:mod:`iceresist.freesurface.probe`), reduced per block on the target: phi
        finite, the liquid's velocity finite and its fastest cell; ``full``: from the populations, with the
        density band and the kinetic energy (lattice units). The same dict as
        :func:`iceresist.models.probe.fluid_probe` on :meth:`macroscopic` (``full``) or
        :func:`iceresist.models.probe.fluid_speed_probe` on :meth:`velocity`."""
        if self._probe is None:
            self._probe = FluidProbe(self.forest, self.target, self.decomp)
        return self._probe.probe(self.fluid.state, self.fluid.fslot, self.fluid.flags, self._u, self.phase.phi,
                                 full, 0.5 * self.g, kinetic_energy_ref)

    def velocity(self) -> np.ndarray:
        """Velocity (3, nx, ny, nz) of the last step, lattice units, float64, NaN in gas and solid: the field the
        step computed for the phase field (j / rho + g / 2, as :meth:`macroscopic`), read without the populations."""
        u = self._host(self._u).astype(np.float64).transpose(1, 0, 2)
        u[:, (self._host(self.fluid.flags) & FL.FLUID) == 0] = np.nan
        return self.dense(u, axis=1)

    def liquid(self) -> np.ndarray:
        """Dense mask (nx, ny, nz) of the liquid cells (flag FLUID; a cell a body covers is GHOST, not liquid)."""
        mask = self.dense(((self._host(self.fluid.flags) & FL.FLUID) != 0).astype(np.float64))
        return None if mask is None else np.nan_to_num(mask, nan=0.0) > 0.5

    def surface_height(self, covered_as_water: bool = False) -> np.ndarray:
        """Height z where phi crosses 1/2 in each column (nx, ny), cells, by linear interpolation (the
        top-most crossing); NaN in a column with no crossing (all water or all gas). ``covered_as_water``: a cell
        a body covers (GHOST) counts as phi = 1, so the surface runs over the top of a floating body (within half
        a cell) rather than through the phi that the coupling mirrors into it; a column through a body that
        stands out of the water then reads the body's top. The columns are walked on the target
        (:mod:`iceresist.freesurface.columns`) and only the map is read; on several ranks over the whole domain's
        phi and flags gathered on rank 0 (None on the others), by the same kernel, so the heights are one
        process's bit for bit."""
        phi, flags, forest = self.phase.phi, self.fluid.flags, self.forest
        if self.decomp is not None:     # the whole domain's blocks on rank 0
            phi = self.decomp.gather_rows(self.phase.phi_host())
            flags = self.decomp.gather_rows(np.asarray(self._host(self.fluid.flags)))
            if phi is None:         # an MPI rank other than 0
                return None
            phi, flags, forest = self._to_target(phi), self._to_target(flags), self.decomp.forest
        if self._columns is None:
            self._columns = SurfaceColumns(forest, self.target)
        return self._columns.height(phi, flags, covered_as_water)


def column_crossing(phi: np.ndarray) -> np.ndarray:
    """Height z (cells from the array's bottom) where the dense ``phi`` (nx, ny, nz) crosses 1/2 in each column,
    the top-most crossing, by linear interpolation; NaN where a column has none: the reference of the columns kernel
    (:mod:`iceresist.freesurface.columns`, tests/test_freesurface_fluid.py)."""
    nz = phi.shape[2]
    z = np.arange(nz) + 0.5
    below = phi[:, :, :-1] >= 0.5
    above = phi[:, :, 1:] < 0.5
    cross = below & above
    k = nz - 2 - np.argmax(cross[:, :, ::-1], axis=2)
    p0 = np.take_along_axis(phi, k[..., None], axis=2)[..., 0]
    p1 = np.take_along_axis(phi, (k + 1)[..., None], axis=2)[..., 0]
    found = cross.any(axis=2)  # there p0 >= 1/2 > p1
    return np.where(found, z[k] + (p0 - 0.5) / np.where(found, p0 - p1, 1.0), np.nan)
