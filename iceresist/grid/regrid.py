"""Regridding: a new block octree from criteria, and per-cell state carried from the old forest to the new one
(paper section 2.5: the blocks follow the ice, the hull, the surface and the eddies).

Both octrees cover the domain with their leaves exactly once, so every cell of a block of the new forest at level L
(a leaf or a ghost, :mod:`iceresist.grid.levels`) lies either in one leaf of the old forest at a level m <= L, or
over old leaves of levels m > L. :func:`carry_over` gives it, per component (each population, phi, ...):

* from an old leaf of level m <= L the value of the old cell that holds it (a refined cell copies its parent: the
  constant reconstruction of the conservative level interface, Rohde et al. 2006);
* from old leaves of level m > L the mean of the 8^(m - L) old cells inside it (the coalescence of that interface).

For populations in the f - w form, rho_cell = 1 + sum_q (f - w), so the mass sum_cells rho_cell (dx_0 / 2^L)^3 over
the leaves is carried over to round-off: a copy repeats a cell's value in 8^(L - m) cells of 1/8^(L - m) its
volume, a mean sums 8^(m - L) cells with weights 1/8^(m - L) (powers of two, exact in binary). So is a conserved
scalar such as phi. The non-equilibrium part is carried unscaled, as across the level interface of the conservative
scheme (:class:`iceresist.lbm.refinement.RefinedLBM`).

Everything here is integer and float NumPy on the host: a regrid runs every N steps, not every step.
"""

from __future__ import annotations

import numpy as np

from iceresist.grid.forest import BLOCK, CELLS
from iceresist.grid.levels import LevelView

_LOCAL = np.stack(np.meshgrid(np.arange(BLOCK), np.arange(BLOCK), np.arange(BLOCK), indexing="ij"),
                  axis=-1).transpose(2, 1, 0, 3).reshape(CELLS, 3).astype(np.int64)
"""(512, 3): the (x, y, z) of cell c = x + 8 (y + 8 z) of a block."""


def _block_at(view: LevelView, origin: np.ndarray) -> np.ndarray:
    """The view's block (leaf or ghost) at each block coordinate ``origin`` (n, 3) of its level, -1 where none."""
    bm = view.block_map
    shape = np.array(bm.shape, dtype=np.int64)
    inside = ((origin >= 0) & (origin < shape[None, :])).all(axis=1)
    out = np.full(len(origin), -1, dtype=np.int64)
    out[inside] = bm[origin[inside, 0], origin[inside, 1], origin[inside, 2]]
    return out


def _flat_index(view: LevelView, xyz: np.ndarray, leaves_only: bool):
    """Flat index block * 512 + cell of global cells ``xyz`` (at the view's level) in the view's forest, -1 where
    no block (or, with ``leaves_only``, no leaf block) holds them."""
    blk = _block_at(view, xyz >> 3)
    if leaves_only:
        blk[blk >= view.nleaves] = -1
    local = xyz & 7
    c = local[:, 0] + BLOCK * (local[:, 1] + BLOCK * local[:, 2])
    return np.where(blk >= 0, blk * CELLS + c, -1)


def _cell_rows(a: np.ndarray, blk: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """The values ``(n, components)`` of a per-block field ``a[block, ..., cell]`` at the cells (``blk``, ``cell``),
    read where they lie (no copy of the whole field)."""
    a = np.asarray(a)
    return a.reshape(a.shape[0], -1, a.shape[-1])[blk, :, cell]


def carry_over(old_views: list, old_fields: dict, new_views: list, new_fields: dict) -> None:
    """Fill ``new_fields[level]`` (``[block, ..., 512]``, every block of the new level's forest: leaves and
    ghosts) from ``old_fields[level]`` (the same layout over the old level's forest; only its leaves are read), as
    the module docstring says. ``old_views`` and ``new_views`` are :func:`iceresist.grid.levels.level_views` of the
    two octrees (None for a level without leaves). Raises RuntimeError if a new cell is not covered exactly once
    (the two octrees do not cover the same domain).

    A new block where the old forest has a leaf of the same level is that leaf, copied whole (most blocks of a
    regrid: the bodies and the surface move a few cells between two); the cells of the others are gathered from
    the old leaves one by one, reading only the old blocks that reach them."""
    old_levels = [v.level for v in old_views if v is not None]
    for nv in new_views:
        if nv is None:
            continue
        L = nv.level
        dst = new_fields[L]
        nb = nv.forest.nblocks
        origin = np.asarray(nv.forest.origin[:nb], dtype=np.int64)
        todo = np.ones(nb, dtype=bool)
        if L in old_levels:
            ov = old_views[L]
            same = _block_at(ov, origin)
            leaf = (same >= 0) & (same < ov.nleaves)
            dst[leaf] = np.asarray(old_fields[L])[same[leaf]]
            todo[leaf] = False
        sel = np.flatnonzero(todo)
        if sel.size == 0:
            continue
        row = np.full(nb, -1, dtype=np.int64)            # new block -> its place among the blocks gathered here
        row[sel] = np.arange(sel.size)
        xyz = (origin[sel][:, None, :] * BLOCK + _LOCAL[None, :, :]).reshape(-1, 3)
        ncomp = int(np.prod(dst.shape[1:-1], dtype=np.int64))
        acc = np.zeros((len(xyz), ncomp), dtype=np.float64)
        weight = np.zeros(len(xyz), dtype=np.float64)
        for m in old_levels:
            ov = old_views[m]
            if m <= L:
                idx = _flat_index(ov, xyz >> (L - m), leaves_only=True)
                hit = np.flatnonzero(idx >= 0)
                acc[hit] += _cell_rows(old_fields[m], idx[hit] // CELLS, idx[hit] % CELLS)
                weight[hit] += 1.0
            else:
                # the old leaves of level m inside the blocks gathered here, in the old forest's order
                oorigin = np.asarray(ov.forest.origin[:ov.nleaves], dtype=np.int64)
                at = _block_at(nv, oorigin >> (m - L))
                blocks = np.flatnonzero((at >= 0) & (row[np.maximum(at, 0)] >= 0))
                if blocks.size == 0:
                    continue
                oxyz = (oorigin[blocks][:, None, :] * BLOCK + _LOCAL[None, :, :]).reshape(-1, 3)
                idx = _flat_index(nv, oxyz >> (m - L), leaves_only=False)
                place = row[idx // CELLS] * CELLS + idx % CELLS
                w = 1.0 / 8.0 ** (m - L)
                cells = np.tile(np.arange(CELLS), blocks.size)
                vals = _cell_rows(old_fields[m], np.repeat(blocks, CELLS), cells)
                for k in range(ncomp):      # np.add.at, by bincount (ten times quicker on millions of cells)
                    acc[:, k] += w * np.bincount(place, weights=vals[:, k], minlength=len(acc))
                weight += w * np.bincount(place, minlength=len(acc))
        if not np.allclose(weight, 1.0, rtol=0.0, atol=1e-12):
            bad = int(np.count_nonzero(np.abs(weight - 1.0) > 1e-12))
            raise RuntimeError(f"regrid: {bad} cells of level {L} are not covered exactly once by the old leaves")
        out = np.moveaxis(acc.reshape(sel.size, CELLS, ncomp), 1, -1).reshape((sel.size, *dst.shape[1:]))
        dst[sel] = out.astype(dst.dtype, copy=False)


def same_blocks(old_view: LevelView, new_view: LevelView) -> tuple[np.ndarray, np.ndarray]:
    """The blocks (leaves and ghosts) of one level at the same place in two forests: index arrays (old, new) of
    equal length, so that per-cell state that only that level holds (a body's cell owners, the cell flags a
    coupling sets) is carried by ``new[b_new] = old[b_old]``."""
    if old_view.level != new_view.level:
        raise ValueError(f"same_blocks compares one level: {old_view.level} and {new_view.level}")
    old_idx = _block_at(old_view, np.asarray(new_view.forest.origin, dtype=np.int64))
    hit = old_idx >= 0
    return old_idx[hit].astype(np.int64), np.flatnonzero(hit).astype(np.int64)


def any_in_boxes(mask: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether any True cell of ``mask`` (a bool array on the level-0 cells) overlaps each box [lo, hi) (corners in
    level-0 cell units, (n, 3)); a box smaller than a cell looks at the cell that holds it. By a summed-volume table:
    O(1) per box."""
    shape = np.array(mask.shape, dtype=np.int64)
    s = np.zeros(tuple(shape + 1), dtype=np.int64)
    s[1:, 1:, 1:] = mask.astype(np.int64).cumsum(0).cumsum(1).cumsum(2)
    i0 = np.clip(np.floor(lo).astype(np.int64), 0, shape)
    i1 = np.clip(np.ceil(hi).astype(np.int64), 0, shape)
    i1 = np.maximum(i1, np.minimum(i0 + 1, shape))
    a0, b0, c0 = i0.T
    a1, b1, c1 = i1.T
    total = (s[a1, b1, c1] - s[a0, b1, c1] - s[a1, b0, c1] - s[a1, b1, c0]
             + s[a0, b0, c1] + s[a0, b1, c0] + s[a1, b0, c0] - s[a0, b0, c0])
    return total > 0


def vorticity_magnitude(u: np.ndarray, dx: float = 1.0) -> np.ndarray:
    """|curl u| of a velocity ``u`` (3, nx, ny, nz) on a uniform grid of spacing ``dx`` (central differences,
    one-sided at the edges): 1/s for u in m/s and dx in m."""
    grads = [np.gradient(u[a], dx) for a in range(3)]        # grads[a][b] = d u_a / d x_b
    wx = grads[2][1] - grads[1][2]
    wy = grads[0][2] - grads[2][0]
    wz = grads[1][0] - grads[0][1]
    return np.sqrt(wx * wx + wy * wy + wz * wz)
