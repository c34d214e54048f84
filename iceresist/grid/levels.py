"""One level of a block octree as the block forest the LBM steps (paper section 2.5).

The cells of level l are those of the octree's leaves at level l. Their fused stream-collide step pulls from the
26 neighbouring cells, so a level also holds **ghost blocks**: the blocks of level l next to its leaves that are not
leaves themselves, each lying either inside one leaf of level l - 1 (filled by interpolation from the coarser level)
or over leaves of level l + 1 (filled by averaging the finer level), :mod:`iceresist.lbm.refinement`. With 2:1
balance no other case occurs next to a leaf. A level's :class:`~iceresist.grid.forest.BlockForest` lists its leaves
first (Morton order), then its ghosts; blocks beyond both are not allocated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iceresist.grid.forest import BLOCK, CELLS, BlockForest, _check_faces, cell_coordinates, morton_key
from iceresist.grid.octree import OFFSETS, BlockOctree

#: Where a ghost block's values come from.
FROM_COARSER, FROM_FINER = -1, 1


@dataclass
class LevelView:
    """Level ``level`` of an octree: ``forest`` (leaves ``[0, nleaves)``, ghosts after them), the octree leaf of
    each leaf block (``leaf_index``) and the source of each ghost block (``ghost_source``: FROM_COARSER or
    FROM_FINER)."""

    level: int
    forest: BlockForest
    nleaves: int
    leaf_index: np.ndarray
    ghost_source: np.ndarray

    @property
    def nghosts(self) -> int:
        return self.forest.nblocks - self.nleaves

    @property
    def block_map(self) -> np.ndarray:
        """(nbx, nby, nbz) int64 at this level: the forest block at each block position, -1 where none."""
        if getattr(self, "_block_map", None) is None:
            m = np.full(self.forest.shape_blocks, -1, dtype=np.int64)
            o = self.forest.origin
            m[o[:, 0], o[:, 1], o[:, 2]] = np.arange(self.forest.nblocks)
            self._block_map = m
        return self._block_map


def level_views(octree: BlockOctree, faces: dict | None = None, solid=None) -> list[LevelView]:
    """The :class:`LevelView` of every level of ``octree`` that has leaves (a list indexed by level; None for a
    level without leaves). ``faces`` as for :meth:`BlockForest.uniform`; periodic faces must match the octree's
    ``periodic``. ``solid(x, y, z)``: as for :meth:`BlockForest.uniform`, the solid cells of level 0 (integer
    level-0 cell indices; the padding of ``domain.pad_to_blocks``, which only a grid of one level has)."""
    faces = _check_faces(faces)
    views: list[LevelView | None] = []
    for lv in range(octree.max_level + 1):
        leaves = np.flatnonzero(octree.level == lv)
        if len(leaves) == 0:
            views.append(None)
            continue
        co = octree.coord[leaves]
        ghosts = set()
        for off in OFFSETS:
            if not off.any():
                continue
            t, inside = octree.neighbour_coords(np.full(len(co), lv), co, off)
            t = t[inside]
            is_leaf = octree.find(np.full(len(t), lv), t) >= 0
            ghosts.update(map(tuple, t[~is_leaf].tolist()))
        g = np.array(sorted(ghosts), dtype=np.int64).reshape(-1, 3)
        idx, lev = octree.leaf_at(np.full(len(g), lv), g)
        source = np.where(idx >= 0, FROM_COARSER, FROM_FINER).astype(np.int8)
        if len(g):
            order = np.argsort(morton_key(g[:, 0], g[:, 1], g[:, 2]), kind="stable")
            g, source = g[order], source[order]
        origin = np.concatenate([co, g])
        shape_cells = tuple(int(n) * BLOCK << lv for n in octree.root)
        fluid = np.ones((len(origin), CELLS), dtype=bool)
        if solid is not None and lv == 0:
            fluid = ~np.asarray(solid(*cell_coordinates(origin)), dtype=bool)
        forest = BlockForest(shape_cells, faces, np.full(len(origin), lv), origin, fluid)
        views.append(LevelView(lv, forest, len(leaves), leaves, source))
    return views
