"""Block forest: 8x8x8-cell blocks, neighbour table, Morton order (docs/ARCHITECTURE.md, paper section 2.5)."""

from iceresist.grid.forest import BlockForest, Face
from iceresist.grid.octree import BlockOctree

__all__ = ["BlockForest", "BlockOctree", "Face"]
