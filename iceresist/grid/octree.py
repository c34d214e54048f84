"""The block octree of adaptive refinement: levels 0..L of 8x8x8-cell blocks (paper section 2.5, fig. 1).

Level 0 is the coarsest: the domain is ``root`` = (nbx, nby, nbz) blocks of 8^3 cells of size dx_0. A block of
level l has cells of size dx_0 / 2^l and integer block coordinates ``coord`` at its own level (its low corner lies at
``coord * 8`` cells of level l). Splitting a block gives its eight children at level l + 1, coordinates
``2 coord + (i, j, k)``. The leaves (blocks that are not split) cover the domain exactly once; they are what holds
cells.

* **Refinement**: :meth:`BlockOctree.refine` splits every leaf whose box a criterion wants finer, level by level;
* **2:1 balance** across faces, edges and corners (:meth:`BlockOctree.balance`): two leaves that touch, even at a
  corner, differ by at most one level, so every level interface interpolates between neighbouring levels only
  (waLBerla's rule, Schornbaum and Ruede 2016);
* **Morton order over all levels**: leaves sorted by the Z-order key of their low corner at the finest level
  (``coord << (L - level)``), which is the depth-first order of the octree, so a contiguous range of leaves is a
  compact piece of the domain (what an MPI partition along the curve cuts);
* **neighbour tables** per leaf and block offset ``k = 13 + ox + 3 oy + 9 oz`` (the order of
  :class:`~iceresist.grid.forest.BlockForest`'s ``nbr_key``): ``nbr_same[b, k]`` the leaf of the same level,
  ``nbr_coarse[b, k]`` the leaf one level coarser that holds the neighbouring region, ``nbr_fine[b, k, :]`` the
  leaves one level finer that touch the block there (4 across a face, 2 across an edge, 1 at a corner; -1 padded).
  Exactly one of the three is set where the neighbour region lies in the domain (periodic axes wrap); none where it
  lies beyond a closed face.

All of it is integer NumPy on the host; the kernels get flat arrays per level from it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from iceresist.errors import InputError
from iceresist.grid.forest import BLOCK, morton_key

#: The 26 block offsets (ox, oy, oz) and (0, 0, 0), in key order k = 13 + ox + 3 oy + 9 oz.
OFFSETS = np.array([(ox, oy, oz) for oz in (-1, 0, 1) for oy in (-1, 0, 1) for ox in (-1, 0, 1)], dtype=np.int64)
#: The eight child offsets (i, j, k), i fastest.
CHILDREN = np.array([(i, j, k) for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=np.int64)


def _touching_children(offset) -> np.ndarray:
    """Child offsets of the block at ``offset`` from a block B that touch B: along an axis with o = +1 the low
    half (0), with o = -1 the high half (1), with o = 0 both."""
    rows = [c for c in CHILDREN if all(o == 0 or c[a] == (0 if o > 0 else 1) for a, o in enumerate(offset))]
    return np.array(rows, dtype=np.int64)


class BlockOctree:
    """Leaves ``level[n]``, ``coord[n, 3]`` of an octree of 8x8x8-cell blocks over ``root`` level-0 blocks.

    ``periodic``: per axis, whether the domain wraps (neighbours across that face exist). ``max_level``: the
    finest level allowed (L).
    """

    def __init__(self, root, max_level: int, periodic=(False, False, False)):
        self.root = np.array([int(n) for n in root], dtype=np.int64)
        if self.root.shape != (3,) or (self.root <= 0).any():
            raise InputError(f"root: three positive block counts (nbx, nby, nbz), got {root!r}")
        if not 0 <= int(max_level) <= 15:
            raise InputError(f"max_level: 0 to 15 levels of refinement, got {max_level!r}")
        self.max_level = int(max_level)
        self.periodic = np.array([bool(p) for p in periodic])
        bx, by, bz = np.meshgrid(*(np.arange(n) for n in self.root), indexing="ij")
        self.level = np.zeros(bx.size, dtype=np.int64)
        self.coord = np.stack([bx.ravel(), by.ravel(), bz.ravel()], axis=1).astype(np.int64)
        self._order()

    @classmethod
    def from_leaves(cls, root, max_level: int, periodic, level, coord) -> "BlockOctree":
        """The octree whose leaves are (``level``, ``coord``) (e.g. a checkpoint's; the caller checks that they
        tile the domain)."""
        t = cls(root, max_level, periodic=periodic)
        t.level = np.asarray(level, dtype=np.int64).copy()
        t.coord = np.asarray(coord, dtype=np.int64).reshape(-1, 3).copy()
        t._order()
        return t

    # ------------------------------------------------------------------ keys and lookup
    @property
    def nleaves(self) -> int:
        return len(self.level)

    def shape_at(self, level) -> np.ndarray:
        """Blocks per axis at ``level``."""
        return self.root << np.int64(level)

    def _key(self, level, coord) -> np.ndarray:
        """A unique int64 per (level, coord): the levels' block grids numbered one after the other."""
        level = np.asarray(level, dtype=np.int64)
        shape = self.root[None, :] << level[..., None] if level.ndim else self.root << level
        cells = np.prod(self.root) * (8 ** np.arange(self.max_level + 2, dtype=np.int64))
        offset = np.concatenate([[0], np.cumsum(cells)])[level]
        c = np.asarray(coord, dtype=np.int64)
        return offset + c[..., 0] + shape[..., 0] * (c[..., 1] + shape[..., 1] * c[..., 2])

    def _order(self):
        """Sort the leaves along the Morton curve at the finest level and rebuild the lookup."""
        fine = self.coord << (self.max_level - self.level)[:, None]
        order = np.argsort(morton_key(fine[:, 0], fine[:, 1], fine[:, 2]), kind="stable")
        self.level, self.coord = self.level[order], self.coord[order]
        keys = self._key(self.level, self.coord)
        self._sorted = np.argsort(keys)
        self._keys = keys[self._sorted]

    def find(self, level, coord) -> np.ndarray:
        """The leaf index of each (level, coord), -1 where that block is not a leaf."""
        k = self._key(level, coord)
        i = np.searchsorted(self._keys, k)
        i = np.minimum(i, len(self._keys) - 1)
        return np.where(self._keys[i] == k, self._sorted[i], -1)

    def leaf_at(self, level, coord):
        """For blocks (level, coord), possibly not leaves: the leaf that holds them (the block or an ancestor),
        returned as (index, leaf level); index -1 where finer leaves cover the block."""
        level = np.asarray(level, dtype=np.int64)
        coord = np.asarray(coord, dtype=np.int64)
        idx = np.full(level.shape, -1, dtype=np.int64)
        lev = np.full(level.shape, -1, dtype=np.int64)
        for up in range(self.max_level + 1):
            m = level - up
            todo = (idx < 0) & (m >= 0)
            if not todo.any():
                break
            hit = np.full(level.shape, -1, dtype=np.int64)
            hit[todo] = self.find(m[todo], coord[todo] >> up)
            new = todo & (hit >= 0)
            idx[new], lev[new] = hit[new], m[new]
        return idx, lev

    def neighbour_coords(self, level, coord, offset):
        """Coordinates of the block at ``offset`` from each (level, coord), wrapped on periodic axes; ``inside``
        False where it lies beyond a closed face."""
        shape = self.root[None, :] << np.asarray(level, dtype=np.int64)[:, None]
        t = coord + np.asarray(offset, dtype=np.int64)[None, :]
        inside = np.ones(len(t), dtype=bool)
        for a in range(3):
            out = (t[:, a] < 0) | (t[:, a] >= shape[:, a])
            if self.periodic[a]:
                t[:, a] %= shape[:, a]
            else:
                inside &= ~out
        return t, inside

    # ------------------------------------------------------------------ refinement
    def _split(self, which: np.ndarray):
        """Replace the leaves ``which`` (bool mask) by their eight children."""
        if not which.any():
            return
        lv, co = self.level[which], self.coord[which]
        kids = (2 * co[:, None, :] + CHILDREN[None, :, :]).reshape(-1, 3)
        self.level = np.concatenate([self.level[~which], np.repeat(lv + 1, 8)])
        self.coord = np.concatenate([self.coord[~which], kids])
        self._order()

    def box(self, level=None, coord=None):
        """Low and high corners of leaves (default all) in level-0 cell units (float64)."""
        level = self.level if level is None else np.asarray(level)
        coord = self.coord if coord is None else np.asarray(coord)
        size = BLOCK / (2.0 ** level)[:, None]
        lo = coord * size
        return lo, lo + size

    def refine(self, wanted: Callable[[np.ndarray, np.ndarray], np.ndarray]):
        """Split leaves, coarsest first, until none is coarser than ``wanted(lo, hi)`` says (an int level per
        leaf box, corners in level-0 cell units; capped at ``max_level``), then :meth:`balance`."""
        for _ in range(self.max_level):
            lo, hi = self.box()
            want = np.minimum(np.asarray(wanted(lo, hi), dtype=np.int64), self.max_level)
            split = want > self.level
            if not split.any():
                break
            self._split(split)
        self.balance()
        return self

    def balance(self):
        """Split leaves until any two that touch (across a face, an edge or a corner) differ by at most one level."""
        while True:
            coarse = np.zeros(self.nleaves, dtype=bool)
            fine = self.level >= 2
            lv, co = self.level[fine], self.coord[fine]
            for off in OFFSETS:
                if not off.any():
                    continue
                t, inside = self.neighbour_coords(lv, co, off)
                idx, lev = self.leaf_at(lv[inside], t[inside])
                bad = (idx >= 0) & (lev < lv[inside] - 1)
                coarse[idx[bad]] = True
            if not coarse.any():
                return self
            self._split(coarse)

    # ------------------------------------------------------------------ neighbours
    def neighbours(self):
        """``(nbr_same, nbr_coarse, nbr_fine)``: int32 arrays (n, 27) and (n, 27, 4), -1 where none (see the
        module docstring). Requires a balanced tree."""
        n = self.nleaves
        same = np.full((n, 27), -1, dtype=np.int32)
        coarse = np.full((n, 27), -1, dtype=np.int32)
        fine = np.full((n, 27, 4), -1, dtype=np.int32)
        for k, off in enumerate(OFFSETS):
            if not off.any():
                continue
            t, inside = self.neighbour_coords(self.level, self.coord, off)
            rows = np.flatnonzero(inside)
            idx, lev = self.leaf_at(self.level[rows], t[rows])
            is_same = (idx >= 0) & (lev == self.level[rows])
            is_coarse = (idx >= 0) & (lev == self.level[rows] - 1)
            if ((idx >= 0) & (lev < self.level[rows] - 1)).any():
                raise InputError("the octree is not 2:1 balanced: call balance() first")
            same[rows[is_same], k] = idx[is_same]
            coarse[rows[is_coarse], k] = idx[is_coarse]
            deeper = rows[idx < 0]
            kids = _touching_children(off)
            for j, c in enumerate(kids):
                found = self.find(self.level[deeper] + 1, 2 * t[inside][idx < 0] + c[None, :])
                if (found < 0).any():
                    raise InputError("the octree is not 2:1 balanced: call balance() first")
                fine[deeper, k, j] = found
        return same, coarse, fine

    # ------------------------------------------------------------------ summaries
    def blocks_per_level(self) -> np.ndarray:
        return np.bincount(self.level, minlength=self.max_level + 1)

    def cells_per_level(self) -> np.ndarray:
        return self.blocks_per_level() * BLOCK ** 3

    def updates_per_step(self) -> int:
        """Cell updates of the leaves in one level-0 step: a leaf of level l steps 2^l times."""
        return int(self.cells_per_level() @ (2 ** np.arange(self.max_level + 1)))

    def level_map(self) -> np.ndarray:
        """The level of the leaf over each block of the finest level's block grid (shape ``shape_at(max_level)``,
        int8): a leaf of level l fills its 8^(L - l) finest blocks."""
        out = np.zeros(tuple(self.root), dtype=np.int8)
        for lv in range(1, self.max_level + 1):
            out = out.repeat(2, axis=0).repeat(2, axis=1).repeat(2, axis=2)
            c = self.coord[self.level == lv]
            out[c[:, 0], c[:, 1], c[:, 2]] = lv
        return out

    def covers(self, other: "BlockOctree") -> bool:
        """Whether this octree is at least as fine as ``other`` (same root and levels) everywhere: every place a leaf
        of ``other`` holds lies on leaves of its level or finer here."""
        return bool((self.level_map() >= other.level_map()).all())

    def __repr__(self):
        per = ", ".join(f"L{lv}: {n}" for lv, n in enumerate(self.blocks_per_level()))
        return f"BlockOctree(root={tuple(int(n) for n in self.root)}, leaves={self.nleaves} ({per}))"
