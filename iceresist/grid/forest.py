"""A forest of 8x8x8-cell blocks ordered along the Morton curve (paper section 2.5, fig. 1).

A uniform grid is a forest of blocks of one level; adaptive refinement adds
levels to the same structure: every block stores its level and integer block
coordinates, and the neighbour table is built from a dictionary keyed by
``(level, bx, by, bz)``. The levels of adaptive refinement (which blocks exist at which level, 2:1 balance,
Morton order over all levels, coarser and finer neighbours) come from :class:`iceresist.grid.octree.BlockOctree`;
the LBM steps one level's blocks at a time.

Layout: values live per block, ``v[block, cell]`` with ``cell = x + 8*(y + 8*z)``
(x fastest). Populations are ``f[block, q, cell]``. Blocks without any fluid
cell are not allocated, so memory follows the fluid.

Neighbour tables:

* ``nbr[block, q]``: the block in lattice direction ``C[q]`` (``iceresist.lattice``
  order), -1 where it lies outside the domain or is not allocated;
* ``nbr_key[block, k]``: the same in the order ``k = 13 + ox + 3*oy + 9*oz`` that
  the kernels compute from a cell offset (``ox = sx >> 3`` for ``sx`` in [-1, 8]);
* ``link_bc[block, k]``: where ``nbr_key`` is -1, the row of the boundary table
  (``bc_kind``, ``bc_velocity``, ``bc_density``) that applies: row 0 is a resting
  wall (solid, unallocated block), rows 1-6 the faces x-, x+, y-, y+, z-, z+.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from iceresist.errors import InputError
from iceresist.grid import flags as FL
from iceresist.lattice import C, Q, index_of

BLOCK = 8
CELLS = BLOCK ** 3
FACE_NAMES = ("x-", "x+", "y-", "y+", "z-", "z+")
FACE_KINDS = ("periodic", "wall", "moving_wall", "velocity_inlet", "pressure_outlet", "slip")

#: Lattice index q of the block offset with key k = (ox+1) + 3*(oy+1) + 9*(oz+1).
Q_OF_KEY = np.array([index_of(ox, oy, oz) for oz in (-1, 0, 1) for oy in (-1, 0, 1) for ox in (-1, 0, 1)],
                    dtype=np.int64)

_LOCAL = np.arange(CELLS)
LX, LY, LZ = _LOCAL & 7, (_LOCAL >> 3) & 7, _LOCAL >> 6


@dataclass(frozen=True)
class Face:
    """Boundary condition on one domain face; ``velocity`` and ``density`` in lattice units."""

    kind: str
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    density: float = 1.0

    def __post_init__(self):
        if self.kind not in FACE_KINDS:
            raise InputError(f"face kind {self.kind!r} is not one of {', '.join(FACE_KINDS)}")
        if len(tuple(self.velocity)) != 3:
            raise InputError(f"face velocity must have 3 components, got {self.velocity!r}")
        if not self.density > 0.0:
            raise InputError(f"face density must be positive (lattice units), got {self.density!r}")


def morton_key(bx, by, bz, bits: int = 21):
    """Z-order key interleaving the bits of the block coordinates (x lowest)."""
    bx, by, bz = (np.asarray(a, dtype=np.uint64) for a in (bx, by, bz))
    key = np.zeros(np.broadcast(bx, by, bz).shape, dtype=np.uint64)
    for i in range(bits):
        one = np.uint64(1)
        for a, arr in enumerate((bx, by, bz)):
            key |= ((arr >> np.uint64(i)) & one) << np.uint64(3 * i + a)
    return key


def _check_faces(faces):
    faces = dict(faces or {})
    unknown = set(faces) - set(FACE_NAMES)
    if unknown:
        raise InputError(f"faces: unknown key(s) {sorted(unknown)}; use {', '.join(FACE_NAMES)}")
    out = {}
    for name in FACE_NAMES:
        face = faces.get(name, Face("periodic"))
        if not isinstance(face, Face):
            raise InputError(f"faces[{name!r}] must be a Face, got {type(face).__name__}")
        out[name] = face
    for axis in "xyz":
        lo, hi = out[axis + "-"], out[axis + "+"]
        if (lo.kind == "periodic") != (hi.kind == "periodic"):
            raise InputError(f"faces {axis}- and {axis}+: periodic faces must be paired "
                             f"(got {lo.kind!r} and {hi.kind!r})")
    return out


def cell_coordinates(origin):
    """Global integer cell coordinates (x, y, z), each (nblocks, 512), of the blocks at ``origin`` (nblocks, 3)."""
    o = np.asarray(origin) * BLOCK
    return o[:, 0:1] + LX, o[:, 1:2] + LY, o[:, 2:3] + LZ


class BlockForest:
    """Blocks of 8x8x8 cells, Morton-ordered, with a D3Q27 neighbour table and cell flags."""

    block_size = BLOCK

    def __init__(self, shape_cells, faces, levels, origin, fluid_mask):
        self.shape_cells = tuple(int(n) for n in shape_cells)
        self.shape_blocks = tuple(n // BLOCK for n in self.shape_cells)
        self.faces = faces
        self.levels = np.asarray(levels, dtype=np.int32)
        self.level = int(self.levels.max()) if self.levels.size else 0
        self.origin = np.asarray(origin, dtype=np.int64).reshape(-1, 3)
        self.nblocks = len(self.origin)
        self.morton = morton_key(self.origin[:, 0], self.origin[:, 1], self.origin[:, 2])
        self.index = {(int(lv), *map(int, o)): i for i, (lv, o) in enumerate(zip(self.levels, self.origin))}
        self._build_boundary_table()
        self._build_neighbours()
        self._build_flags(np.asarray(fluid_mask, dtype=bool))

    # ------------------------------------------------------------------ construction
    @classmethod
    def uniform(cls, shape_cells, faces: dict | None = None, solid: Callable | None = None, level: int = 0):
        """A uniform forest of ``shape_cells`` (multiples of 8) cells.

        ``faces``: {"x-": Face(...), ...}, default all periodic. ``solid(x, y, z)``: optional
        callable on integer cell-index arrays returning True for solid cells; blocks
        without fluid are not allocated.
        """
        shape_cells = tuple(shape_cells)
        if len(shape_cells) != 3:
            raise InputError(f"shape_cells must have 3 entries (nx, ny, nz), got {shape_cells!r}")
        for axis, n in zip("xyz", shape_cells):
            if int(n) != n or n <= 0 or n % BLOCK:
                raise InputError(f"shape_cells {axis}: {n} cells is not a positive multiple of {BLOCK}; "
                                 f"round the {axis} resolution to a multiple of {BLOCK}")
        faces = _check_faces(faces)
        nbx, nby, nbz = (int(n) // BLOCK for n in shape_cells)
        nx, ny, _ = (int(n) for n in shape_cells)
        if solid is None:
            fluid_blocks = np.ones((nbx, nby, nbz, CELLS), dtype=bool)
        else:
            fluid_blocks = np.empty((nbx, nby, nbz, CELLS), dtype=bool)
            x, y = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
            for bz in range(nbz):   # one layer of blocks at a time bounds the memory
                xs = np.repeat(x[:, :, None], BLOCK, axis=2)
                ys = np.repeat(y[:, :, None], BLOCK, axis=2)
                zs = np.broadcast_to(np.arange(bz * BLOCK, (bz + 1) * BLOCK), xs.shape)
                mask = np.asarray(solid(xs, ys, zs), dtype=bool)
                if mask.shape != xs.shape:
                    raise InputError(f"solid(x, y, z) must return a mask of the shape of its inputs {xs.shape}, "
                                     f"got {mask.shape}")
                m = (~mask).reshape(nbx, BLOCK, nby, BLOCK, BLOCK)          # (bx, lx, by, ly, lz)
                fluid_blocks[:, :, bz] = m.transpose(0, 2, 4, 3, 1).reshape(nbx, nby, CELLS)
        bx, by, bz = np.meshgrid(np.arange(nbx), np.arange(nby), np.arange(nbz), indexing="ij")
        keep = fluid_blocks.any(axis=3)
        origin = np.stack([bx[keep], by[keep], bz[keep]], axis=1)
        order = np.argsort(morton_key(origin[:, 0], origin[:, 1], origin[:, 2]), kind="stable")
        origin = origin[order]
        fluid = fluid_blocks[keep][order]
        return cls(shape_cells, faces, np.full(len(origin), level), origin, fluid)

    def _build_boundary_table(self):
        """Rows: 0 resting wall (solids), 1-6 the faces x-, x+, y-, y+, z-, z+."""
        kinds, vel, rho = [FL.BC_WALL], [(0.0, 0.0, 0.0)], [1.0]
        for name in FACE_NAMES:
            face = self.faces[name]
            kinds.append(FL.BC_OF_KIND.get(face.kind, FL.BC_WALL))
            vel.append(tuple(float(v) for v in face.velocity))
            rho.append(float(face.density))
        self.bc_kind = np.array(kinds, dtype=np.int32)
        self.bc_velocity = np.array(vel, dtype=np.float64)
        self.bc_density = np.array(rho, dtype=np.float64)

    def _build_neighbours(self):
        """nbr[b, q]: the block at origin + c_q of the same level (-1: none); periodic faces wrap, and where c_q
        leaves the domain through closed faces, link_bc[b, q] is 1 + the face (of the crossed ones, the first by
        :data:`~iceresist.grid.flags.FACE_PRIORITY`, then by name)."""
        n = np.array(self.shape_blocks, dtype=np.int64)
        periodic = np.array([self.faces[a + "-"].kind == "periodic" for a in "xyz"])
        t = self.origin[:, None, :] + C[None, :, :].astype(np.int64)             # (nblocks, Q, 3)
        above = t >= n
        out = ((t < 0) | above) & ~periodic
        t = np.where(periodic & (n > 0), t % np.maximum(n, 1), t)
        face = 2 * np.arange(3) + above                                          # the face crossed on each axis
        rank = np.array([FL.FACE_PRIORITY.get(self.faces[name].kind, 99) for name in FACE_NAMES]) * 8
        key = np.where(out, rank[face] + face, 1 << 20)
        crossed = out.any(axis=2)
        first = np.take_along_axis(face, key.argmin(axis=2)[..., None], axis=2)[..., 0]
        link_bc = np.where(crossed, 1 + first, 0).astype(np.int32)
        if self.nblocks and ((self.levels != self.levels[0]).any() or (self.origin < 0).any()
                             or (self.origin >= n).any()):
            raise ValueError("a BlockForest holds blocks of one level inside its domain")
        # one level: the neighbours from a dense map of the blocks
        bmap = np.full(tuple(int(v) for v in n), -1, dtype=np.int32)
        bmap[tuple(self.origin.T)] = np.arange(self.nblocks, dtype=np.int32)
        nbr = np.full((self.nblocks, Q), -1, dtype=np.int32)
        inside = ~crossed
        ti = t[inside]
        nbr[inside] = bmap[ti[:, 0], ti[:, 1], ti[:, 2]]
        self.nbr = nbr
        self.nbr_key = np.ascontiguousarray(nbr[:, Q_OF_KEY])
        self.link_bc = np.ascontiguousarray(link_bc[:, Q_OF_KEY])

    def pull_source(self, q: int, blocks=None):
        """For every (block, cell): the block and cell that direction q pulls from (x - c_q).

        Returns ``(nb, sc, bc)`` int arrays (nblocks, 512): the source block (-1 where the
        link leaves the domain or reaches an unallocated block), the source cell, and the
        boundary-table row used where ``nb`` is -1. ``blocks``: those blocks' rows only (len(blocks), 512).
        """
        cx, cy, cz = (int(v) for v in C[q])
        sx, sy, sz = LX - cx, LY - cy, LZ - cz
        key = 13 + (sx >> 3) + 3 * (sy >> 3) + 9 * (sz >> 3)
        sc = (sx & 7) + 8 * ((sy & 7) + 8 * (sz & 7))
        nbr, link = (self.nbr_key, self.link_bc) if blocks is None else (self.nbr_key[blocks], self.link_bc[blocks])
        nb = nbr[:, key]
        bc = link[:, key]
        return nb, np.broadcast_to(sc, nb.shape), bc

    def _build_flags(self, fluid):
        """FLUID or SOLID per cell, NEAR_WALL on a fluid cell that pulls from a solid cell or through a closed face
        (not an outlet), NEAR_OUTLET on one that pulls through an outlet. Only the blocks that are not wholly fluid
        with 26 wholly fluid neighbours are looked at cell by cell (the others are FLUID throughout)."""
        flags = np.where(fluid, FL.FLUID, FL.SOLID).astype(np.uint8)
        full = fluid.all(axis=1)
        inner = full & (self.nbr_key >= 0).all(axis=1)
        inner[inner] = full[self.nbr_key[inner]].all(axis=1)
        rest = np.flatnonzero(~inner)
        if len(rest):
            own = fluid[rest]
            near_wall = np.zeros(own.shape, dtype=bool)
            near_outlet = np.zeros(own.shape, dtype=bool)
            for q in range(1, Q):
                nb, sc, bc = self.pull_source(q, rest)
                inside = nb >= 0
                src_fluid = np.zeros(own.shape, dtype=bool)
                src_fluid[inside] = fluid[nb[inside], sc[inside]]
                outlet = ~inside & (self.bc_kind[bc] == FL.BC_OUTLET)
                near_outlet |= outlet
                near_wall |= ~src_fluid & ~outlet
            sub = flags[rest]
            sub[own & near_wall] |= FL.NEAR_WALL
            sub[own & near_outlet] |= FL.NEAR_OUTLET
            flags[rest] = sub
        self.flags = flags
        self.fluid = fluid
        self.cells = int(fluid.sum())

    # ------------------------------------------------------------------ dense views
    def to_dense(self, values, z_blocks: tuple[int, int] | None = None):
        """Per-block values (nblocks, 512) or (k, nblocks, 512) -> dense (nx, ny, nz) or (k, nx, ny, nz),
        float64, NaN where no block is allocated; ``z_blocks`` (lo, hi): only the layers of blocks lo <= bz < hi,
        (nx, ny, 8 (hi - lo)) cells from z = 8 lo."""
        v = np.asarray(values, dtype=np.float64)
        single = v.ndim == 2
        if single:
            v = v[None]
        if v.shape[1:] != (self.nblocks, CELLS):
            raise InputError(f"to_dense: values must have shape (nblocks={self.nblocks}, {CELLS}) "
                             f"or (k, {self.nblocks}, {CELLS}), got {np.shape(values)}")
        k = v.shape[0]
        nbx, nby, nbz = self.shape_blocks
        o = self.origin
        lo, hi = (0, nbz) if z_blocks is None else (max(int(z_blocks[0]), 0), min(int(z_blocks[1]), nbz))
        pick = slice(None) if z_blocks is None else np.flatnonzero((o[:, 2] >= lo) & (o[:, 2] < hi))
        dense = np.full((k, nbx, nby, hi - lo, BLOCK, BLOCK, BLOCK), np.nan)
        o = o[pick]
        dense[:, o[:, 0], o[:, 1], o[:, 2] - lo] = v[:, pick].reshape(k, len(o), BLOCK, BLOCK, BLOCK).transpose(
            0, 1, 4, 3, 2)
        dense = dense.transpose(0, 1, 4, 2, 5, 3, 6).reshape(k, nbx * BLOCK, nby * BLOCK, (hi - lo) * BLOCK)
        return dense[0] if single else dense

    def from_dense(self, array):
        """Dense (nx, ny, nz) or (k, nx, ny, nz) -> per-block (nblocks, 512) or (k, nblocks, 512)."""
        a = np.asarray(array)
        single = a.ndim == 3
        if single:
            a = a[None]
        if a.shape[1:] != self.shape_cells:
            raise InputError(f"from_dense: array must have shape {self.shape_cells} or (k, *{self.shape_cells}), "
                             f"got {np.shape(array)}")
        k = a.shape[0]
        nbx, nby, nbz = self.shape_blocks
        b = a.reshape(k, nbx, BLOCK, nby, BLOCK, nbz, BLOCK).transpose(0, 1, 3, 5, 6, 4, 2)
        o = self.origin
        out = np.ascontiguousarray(b[:, o[:, 0], o[:, 1], o[:, 2]].reshape(k, self.nblocks, CELLS))
        return out[0] if single else out

    def cell_coordinates(self):
        """Global integer cell coordinates (x, y, z), each (nblocks, 512)."""
        return cell_coordinates(self.origin)

    def __repr__(self):
        return (f"BlockForest(shape_cells={self.shape_cells}, nblocks={self.nblocks}, cells={self.cells}, "
                f"level={self.level})")
