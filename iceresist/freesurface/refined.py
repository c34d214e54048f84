"""The free surface on the levels of a block octree (paper sections 2.2 and 2.5): the surface in the finest level.

The paper keeps the water surface, like the ice and the hull, inside the finest blocks; so does this module. The
finest level runs the whole free-surface step (:class:`~iceresist.freesurface.fluid.FreeSurfaceFluid`: the fused
update with eq. (11), the velocity and its extension, the phase field (h, phi) and reflag). Every coarser level is
liquid throughout and runs the same fused update with phi = 1 (the same body force rho g, so the hydrostatic
density is the same function of depth on every level), and the liquid crosses the level interfaces by the
conservative scheme of :class:`~iceresist.lbm.refinement.RefinedLBM` (mass to round-off).

The phase field needs values in the finest level's ghost blocks (they lie inside coarse leaves): the bulk liquid,
phi = 1 and h = h^eq(1, u) = w_k (1 + c_k.u / c_s^2 + ...) with u the velocity of the coarse cell under the ghost
cell (its populations now, the half-force shift removed), refilled before every fine step
(:func:`build_ghost_phase_cell`); u is the ghost cell's velocity for the phase field too (the fused update skips the
ghost blocks: no one reads their populations). The phi flux the leaves pull from the ghosts is then the liquid's own
flux u: the volume of the finest level changes only by the liquid's compressibility.

Where that picture does not hold the scene is refused: a coarser level (or a ghost of the finest) holding cells
with phi < 1 - 1e-4 at the start (the surface, its tanh profile's tail about 2.3 interface widths deep, or the gas
outside the finest level). The water volume
(:meth:`RefinedFreeSurface.volume`) is the finest level's sum of phi plus the coarser levels' liquid cells, in
level-0 cells.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.backends.launch import CellLauncher
from iceresist.errors import InputError
from iceresist.freesurface import kernel_key
from iceresist.freesurface.fluid import FreeSurfaceFluid
from iceresist.freesurface.hlattice import h_lattice as lookup_h_lattice
from iceresist.freesurface.pool import PooledLBM
from iceresist.freesurface.probe import COLUMNS, FluidProbe
from iceresist.grid.forest import CELLS, LX, LY, LZ
from iceresist.grid.levels import FROM_COARSER
from iceresist.grid.octree import BlockOctree
from iceresist.grid.regrid import same_blocks
from iceresist.lbm.refinement import RefinedLBM, locate_cells
from iceresist.parallel.levels import LevelShare

#: A coarse level's cells must start at least this liquid (phi >= 1 - PHI_BULK_TOL).
PHI_BULK_TOL = 1e-4


def build_ghost_phase_cell(target, real, lattice_name: str):
    """``ghost_phase_cell(i, c, b0, pb, pc, fc, gc, h, phi, u)``: cell c of ghost block b0 + i of the finest level
    takes phi = 1, the velocity u (``u[b, :, c]``) of the coarse cell under it (``pb[i, c]``, ``pc[i, c]``) from
    its populations ``fc`` (f - w) with the half-force shift of the coarse level's gravity ``gc`` (lattice units of
    that level, acting along -z) removed, u = sum c f / rho + (0, 0, gc / 2) (lattice velocities are the same on
    every level), and h_k = w_k (1 + c_k.u / c_s^2 + ((c_k.u)^2 - c_s^2 u.u) / (2 c_s^4)) (h^eq of eqs. 7-8 at
    phi = 1, where theta = 0)."""
    lat = lookup_h_lattice(lattice_name)
    nq = lat.q
    hc = np.asarray(lat.c, dtype=np.float64)
    hx, hy, hz = (np.ascontiguousarray(hc[:, a].astype(real)) for a in range(3))
    hw = np.array(lat.w, dtype=real)
    ex, ey, ez = (np.ascontiguousarray(L.C[:, a].astype(real)) for a in range(3))
    zero, one, half = real(0.0), real(1.0), real(0.5)
    cs2, ics2, half_ics4 = real(lat.cs2), real(1.0 / lat.cs2), real(0.5 / lat.cs2 ** 2)
    int64 = np.int64

    @target.device
    def ghost_phase_cell(i, c, b0, pb, pc, fc, gc, h, phi, u):
        i = int64(i)
        b = int64(b0) + i
        sb = int64(pb[i, c])
        sc = int64(pc[i, c])
        rho = one
        jx = zero
        jy = zero
        jz = zero
        for q in range(27):
            fq = fc[sb, q, sc]
            rho += fq
            jx += ex[q] * fq
            jy += ey[q] * fq
            jz += ez[q] * fq
        ux = jx / rho
        uy = jy / rho
        uz = jz / rho + half * gc
        uu = ux * ux + uy * uy + uz * uz
        phi[b, c] = one
        u[b, 0, c] = ux
        u[b, 1, c] = uy
        u[b, 2, c] = uz
        for k in range(nq):
            cu = hx[k] * ux + hy[k] * uy + hz[k] * uz
            h[b, k, c] = hw[k] * (one + ics2 * cu + half_ics4 * (cu * cu - cs2 * uu))

    return ghost_phase_cell


def liquid_h(lattice_name: str, f: np.ndarray, g_lattice: float) -> np.ndarray:
    """The host form of :func:`build_ghost_phase_cell`: h (n, q, 512) of bulk liquid (phi = 1) at the velocity of
    populations ``f`` (n, 27, 512, f - w) whose level has gravity ``g_lattice`` (its half-force shift removed)."""
    lat = lookup_h_lattice(lattice_name)
    f = np.asarray(f, dtype=np.float64)
    rho = 1.0 + f.sum(axis=1)
    u = np.einsum("qa,nqc->anc", L.C.astype(np.float64), f) / rho[None]
    u[2] += 0.5 * g_lattice
    cu = np.einsum("ka,anc->nkc", lat.c.astype(np.float64), u)
    uu = (u * u).sum(axis=0)[:, None, :]
    w = np.asarray(lat.w, dtype=np.float64)[None, :, None]
    return w * (1.0 + cu / lat.cs2 + (cu * cu - lat.cs2 * uu) / (2.0 * lat.cs2 ** 2))


@lru_cache(maxsize=None)
def ghost_phase_launcher(target, precision: str, lattice_name: str) -> CellLauncher:
    cell = build_ghost_phase_cell(target, jit.real_type(precision), lattice_name)
    return CellLauncher(target, cell, ("b0", "pb", "pc", "fc", "gc", "h", "phi", "u"), label="ghost_phase",
                        cache_key=kernel_key(target, f"ghost_phase|{precision}|{lattice_name}",
                                             ("iceresist.freesurface.refined",)))


def carried_surface(fs: "RefinedFreeSurface", f_finest, surface_state: dict, old_view, view, flags):
    """The finest level's (h, phi, h validity, flags) on the blocks of ``view`` after a regrid, from
    ``surface_state`` (:meth:`FreeSurfaceFluid.state` on the forest of ``old_view``) and the carried populations
    ``f_finest`` of ``view``'s blocks; ``flags`` the static flags of ``view``'s blocks. Copied block by block where
    both forests hold a block; a block new to the level lies in the bulk water (the criteria keep the surface on the
    finest level), so takes phi = 1, h of that water at its carried velocity (:func:`liquid_h`, as
    :meth:`RefinedFreeSurface.refill_ghosts` gives a ghost block) and the static flags. Raises RuntimeError where a
    block the level drops holds a cell less liquid than 1 - 1e-4."""
    L_ = fs.finest
    src, dst = same_blocks(old_view, view)
    kept = np.zeros(old_view.forest.nblocks, dtype=bool)
    kept[src] = True
    gone = np.flatnonzero(~kept[:old_view.nleaves])
    phi_old = np.asarray(surface_state["phi"])
    if gone.size and phi_old[gone].min() < 1.0 - PHI_BULK_TOL:
        raise RuntimeError(f"regrid: the finest level (level {L_}) would drop blocks the surface reaches "
                           f"(phi = {phi_old[gone].min():.3g})")
    n = view.forest.nblocks
    fresh = np.ones(n, dtype=bool)
    fresh[dst] = False
    real = jit.real_type(fs.precision)
    h = np.zeros((n,) + tuple(surface_state["h"].shape[1:]), dtype=real)
    phi = np.ones((n, CELLS), dtype=real)
    valid = np.ones(n, dtype=np.int8)
    flags = np.array(flags, dtype=np.uint8)
    h[dst], phi[dst] = surface_state["h"][src], phi_old[src]
    valid[dst], flags[dst] = surface_state["h_valid"][src], surface_state["flags"][src]
    g_coarse = fs.g0 / 2 ** max(L_ - 1, 0)     # the carried f of a fresh block is its coarse parent's
    h[fresh] = liquid_h(fs.h_lattice, np.asarray(f_finest)[fresh], g_coarse)
    return h, phi, valid, flags


class _LiquidLevel:
    """A coarser level: liquid throughout, the free-surface fused update with phi = 1 (populations in every block,
    the pool's identity map), so the body force is rho g as on the finest level."""

    def __init__(self, forest, tau, force, *, operator, precision, target, half_width):
        self.forest = forest
        self.fluid = PooledLBM(forest, tau=tau, force=force, operator=operator, precision=precision, target=target,
                               margin=None)
        self.real = jit.real_type(precision)
        self.force = tuple(float(v) for v in force)
        self._phi = target.to_device(np.ones((forest.nblocks, CELLS), self.real))
        self._half_width = self.real(half_width)
        self._probe = None

    @property
    def state(self):
        return self.fluid.state

    @property
    def active_blocks(self) -> int:
        return self.fluid.active_blocks

    @active_blocks.setter
    def active_blocks(self, n: int):
        self.fluid.active_blocks = int(n)

    def step(self):
        self.fluid.step(1, self._phi, self._half_width)

    def initialize(self, rho_blocks, u):
        self.fluid.initialize(self.forest.to_dense(rho_blocks), u, wet=np.ones(self.forest.nblocks, bool))

    def macroscopic_blocks(self):
        f = self.fluid.populations()
        rho = 1.0 + f.sum(axis=1)
        j = np.einsum("qa,bqc->abc", L.C.astype(np.float64), f)
        u = j / rho - 0.5 * np.asarray(self.force)[:, None, None]
        return rho, u

    def leaf_rows(self, nleaves: int) -> np.ndarray:
        """The probe's full rows (:data:`~iceresist.freesurface.probe.COLUMNS`) of the first ``nleaves`` blocks (the
        leaves), reduced per block on the target (:mod:`iceresist.freesurface.probe`): a row per block is read, not
        the populations. The velocity is the liquid's, its half-force shift removed (as :meth:`macroscopic_blocks`)."""
        if self._probe is None:
            self._probe = FluidProbe(self.forest, self.fluid.target)
            # the full pass takes the velocity from the populations: the array it would read otherwise is a stand-in
            self._no_u = self.fluid.target.to_device(np.zeros((1, 3, CELLS), self.real))
        return self._probe.rows(self.fluid.state, self.fluid.fslot, self.fluid.flags, self._no_u, self._phi, True,
                                -0.5 * self.force[2])[:nleaves]

    def leaves_finite(self, nleaves: int) -> bool:
        """Whether the populations of the first ``nleaves`` blocks (the leaves) give a finite density and velocity
        on every fluid cell and a finite mass (:meth:`leaf_rows`)."""
        rows = self.leaf_rows(nleaves)
        return bool(rows[:, COLUMNS.index("n_bad")].sum() == 0 and np.isfinite(rows[:, COLUMNS.index("mass")].sum()))


class _SurfaceLevel:
    """The finest level: the ghost blocks refilled with bulk liquid (:meth:`RefinedFreeSurface.refill_ghosts`), then
    the whole free-surface step."""

    def __init__(self, fs: FreeSurfaceFluid, refill):
        self.fs = fs
        self.forest = fs.forest
        self.refill = refill

    @property
    def state(self):
        return self.fs.fluid.state

    @property
    def active_blocks(self) -> int:
        return self.fs.fluid.active_blocks

    @active_blocks.setter
    def active_blocks(self, n: int):
        self.fs.fluid.active_blocks = int(n)

    def step(self):
        self.refill()
        self.fs.step()

    def macroscopic_blocks(self):
        f = self.fs.fluid.populations()
        rho = 1.0 + f.sum(axis=1)
        j = np.einsum("qa,bqc->abc", L.C.astype(np.float64), f)
        u = j / rho
        u[2] += 0.5 * self.fs.g
        return rho, u


class RefinedFreeSurface:
    """Liquid with a free surface under gravity on every level of ``octree`` (module docstring).

    ``tau0``: the relaxation time on level 0 (each finer level by acoustic scaling); ``gravity0``: g on level 0
    (lattice units, acting along -z; halved per level); ``depth0``: the still-water level in level-0 cells from the
    bottom; ``mobility``, ``width``, ``h_lattice``: the phase field on the finest level (its lattice units);
    ``faces``, ``operator``, ``precision``, ``target`` as for :class:`~iceresist.lbm.refinement.RefinedLBM`.
    ``lbm`` is the :class:`RefinedLBM` that steps the levels; ``surface`` the finest level's
    :class:`FreeSurfaceFluid`.

    ``f_pool_margin``: the finest level's spare population rows (:class:`FreeSurfaceFluid`; None: every block
    holds its populations). ``decomp``: the :class:`~iceresist.parallel.levels.LevelDecomposition` of an MPI run;
    the levels are then this rank's share. A coarser level steps its own leaves and swaps its halo leaves after each step; the finest level
    steps its halo leaves too (the phase field's passes read the velocity the fused update gives them) and swaps
    their whole state (populations, h, phi, flags) after each step: the passes reach at most 5 cells into its one
    block of halo, as on a uniform grid (:class:`~iceresist.models.surface.FreeSurfaceModel`).
    """

    def __init__(self, octree: BlockOctree, *, tau0: float, gravity0: float, depth0: float, mobility: float = 0.05,
                 width: float = 3.0, h_lattice: str = "D3Q15", operator: str = "cumulant",
                 precision: str = "float32", target=None, faces: dict | None = None, decomp=None,
                 f_pool_margin: float | None = None, views: list | None = None):
        self.target = target or jit.cpu
        self.precision = precision
        self.octree = octree
        self.g0 = float(gravity0)
        self.depth0 = float(depth0)
        self.h_lattice = h_lattice
        finest = int(octree.level.max())
        self.finest = finest
        self.width = float(width)
        built = {}

        def factory(lv, forest, tau, force):
            if lv == finest:
                fs = FreeSurfaceFluid(forest, tau=tau, gravity_lattice=-force[2], depth_cells=self.depth0 * 2 ** lv,
                                      mobility=mobility, width=width, h_lattice=h_lattice, operator=operator,
                                      precision=precision, target=self.target, f_pool_margin=f_pool_margin)
                built["surface"] = fs
                return _SurfaceLevel(fs, self.refill_ghosts)
            return _LiquidLevel(forest, tau, force, operator=operator, precision=precision, target=self.target,
                                half_width=0.5 * width)

        self.decomp = decomp
        self.lbm = RefinedLBM(octree, tau0=tau0, force0=(0.0, 0.0, -self.g0), faces=faces, operator=operator,
                              precision=precision, scheme="conservative", target=self.target,
                              solver_factory=factory, views=views if decomp is None else decomp.views,
                              partial=decomp is not None)
        self.surface: FreeSurfaceFluid = built["surface"]
        self.levels = self.lbm.levels
        self.views = self.lbm.views
        self._ghost_table()
        if decomp is not None:
            self._split_steps(decomp)

    def _split_steps(self, decomp):
        """On several ranks: each level's step followed by the swap of its halo leaves (class docstring)."""
        fs, t = self.surface, self.target
        fs.decomp = LevelShare(decomp, self.finest)
        for lv, level in self.lbm.solvers.items():
            if lv == self.finest:
                def arrays():
                    return fs.halo_state
            else:
                level.active_blocks = decomp.nown[lv]

                def arrays(level=level):
                    return (level.state,)

            def step(level=level, lv=lv, arrays=arrays):
                level.step()
                for a in arrays():
                    decomp.exchange(lv, a, t)

            self.lbm.set_stepper(lv, step)

    # ------------------------------------------------------------------ ghosts
    def _ghost_table(self):
        """The coarse cell under every cell of the finest level's ghost blocks (all lie inside coarser leaves)."""
        v = self.views[self.finest]
        self._nleaves = v.nleaves
        self._nghosts = v.nghosts
        if self._nghosts == 0 or len(self.levels) == 1:
            self._ghost = None
            return
        if not np.all(v.ghost_source == FROM_COARSER):
            raise InputError("refinement: the finest level has ghosts over a finer level")
        coarse = self.views[self.finest - 1]
        o = v.forest.origin[v.nleaves:] * 8
        pts = np.stack([o[:, a:a + 1] + Lc for a, Lc in enumerate((LX, LY, LZ))], axis=-1) >> 1
        pb, pc, _ = locate_cells(coarse, pts, self.lbm.periodic)
        if (pb < 0).any():
            raise InputError("refinement: a ghost block of the finest level lies over no coarse block")
        dev = self.target.to_device
        real = jit.real_type(self.precision)
        self._ghost = (ghost_phase_launcher(self.target, self.precision, self.surface.phase.lat.name),
                       np.int64(v.nleaves), dev(np.ascontiguousarray(pb, np.int64)),
                       dev(np.ascontiguousarray(pc, np.int64)), real(self.g0 / 2 ** (self.finest - 1)))

    def refill_ghosts(self):
        if self._ghost is None:
            return
        launch, b0, pb, pc, gc = self._ghost
        coarse = self.lbm.solvers[self.finest - 1]
        launch(self._nghosts, b0, pb, pc, coarse.state, gc, self.surface.phase.h, self.surface.phase.phi,
               self.surface._u)

    # ------------------------------------------------------------------ state
    def initialize(self, surface=None, u=(0.0, 0.0, 0.0)):
        """Still water in hydrostatic balance under the surface z_s(x, y) (``surface``: heights in level-0 cells, an
        (nx, ny) array of the finest level's columns, default the flat ``depth0``), moving with ``u`` (lattice
        units, the same on every level). Refused where a coarser level or a ghost of the finest level would hold
        a cell less liquid than phi = 1 - 1e-4 (module docstring)."""
        fs = self.surface
        lv = self.finest
        nx, ny, _ = fs.forest.shape_cells
        zs = np.full((nx, ny), self.depth0) if surface is None else np.asarray(surface, dtype=float)
        if zs.shape != (nx, ny):
            raise InputError(f"surface must be an array of shape ({nx}, {ny}) (heights in level-0 cells, one per "
                             f"column of the finest level), got {zs.shape}")
        for level in self.levels:
            view = self.views[level]
            x, y, z = view.forest.cell_coordinates()
            scale = 2 ** (lv - level)            # finest cells per cell of this level
            n = view.nleaves if level < lv else view.forest.nblocks
            first = 0 if level < lv else view.nleaves
            sel = slice(first, n)
            # the surface height over each cell: the lowest of its finest columns (the most demanding)
            col = zs.reshape(nx // scale, scale, ny // scale, scale).min(axis=(1, 3))
            s_cells = col[x[sel], y[sel]] * 2 ** level - (z[sel] + 0.5)
            phi = 0.5 + 0.5 * np.tanh(2.0 * s_cells * scale / self.width)
            if s_cells.size and phi.min() < 1.0 - PHI_BULK_TOL:
                where = "a ghost block of the finest level" if level == lv else f"level {level}"
                raise InputError(f"refinement.regions: {where} reaches the free surface (phi = {phi.min():.3g} "
                                 f"at the start); the surface and the gas above it must lie in the finest level "
                                 f"(level {lv}), {int(np.ceil(2.5 * self.width))} of its cells or more from its edge: "
                                 f"extend the finest region around the surface")
        surface_fine = zs * 2 ** lv
        fs.initialize(surface=surface_fine, u=u)
        for level in self.levels[:-1]:
            view = self.views[level]
            x, y, z = view.forest.cell_coordinates()
            scale = 2 ** (lv - level)
            col = zs.reshape(nx // scale, scale, ny // scale, scale).mean(axis=(1, 3)) * 2 ** level
            s_cells = col[x, y] - (z + 0.5)
            g = self.g0 / 2 ** level
            rho = np.exp(3.0 * g * np.maximum(s_cells, 0.0))
            self.lbm.solvers[level].initialize(rho, tuple(float(v) for v in u))
        self.refill_ghosts()
        self.lbm.iteration = 0

    # ------------------------------------------------------------------ regridding
    def carry_from(self, f_levels: dict, surface_state: dict, old_view):
        """Take the state of the levels before a regrid onto this octree's levels (block AMR part 2):
        ``f_levels`` every level's populations (f - w) on this octree's blocks, as
        :func:`iceresist.grid.regrid.carry_over` gives them; ``surface_state`` the finest level's
        :meth:`FreeSurfaceFluid.state` before, on the forest of ``old_view`` (its :class:`LevelView`); the finest
        level's phase field and flags as :func:`carried_surface` gives them."""
        self._carry_coarse(f_levels)
        fs, view = self.surface, self.views[self.finest]
        flags = np.array(self.target.to_host(fs.fluid.flags), dtype=np.uint8)
        h, phi, valid, flags = carried_surface(self, f_levels[self.finest], surface_state, old_view, view, flags)
        n = fs.forest.nblocks
        fs.load_state({"f_blocks": np.arange(n, dtype=np.int64), "f": self._real_f(f_levels[self.finest]),
                       "f_rows": np.int64(n), "h": h, "phi": phi, "h_valid": valid, "flags": flags,
                       "iteration": np.int64(surface_state["iteration"])}, take=True)

    def carry_split(self, f_levels: dict, f_whole, surface_whole, old_view):
        """:meth:`carry_from` on MPI ranks: ``f_levels`` this rank's share of the carried levels; on rank 0
        ``f_whole`` (the whole finest level's carried populations), ``surface_whole`` (the finest level's state
        before, gathered) and ``old_view`` (the finest level's whole view before): rank 0 carries the whole finest
        level's phase field and flags and deals them out."""
        d, L = self.decomp, self.finest
        self._carry_coarse(f_levels)
        whole, error = None, None
        if d.rank == 0:
            view = d.global_views[L]
            try:
                whole = carried_surface(self, f_whole[L], surface_whole, old_view, view,
                                        view.forest.flags.astype(np.uint8))
            except RuntimeError as err:
                error = str(err)
        error = d.bcast(error)
        if error is not None:
            raise RuntimeError(error)
        h, phi, valid, flags = (d.scatter(L, None if whole is None else part) for part in
                                (whole or (None,) * 4))
        n = self.surface.forest.nblocks
        iteration = d.bcast(None if surface_whole is None else int(surface_whole["iteration"]))
        self.surface.load_rows({"f_blocks": np.arange(n, dtype=np.int64), "f": self._real_f(f_levels[L]),
                                "f_rows": np.int64(n), "h": h, "phi": phi, "h_valid": valid, "flags": flags,
                                "iteration": np.int64(iteration)}, take=True)

    def _carry_coarse(self, f_levels: dict):
        for lv in self.levels[:-1]:
            level = self.lbm.solvers[lv]
            n = level.forest.nblocks
            level.fluid.set_rows(np.arange(n), self._real_f(f_levels[lv]), n, take=True)
            level.fluid.iteration = self.lbm.iteration * 2 ** lv

    def _real_f(self, f):
        """``f`` C-contiguous in the storage precision, not copied where it is (the pool takes it as its buffer)."""
        return np.ascontiguousarray(f, dtype=jit.real_type(self.precision))

    def step(self, n: int = 1):
        """Advance level 0 by ``n`` steps (the finest level by n 2^L)."""
        self.lbm.step(n)

    @property
    def iteration(self) -> int:
        return self.lbm.iteration

    # ------------------------------------------------------------------ diagnostics
    def leaf_rows(self, lv: int, n: int) -> np.ndarray:
        """The probe's full rows (:data:`~iceresist.freesurface.probe.COLUMNS`: the liquid cells' count, mass,
        kinetic energy, fastest cell, lattice units) of level ``lv``'s first ``n`` blocks (its leaves, this rank's
        own on several ranks), reduced per block on the target: what a record reads of a level. The finest level's
        liquid is its FLUID cells (phi >= 1/2 by the last reflag, not a body's), a coarser level's every fluid cell."""
        if lv != self.finest:
            return self.lbm.solvers[lv].leaf_rows(n)
        fs = self.surface
        if getattr(self, "_finest_probe", None) is None or self._finest_probe.forest is not fs.forest:
            self._finest_probe = FluidProbe(fs.forest, self.target)
            # the full pass takes the velocity from the populations: the array it would read otherwise is a stand-in
            self._no_u = self.target.to_device(np.zeros((1, 3, CELLS), jit.real_type(self.precision)))
        return self._finest_probe.rows(fs.fluid.state, fs.fluid.fslot, fs.fluid.flags, self._no_u, fs.phase.phi,
                                       True, 0.5 * fs.g)[:n]

    def coarse_levels_finite(self) -> bool:
        """Whether every coarser level's leaves (this rank's) hold finite populations
        (:meth:`_LiquidLevel.leaves_finite`: reduced on the target); the finest level's are the surface's probe's."""
        return all(self.lbm.solvers[lv].leaves_finite(self.views[lv].nleaves) for lv in self.levels[:-1])

    def volume(self, per_block: np.ndarray | None = None) -> float:
        """The water volume in level-0 cells: the finest level's leaves' sum of phi over 8^L (per-block sums added in
        the level's global block order: the same float64 sum on any number of ranks), plus every coarser level's
        leaf cells (liquid throughout) over 8^l. ``per_block``: the finest level's volume per block of this rank
        (its leaves first) to add instead of phi's sums (the bodies': :meth:`PhaseField.volume_per_block`)."""
        if per_block is None and len(self.levels) == 1:        # one level: the surface's own sum
            return self.surface.volume() / 8.0 ** self.finest
        if per_block is None:
            phi = np.asarray(self.target.to_host(self.surface.phase.phi), dtype=np.float64)
            per_block = phi.sum(axis=1)
        leaves = self.octree.blocks_per_level()
        d = self.decomp
        if d is None:
            per_block = per_block[:self._nleaves]
        else:
            per_block = d.bcast(d.gather_leaves(self.finest, per_block[:d.nown[self.finest]]))
        total = per_block.sum() / 8.0 ** self.finest
        for level in self.levels[:-1]:
            total += int(leaves[level]) * CELLS / 8.0 ** level
        return float(total)

    def surface_height(self) -> np.ndarray:
        """Height of the phi = 1/2 surface over each column of the finest level (nx, ny), in finest-level cells
        from the bottom (:meth:`FreeSurfaceFluid.surface_height`)."""
        return self.surface.surface_height()

    def max_speed(self) -> float:
        """max |u| (lattice units) over the liquid leaf cells of every level."""
        out = 0.0
        for level in self.levels:
            rho, u = self.lbm.solvers[level].macroscopic_blocks()
            n = self.views[level].nleaves
            u = u[:, :n]
            if level == self.finest:
                phi = np.asarray(self.target.to_host(self.surface.phase.phi))[:n]
                u = u[:, phi >= 0.5]
            out = max(out, float(np.sqrt((u ** 2).sum(axis=0)).max()))
        return out
