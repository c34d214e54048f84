"""The LBM solver on a block forest: state, fused stream-collide steps, macroscopic fields.

State is two population buffers ``f[block, q, cell]`` in the well-conditioned form
f - w (rho0 = 1, :mod:`iceresist.lbm.collide`), float32 by default. On CUDA the buffers
and tables are copied to the device once and stay there; only ``macroscopic()``
and ``mass()`` copy populations back. The buffer holds post-collision
populations, so macroscopic values subtract half the force:
u = (sum c f* - F/2) / rho (the half-force shift of ``iceresist.lbm.collide``).
"""

from __future__ import annotations

import logging
from functools import lru_cache

import numpy as np

from iceresist.backends import cache, jit
from iceresist.backends.launch import ActiveLauncher, CellLauncher
from iceresist.errors import InputError, StabilityError
from iceresist.lattice import C, Q, W
from iceresist.lbm.collide import build_collide_bgk
from iceresist.lbm.stream import ARGS, build_stream_collide, build_stream_collide_block

log = logging.getLogger(__name__)

OPERATORS = ("cumulant", "bgk")

#: Modules whose source decides the compiled stream-collide launcher (the key of its on-disk cache,
#: :mod:`iceresist.backends.cache`).
KEY_MODULES = ("iceresist.lbm.stream", "iceresist.lbm.boundary", "iceresist.lbm.codegen", "iceresist.lbm.collide",
               "iceresist.lattice", "iceresist.grid.flags", "iceresist.grid.forest")
#: ... and those of the cumulant operator (not imported by a BGK run: the generator needs sympy).
CUMULANT_MODULES = ("iceresist.lbm.cumulant", "iceresist.lbm.cumulant_gen", "iceresist.lbm.operators")


def collide_builder(operator: str):
    """The collision builder ``build_collide_*(target, real)`` of an operator name."""
    if operator == "bgk":
        return build_collide_bgk
    if operator == "cumulant":
        # deferred: the cumulant operator's generator imports sympy (half a second), which a BGK run never needs
        from iceresist.lbm.operators import get_collide_builder

        return get_collide_builder("cumulant")
    raise InputError(f"operator must be one of {', '.join(OPERATORS)}, not {operator!r}")


def operator_available(operator: str) -> bool:
    """True where ``collide_builder(operator)`` succeeds."""
    try:
        collide_builder(operator)
    except InputError:
        return False
    return True


@lru_cache(maxsize=None)
def fused_launcher(target, precision: str, operator: str, free_surface: bool = False, active: bool = False):
    """Compile (once per target, precision, operator) the fused stream-collide launcher, on the CPU from the on-disk
    kernel cache; ``free_surface``: the variant with eq. (11) at gas cells and the force rho g
    (:mod:`iceresist.lbm.stream`); ``active``: an :class:`ActiveLauncher` of the blocks flagged in an array of a
    flag per block (an MPI rank updates the blocks whose cells it sends first, the rest while its messages
    travel), else a :class:`CellLauncher` of the first blocks."""
    real = jit.real_type(precision)
    collide = collide_builder(operator)(target, real)
    kind, argnames = (ActiveLauncher, ("active",) + ARGS) if active else (CellLauncher, ARGS)
    if target.is_cuda:
        return kind(target, build_stream_collide(target, real, collide, free_surface), argnames,
                    label="lbm_stream_collide")
    modules = KEY_MODULES + (CUMULANT_MODULES if operator == "cumulant" else ())
    key = cache.fingerprint(f"{precision}|{operator}|fs={bool(free_surface)}" + ("|active" if active else ""),
                            modules)
    return kind(target, build_stream_collide_block(target, real, collide, free_surface=free_surface), argnames,
                per_block=True, label="lbm_stream_collide", cache_key=key)


def equilibrium_minus_w(rho, ux, uy, uz):
    """f_eq - w (paper eq. 12) computed without forming f_eq: well-conditioned for rho ~ 1."""
    cu = [C[q, 0] * ux + C[q, 1] * uy + C[q, 2] * uz for q in range(Q)]
    uu = ux * ux + uy * uy + uz * uz
    return np.stack([W[q] * ((rho - 1.0) + rho * (3.0 * cu[q] + 4.5 * cu[q] ** 2 - 1.5 * uu)) for q in range(Q)])


class LBMSolver:
    """Fused pull stream-collide LBM (paper eqs. 1-3) on a :class:`~iceresist.grid.BlockForest`.

    ``tau``: relaxation time (lattice units, > 1/2); ``force``: uniform body-force density
    (lattice units); ``operator``: "cumulant" or "bgk"; ``precision``: storage and
    arithmetic, "float32" or "float64"; ``target``: ``jit.cpu`` or ``jit.cuda()``.
    ``free_surface``: compile the free-surface variant (:mod:`iceresist.freesurface.fluid`), in
    which ``force`` is an acceleration g (force density rho g) and GAS cells are skipped.
    """

    def __init__(self, forest, *, tau: float, force=(0.0, 0.0, 0.0), operator: str = "cumulant",
                 precision: str = "float32", target=jit.cpu, free_surface: bool = False):
        if not tau > 0.5:
            raise StabilityError(f"tau = {tau} must exceed 1/2 (lattice viscosity (tau - 1/2)/3 > 0); "
                                 "raise the viscosity or coarsen the time step")
        if len(tuple(force)) != 3:
            raise InputError(f"force must have 3 components (lattice units), got {force!r}")
        self.forest = forest
        self.tau = float(tau)
        self.force = tuple(float(v) for v in force)
        self.operator = operator
        self.precision = precision
        self.real = jit.real_type(precision)
        self.target = target
        self.iteration = 0
        self.cells = forest.cells
        #: Bytes of population storage per cell (two buffers), also the memory traffic of one update.
        self.bytes_per_cell = 2 * Q * np.dtype(self.real).itemsize
        self._launch = fused_launcher(target, precision, operator, free_surface)
        real = self.real
        tables = dict(nbr_key=forest.nbr_key.astype(np.int32), link_bc=forest.link_bc.astype(np.int32),
                      flags=forest.flags.astype(np.uint8), bc_kind=forest.bc_kind.astype(np.int32),
                      bc_u=forest.bc_velocity.astype(real), bc_rho=forest.bc_density.astype(real))
        self._tables = {k: self._to_device(np.ascontiguousarray(v)) for k, v in tables.items()}
        shape = (forest.nblocks, Q, 512)
        self._f = [self._to_device(np.zeros(shape, dtype=real)) for _ in range(2)]
        self._scalars = (real(1.0 / self.tau), *(real(v) for v in self.force))
        #: Blocks the step updates, the forest's first ones (a rank of an MPI run updates its own blocks, not its
        #: halo, :mod:`iceresist.parallel.decomposition`).
        self.active_blocks = forest.nblocks
        #: The halo exchange of an MPI run after each step (:class:`~iceresist.parallel.decomposition.SolverHalo`),
        #: or None: the blocks whose cells other ranks pull are updated first, their messages posted, the other
        #: blocks updated while they travel.
        self.halo = None
        self._free_surface = free_surface
        log.info("LBM solver: %d cells in %d blocks, %s %s on %s", self.cells, forest.nblocks, operator,
                 precision, target.name)

    def _to_device(self, a):
        return self.target.to_device(a)

    @property
    def state(self):
        """The population buffer the next step pulls from (a device array on CUDA); moving-boundary hooks
        (:mod:`iceresist.coupling`) edit it in place between steps."""
        return self._f[0]

    @property
    def flags(self):
        """The cell-flag table the fused kernel reads (a device array on CUDA); moving bodies rewrite it."""
        return self._tables["flags"]

    def _host_f(self) -> np.ndarray:
        return self.target.to_host(self._f[0], copy=False)

    # ------------------------------------------------------------------ state
    def initialize(self, rho=1.0, u=(0.0, 0.0, 0.0)):
        """Set the equilibrium of density ``rho`` and velocity ``u`` (scalars or dense (nx,ny,nz) / (3,nx,ny,nz))."""
        fo = self.forest
        nshape = (fo.nblocks, 512)
        rho_b = fo.from_dense(np.broadcast_to(np.asarray(rho, dtype=float), fo.shape_cells)) \
            if np.ndim(rho) else np.full(nshape, float(rho))
        u = np.asarray(u, dtype=float)
        if u.shape == (3,):
            ub = [np.full(nshape, u[a]) for a in range(3)]
        elif u.shape == (3, *fo.shape_cells):
            ub = list(fo.from_dense(u))
        else:
            raise InputError(f"initialize: u must be 3 numbers or an array (3, {', '.join(map(str, fo.shape_cells))}), "
                             f"got shape {u.shape}")
        feq = equilibrium_minus_w(rho_b, *ub).transpose(1, 0, 2)      # (nblocks, 27, 512)
        feq[np.broadcast_to(~fo.fluid[:, None, :], feq.shape)] = 0.0
        self.set_populations(feq)
        self.iteration = 0

    def set_populations(self, f: np.ndarray):
        """Both population buffers set to ``f`` (host f - w, (nblocks, 27, 512), cast to the storage precision): a
        regrid's carried populations, a checkpoint's."""
        host = np.ascontiguousarray(np.asarray(f).astype(self.real, copy=False))
        for buf in self._f:
            if hasattr(buf, "copy_to_device"):
                buf.copy_to_device(host)
            else:
                buf[...] = host

    def step(self, n: int = 1):
        """Advance ``n`` fused stream-collide steps; the buffers swap after each."""
        t = self._tables
        nb = self.active_blocks
        halo = self.halo
        for _ in range(int(n)):
            src, dst = self._f
            args = (src, dst, t["nbr_key"], t["link_bc"], t["flags"], t["bc_kind"], t["bc_u"], t["bc_rho"],
                    *self._scalars)
            if halo is None:
                self._launch(nb, *args)
            elif not halo.overlap:
                self._launch(nb, *args)
                halo.finish(halo.start(dst))
            else:
                launch = self._active_launcher()
                launch(self.forest.nblocks, halo.sent, *args)
                pending = halo.start(dst)
                launch(self.forest.nblocks, halo.inner, *args)
                halo.finish(pending)
            self._f = [dst, src]
            self.iteration += 1

    def _active_launcher(self):
        return fused_launcher(self.target, self.precision, self.operator, self._free_surface, active=True)

    def synchronize(self):
        """Wait for the device (CUDA); a no-op on the CPU."""
        self.target.synchronize()

    # ------------------------------------------------------------------ diagnostics
    def populations(self) -> np.ndarray:
        """Host copy of the post-collision populations f - w, (nblocks, 27, 512), float64."""
        return self._host_f().astype(np.float64)

    def stored_populations(self) -> np.ndarray:
        """The populations f - w on the host in the storage precision, (nblocks, 27, 512): on the CPU the buffer
        the next step pulls from itself (no copy; what a regrid carries), on CUDA its host copy."""
        return self._host_f()

    def macroscopic_blocks(self):
        """rho (nblocks, 512) and u (3, nblocks, 512), float64, NaN outside fluid."""
        f = self.populations()
        rho = 1.0 + f.sum(axis=1)
        j = np.einsum("qa,bqc->abc", C.astype(np.float64), f)
        u = (j - 0.5 * np.asarray(self.force)[:, None, None]) / rho
        fluid = self.forest.fluid
        rho[~fluid] = np.nan
        u[:, ~fluid] = np.nan
        return rho, u

    def macroscopic(self):
        """Density (nx, ny, nz) and velocity (3, nx, ny, nz), lattice units, float64, NaN outside fluid."""
        rho, u = self.macroscopic_blocks()
        return self.forest.to_dense(rho), self.forest.to_dense(u)

    def mass(self) -> float:
        """Sum of rho over the fluid cells (float64)."""
        f = self._host_f()
        fluid = self.forest.fluid
        return float(self.cells + f.sum(axis=1, dtype=np.float64)[fluid].sum())
