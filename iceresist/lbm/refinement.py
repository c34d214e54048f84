"""The LBM on the levels of a block octree: acoustic scaling, sub-cycling and the level interfaces (paper section
2.5, fig. 1).

Acoustic scaling: level l + 1 halves the cell and the time step of level l, so lattice velocities are the same on
every level, the lattice viscosity doubles (tau_{l+1} - 1/2 = 2 (tau_l - 1/2), the same physical viscosity) and a
body-force acceleration halves (g dt^2 / dx). Sub-cycling: one step of level l is two steps of level l + 1.

Level interfaces, through the ghost blocks of each level (:mod:`iceresist.grid.levels`):

* **coarse to fine** (``prolong``): a ghost cell of level l + 1 inside a leaf of level l takes the trilinear
  interpolation of the post-collision populations f - w of the eight nearest cells of level l (cell centres of
  level l + 1 lie a quarter of a coarse cell from them), as the paper does, the non-equilibrium part not rescaled;
  at the half step of level l + 1 from the mean of level l's populations before and after its step;
* **fine to coarse** (``restrict``): a ghost cell of level l over leaves of level l + 1 takes the mean of its
  eight children.

Every level's leaves are then stepped by the fused stream-collide kernel of the uniform grid
(:class:`~iceresist.lbm.solver.LBMSolver`), which also steps the ghost blocks (their values are refilled before
they are read). This is the host (NumPy) orchestration of the level exchange, CPU only.
"""

from __future__ import annotations

import numpy as np

from iceresist.errors import InputError
from iceresist.grid.forest import LX, LY, LZ
from iceresist.grid.levels import FROM_COARSER, FROM_FINER, LevelView, level_views
from iceresist.grid.octree import CHILDREN, BlockOctree
from iceresist.lattice import C
from iceresist.lbm.solver import _equilibrium_minus_w


def _lookup(view: LevelView, x, y, z, periodic):
    """(block, cell) of global cells (x, y, z) of ``view``'s level (wrapped on periodic axes, clamped on closed
    ones); block -1 where no block is allocated there."""
    n = np.array(view.forest.shape_cells)
    out = []
    for a, v in enumerate((x, y, z)):
        v = np.asarray(v, dtype=np.int64)
        out.append(v % n[a] if periodic[a] else np.clip(v, 0, n[a] - 1))
    x, y, z = out
    bm = view.block_map
    b = bm[x >> 3, y >> 3, z >> 3]
    c = (x & 7) + 8 * ((y & 7) + 8 * (z & 7))
    return b, c


def prolongation_table(fine: LevelView, coarse: LevelView, periodic):
    """For every cell of ``fine``'s ghost blocks that come from the coarser level: its (ghost block, cell) and
    the coarse (block, cell, weight) of its eight trilinear corners (weights renormalised over the corners that
    exist)."""
    g = np.flatnonzero(fine.ghost_source == FROM_COARSER) + fine.nleaves
    if len(g) == 0:
        return None
    o = fine.forest.origin[g] * 8
    fx, fy, fz = (o[:, a:a + 1] + L for a, L in enumerate((LX, LY, LZ)))
    p = [(v + 0.5) / 2 - 0.5 for v in (fx, fy, fz)]          # coarse index coordinates
    i0 = [np.floor(v).astype(np.int64) for v in p]
    t = [v - i for v, i in zip(p, i0)]
    blocks, cells, weights = [], [], []
    for cx, cy, cz in CHILDREN:
        b, c = _lookup(coarse, i0[0] + cx, i0[1] + cy, i0[2] + cz, periodic)
        w = ((t[0] if cx else 1 - t[0]) * (t[1] if cy else 1 - t[1]) * (t[2] if cz else 1 - t[2]))
        w = np.where(b >= 0, w, 0.0)
        blocks.append(np.maximum(b, 0))
        cells.append(c)
        weights.append(w)
    w = np.stack(weights, axis=-1)
    wsum = w.sum(axis=-1, keepdims=True)
    if (wsum <= 0).any():
        raise InputError("a fine ghost cell has no coarse cell to interpolate from")
    return (np.repeat(g[:, None], 512, axis=1), np.broadcast_to(np.arange(512), (len(g), 512)),
            np.stack(blocks, -1), np.stack(cells, -1), w / wsum)


def restriction_table(coarse: LevelView, fine: LevelView, periodic):
    """For every cell of ``coarse``'s ghost blocks over the finer level: its (ghost block, cell) and the fine
    (block, cell) of its eight children, weight 1/8 each (0 where a child is not a fine leaf; renormalised)."""
    g = np.flatnonzero(coarse.ghost_source == FROM_FINER) + coarse.nleaves
    if len(g) == 0:
        return None
    o = coarse.forest.origin[g] * 8
    cx, cy, cz = (o[:, a:a + 1] + L for a, L in enumerate((LX, LY, LZ)))
    blocks, cells, weights = [], [], []
    for a, b_, c_ in CHILDREN:
        b, c = _lookup(fine, 2 * cx + a, 2 * cy + b_, 2 * cz + c_, periodic)
        ok = (b >= 0) & (b < fine.nleaves)
        blocks.append(np.where(ok, b, 0))
        cells.append(c)
        weights.append(np.where(ok, 0.125, 0.0))
    w = np.stack(weights, axis=-1)
    wsum = w.sum(axis=-1, keepdims=True)
    w = np.divide(w, wsum, out=np.zeros_like(w), where=wsum > 0)
    return (np.repeat(g[:, None], 512, axis=1), np.broadcast_to(np.arange(512), (len(g), 512)),
            np.stack(blocks, -1), np.stack(cells, -1), w)


def _apply(table, dst, src, neq_scale: float = 1.0):
    """dst[gb, :, gc] = sum_k w_k src[b_k, :, c_k] over the cells of a transfer table (in place), the
    non-equilibrium part (about the equilibrium of the result's own density and velocity) times ``neq_scale``."""
    gb, gc, b, c, w = table
    have = w.sum(axis=-1) > 0
    acc = np.zeros(gb.shape + (src.shape[1],), dtype=np.float64)
    for k in range(w.shape[-1]):
        acc += w[..., k, None] * src[b[..., k], :, c[..., k]]
    if neq_scale != 1.0:
        rho = 1.0 + acc.sum(axis=-1)
        u = (acc @ C.astype(np.float64)) / rho[..., None]
        feq = np.moveaxis(_equilibrium_minus_w(rho, u[..., 0], u[..., 1], u[..., 2]), 0, -1)
        acc = feq + neq_scale * (acc - feq)
    dst[gb[have], :, gc[have]] = acc[have].astype(dst.dtype)


class RefinedLBM:
    """The LBM on every level of ``octree`` (leaves of all levels fluid; walls and periodic faces as ``faces``).

    ``tau0`` and ``force0`` are the relaxation time and body-force acceleration of level 0 (lattice units of level
    0); each finer level gets tau and force by acoustic scaling. ``step()`` advances level 0 by one step and every
    level l by 2^l steps.
    """

    def __init__(self, octree: BlockOctree, *, tau0: float, force0=(0.0, 0.0, 0.0), faces: dict | None = None,
                 operator: str = "bgk", precision: str = "float64", rescale: bool = True):
        from iceresist.lbm.solver import LBMSolver

        self.rescale = bool(rescale)
        self.octree = octree
        self.views = level_views(octree, faces)
        self.periodic = tuple(bool(p) for p in octree.periodic)
        for v in self.views:
            if v is not None and tuple(v.forest.faces[a + "-"].kind == "periodic" for a in "xyz") != self.periodic:
                raise InputError("faces: the periodic axes must be the octree's periodic axes")
        self.levels = [v.level for v in self.views if v is not None]
        if self.levels != list(range(self.levels[0], self.levels[-1] + 1)):
            raise InputError("every level between the coarsest and the finest must hold leaves")
        self.tau = {}
        self.solvers = {}
        for lv in self.levels:
            tau = 0.5 + (tau0 - 0.5) * 2 ** lv
            g = tuple(float(a) / 2 ** lv for a in force0)
            self.tau[lv] = tau
            self.solvers[lv] = LBMSolver(self.views[lv].forest, tau=tau, force=g, operator=operator,
                                         precision=precision)
        self.prolong = {lv: prolongation_table(self.views[lv], self.views[lv - 1], self.periodic)
                        for lv in self.levels[1:]}
        self.restrict = {lv: restriction_table(self.views[lv], self.views[lv + 1], self.periodic)
                         for lv in self.levels[:-1]}
        for lv in self.levels[1:]:
            if self.rescale and (self.tau[lv - 1] == 1.0 or self.tau[lv] == 1.0):
                raise InputError(f"tau = 1 on level {lv - 1 if self.tau[lv - 1] == 1.0 else lv}: its post-collision "
                                 "populations hold no stress to rescale across the level interface; choose a tau0 "
                                 "whose levels avoid 1 (e.g. tau0 = 0.6), or rescale=False")
        self.iteration = 0

    def neq_scale(self, fine: int, to_fine: bool) -> float:
        """Factor on the post-collision non-equilibrium populations across the interface of levels fine - 1 and
        ``fine`` (Dupuis and Chopard 2003): f_neq* scales as (tau - 1) dx, so coarse to fine times
        (tau_f - 1) / (2 (tau_c - 1)), fine to coarse its inverse; 1 without ``rescale`` (the paper's choice)."""
        if not self.rescale:
            return 1.0
        s = (self.tau[fine] - 1.0) / (2.0 * (self.tau[fine - 1] - 1.0))
        return s if to_fine else 1.0 / s

    def initialize(self, rho=1.0, u=(0.0, 0.0, 0.0)):
        for s in self.solvers.values():
            s.initialize(rho=rho, u=u)
        self.iteration = 0

    def _advance(self, lv: int):
        s = self.solvers[lv]
        if lv in self.restrict and self.restrict[lv] is not None:
            _apply(self.restrict[lv], s.state, self.solvers[lv + 1].state, self.neq_scale(lv + 1, False))
        finer = lv + 1 if lv + 1 in self.solvers else None
        before = s.state.copy() if finer is not None else None
        s.step()
        if finer is None:
            return
        table = self.prolong[finer]
        for half in (0.0, 0.5):
            if table is not None:
                src = before if half == 0.0 else 0.5 * (before + s.state)
                _apply(table, self.solvers[finer].state, src, self.neq_scale(finer, True))
            self._advance(finer)

    def step(self, n: int = 1):
        """Advance the coarsest level by ``n`` steps (level l by n 2^(l - coarsest))."""
        for _ in range(int(n)):
            self._advance(self.levels[0])
            self.iteration += 1

    def leaf_fields(self, lv: int):
        """rho and u (3, nleaves, 512) of the leaves of level ``lv`` and their global cell coordinates."""
        v = self.views[lv]
        rho, u = self.solvers[lv].macroscopic_blocks()
        x, y, z = v.forest.cell_coordinates()
        n = v.nleaves
        return rho[:n], u[:, :n], (x[:n], y[:n], z[:n])

    def mass(self) -> float:
        """Sum of rho times cell volume (level-0 cells) over the leaves of every level."""
        total = 0.0
        for lv in self.levels:
            rho, _, _ = self.leaf_fields(lv)
            total += np.nansum(rho) / 8.0 ** lv
        return total
