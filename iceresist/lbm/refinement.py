"""The LBM on the levels of a block octree: acoustic scaling, sub-cycling and the level interfaces (paper section
2.5, fig. 1).

Acoustic scaling: level l + 1 halves the cell and the time step of level l, so lattice velocities are the same on
every level, the lattice viscosity doubles (tau_{l+1} - 1/2 = 2 (tau_l - 1/2), the same physical viscosity) and a
body-force acceleration halves (g dt^2 / dx). Sub-cycling: one step of level l is two steps of level l + 1.

Level interfaces, through the ghost blocks of each level (:mod:`iceresist.grid.levels`), two schemes:

* ``'conservative'`` (default; Rohde et al. 2006, "A generic, mass conservative local grid refinement technique for
  lattice-Boltzmann schemes"): the finer level steps first. A coarse cell is cut into eight homogeneous fine packets
  that stream without colliding (explosion): the fine leaves pull at each sub-step the packets that reach them; then
  the coarse step pulls, for every population that crossed the interface, the mean of the eight fine packets that
  reached its sub-cells over the two sub-steps, each taken where it last collided (coalescence). Every packet is
  consumed once, so mass and momentum cross the interface exactly (mass to round-off: 2e-16 over 1000 steps). Where
  an interface meets a resting wall the packets follow the wall's bounce-back, and the coarse packets that the
  plain coarse bounce-back keeps whole are swapped out of the fine leaves' pulls (:func:`_take_free_packets`): the
  mass is exact there too.
  ``reconstruction='linear'`` (default) gives the packets of a coarse cell its value plus the central-difference
  gradient times the sub-cell's offset (+-1/4 cell; the eight still sum to the cell's mass): a Taylor-Green vortex
  with a refined centre decays at the fine grid's viscosity +0.34 %, where ``'constant'`` packets give +3.0 %;
* ``'interpolate'`` (the paper's): a ghost cell of level l + 1 inside a leaf of level l takes the trilinear
  interpolation of the post-collision populations f - w of the eight nearest cells of level l (at the half step
  from the mean of level l before and after its step), and a ghost cell of level l over level l + 1 the mean of
  its eight children. Not conservative (mass drifts about 7e-6 in 1000 steps); its non-equilibrium part needs the
  rescaling of Dupuis and Chopard (2003), (tau - 1) dx for post-collision populations (``rescale``), which the paper
  leaves out.

Every level's leaves are then stepped by the fused stream-collide kernel of the uniform grid
(:class:`~iceresist.lbm.solver.LBMSolver`); with the conservative interface its ghost blocks are not stepped (what a
leaf pulls from them is written by the transfers before the step, and no transfer reads their update: bit for bit
the same leaves as stepping them), with the interpolating one they are. The conservative transfers run as one
kernel on the target (:mod:`iceresist.lbm.exchange`, CPU or CUDA, the state never leaves the device); the
interpolating scheme runs in NumPy on the CPU.
"""

from __future__ import annotations

import numpy as np

from iceresist.backends import jit
from iceresist.errors import InputError
from iceresist.grid.forest import LX, LY, LZ
from iceresist.grid.levels import FROM_COARSER, FROM_FINER, LevelView, level_views
from iceresist.grid.octree import BlockOctree, CHILDREN
from iceresist.lattice import C, OPP
from iceresist.lbm.exchange import copy_blocks, pack_table, transfer_launcher
from iceresist.lbm.solver import LBMSolver, equilibrium_minus_w


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


def locate_cells(view: LevelView, pts, periodic):
    """(block, cell, inside) of global cells ``pts`` (..., 3) of ``view``'s level: wrapped on periodic axes;
    ``inside`` False beyond a closed face; block -1 where none is allocated."""
    n = np.array(view.forest.shape_cells)
    pts = np.array(pts, dtype=np.int64, copy=True)
    inside = np.ones(pts.shape[:-1], dtype=bool)
    for a in range(3):
        if periodic[a]:
            pts[..., a] %= n[a]
        else:
            inside &= (pts[..., a] >= 0) & (pts[..., a] < n[a])
            pts[..., a] = np.clip(pts[..., a], 0, n[a] - 1)
    b, c = _lookup(view, pts[..., 0], pts[..., 1], pts[..., 2], periodic)
    return b, c, inside


def _cells_of(view: LevelView, blocks):
    """Global cell coordinates (len(blocks), 512, 3) of the given blocks of ``view``."""
    o = view.forest.origin[blocks] * 8
    return np.stack([o[:, a:a + 1] + L for a, L in enumerate((LX, LY, LZ))], axis=-1)


#: Level-interface schemes: 'conservative' (explosion and coalescence of packets, Rohde et al. 2006: mass and
#: momentum cross the interface exactly) and 'interpolate' (the paper's trilinear interpolation of f coarse to fine,
#: the mean of the children fine to coarse).
SCHEMES = ("conservative", "interpolate")

#: Sources of a conservative transfer: the coarse state at t, the fine state at t, the fine state at t + 1/2.
COARSE_T, FINE_T, FINE_HALF = 0, 1, 2


def _side_cells() -> np.ndarray:
    """(27, 512) bool: for each neighbour key (ox + 3 oy + 9 oz, offsets -1..1 as 0..2, the order of
    ``nbr_key``), the cells of a block on the side facing that neighbour (every cell for the offset 0 of an axis)."""
    out = np.ones((27, 512), dtype=bool)
    for k in range(27):
        for a, local in enumerate((LX, LY, LZ)):
            o = (k // 3 ** a) % 3 - 1
            if o:
                out[k] &= local == (0 if o < 0 else 7)
    return out


_SIDE_CELLS = _side_cells()


def next_to_leaves(view: LevelView, blocks) -> np.ndarray:
    """(len(blocks), 512) bool: the cells of ``blocks`` of ``view``'s level that have a leaf cell of that level
    among their 26 neighbours (those on a block's side that faces a leaf block; the forest's neighbour table wraps
    periodic axes and has none beyond closed faces)."""
    nbr = view.forest.nbr_key[blocks]
    leaf = (nbr >= 0) & (nbr < view.nleaves)
    return (leaf[:, :, None] & _SIDE_CELLS[None, :, :]).any(axis=1)


def _coarse_stencil(coarse: LevelView, pos, periodic):
    """For packets at fine cells ``pos`` (..., 3) taken from their coarse cells: the offset of the sub-cell from
    its coarse cell's centre (coarse units, +-1/4 per axis) and the (block, cell) of the coarse neighbours at -1
    and +1 along each axis (the cell itself where a neighbour is missing), for a linear reconstruction."""
    pos = np.asarray(pos, dtype=np.int64)
    X = pos >> 1
    off = ((pos & 1) - 0.5) / 2.0
    b0, c0, _ = locate_cells(coarse, X, periodic)
    nbrs = []
    for a in range(3):
        for d in (-1, 1):
            e = np.zeros(3, dtype=np.int64)
            e[a] = d
            b, c, inside = locate_cells(coarse, X + e, periodic)
            ok = inside & (b >= 0)
            nbrs.append((np.where(ok, b, b0), np.where(ok, c, c0), ok))
    # one-sided where a neighbour is missing: the difference over the cells that exist
    return off, nbrs


def _wall_faces(view: LevelView) -> np.ndarray:
    """(3, 2) bool: whether the low and high face of each axis is a resting wall (half-way bounce-back)."""
    return np.array([[view.forest.faces[a + s].kind == "wall" for s in "-+"] for a in "xyz"])


def _beyond(p, n, walls, periodic):
    """For cells ``p`` (n, 3) of a level of ``n`` cells: whether each lies beyond a closed face, and whether every
    face it lies beyond is a resting wall (``walls``: :func:`_wall_faces`)."""
    crossed = np.zeros(len(p), dtype=bool)
    all_walls = np.ones(len(p), dtype=bool)
    for a in range(3):
        if periodic[a]:
            continue
        low, high = p[:, a] < 0, p[:, a] >= n[a]
        crossed |= low | high
        all_walls &= ~(low & ~walls[a, 0]) & ~(high & ~walls[a, 1])
    return crossed, all_walls


def _wrap(p, n, periodic):
    """Cells ``p`` (n, 3) of a level of ``n`` cells wrapped on the periodic axes (in place)."""
    for a in range(3):
        if periodic[a]:
            p[:, a] %= n[a]
    return p


def _arrival(fine: LevelView, s, d, steps: int, periodic):
    """Where the packets in slot ``d`` (n,) of fine cells ``s`` (n, 3) after ``steps`` (1 or 2) sub-steps last
    collided, following them back through cells of the coarser level (where they stream without colliding, as
    homogeneous packets of their coarse cell) and off the resting walls (half-way bounce-back, as the fused kernel:
    the packet in slot q of x whose x - c_q lies beyond a wall is the one of slot opp(q) of x a sub-step before).

    Returns (tag, block, cell, slot, position, ok), each (n,) but position (n, 3): a fine leaf at t + 1/2
    (FINE_HALF, after the first step back of two) or at t (FINE_T), else the coarse cell of ``position`` (COARSE_T;
    block and cell of the coarse level left to the caller); ``ok`` False where a path crosses a closed face that is
    not a resting wall."""
    n = np.array(fine.forest.shape_cells, dtype=np.int64)
    walls = _wall_faces(fine)
    s = np.array(s, dtype=np.int64, copy=True)
    d = np.array(d, dtype=np.int64, copy=True)
    tag = np.full(len(s), COARSE_T, dtype=np.int64)
    blk = np.zeros(len(s), dtype=np.int64)
    cel = np.zeros(len(s), dtype=np.int64)
    ok = np.ones(len(s), dtype=bool)
    moving = np.ones(len(s), dtype=bool)        # not yet found at a fine leaf
    for k in range(steps, 0, -1):
        p = s - C[d].astype(np.int64)
        crossed, all_walls = _beyond(p, n, walls, periodic)
        ok &= ~(moving & crossed & ~all_walls)
        back = moving & crossed
        p = np.where(back[:, None], s, p)
        d = np.where(back, OPP[d], d)
        pb, pc, _ = locate_cells(fine, p, periodic)
        leaf = moving & (pb >= 0) & (pb < fine.nleaves)
        tag = np.where(leaf, FINE_HALF if k == 2 else FINE_T, tag)
        blk, cel = np.where(leaf, pb, blk), np.where(leaf, pc, cel)
        s = np.where(moving[:, None], p, s)
        moving &= ~leaf
    return tag, blk, cel, d, _wrap(s, n, periodic), ok


def _coarse_row(coarse: LevelView, pos, d, periodic):
    """The coarse cell and slot that take the packet of slot ``d`` (n,) at fine cells ``pos`` (n, 3) when its coarse
    cell streams it without the finer level: the cell Z + c_d pulls it into slot d, or, beyond a resting wall, Z's
    own bounce-back into slot opp(d). Returns (cell (n, 3), slot (n,), fine cell (n, 3) where that row's picture of
    the step puts the packet: pos + 2 c_d, or pos itself after a bounce-back, ok (n,): False beyond another face)."""
    n = np.array(coarse.forest.shape_cells, dtype=np.int64)
    walls = _wall_faces(coarse)
    cd = C[d].astype(np.int64)
    Y = (pos >> 1) + cd
    crossed, all_walls = _beyond(Y, n, walls, periodic)
    _wrap(Y, n, periodic)
    cell = np.where(crossed[:, None], pos >> 1, Y)
    slot = np.where(crossed, OPP[d], d)
    to = _wrap(np.where(crossed[:, None], pos, pos + 2 * cd), 2 * n, periodic)
    return cell, slot, to, ~crossed | all_walls


def _sub_cell_keys(coarse: LevelView, to, slot) -> np.ndarray:
    """An int64 key per (fine cell ``to`` (n, 3) inside a coarse cell, the coarse row's slot): the sub-cell of a
    coarse row (the coarse cell and the population it pulls)."""
    n = np.array(coarse.forest.shape_cells, dtype=np.int64)
    cell = to >> 1
    child = (to[:, 0] & 1) + 2 * (to[:, 1] & 1) + 4 * (to[:, 2] & 1)
    return (((cell[:, 0] * n[1] + cell[:, 1]) * n[2] + cell[:, 2]) * 27 + slot) * 8 + child


def _in_sorted(keys: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Whether each of ``keys`` is in the sorted array ``table`` (np.isin without hashing ``table`` again at every
    call: a regrid's tables ask it of millions of sub-cells)."""
    if table.size == 0:
        return np.zeros(keys.shape, dtype=bool)
    i = np.minimum(np.searchsorted(table, keys), table.size - 1)
    return table[i] == keys


def _take_free_packets(fine: LevelView, coarse: LevelView, periodic, fed, slot, pos):
    """Where an interface meets a wall, the coarse packets (slot ``slot``, fine cell ``pos``) that the fine leaves
    pull across it, made free ones. Every coarse leaf's population takes the coarse packets its step would take
    (:func:`_coarse_row`: the plain stream, or the bounce-back that keeps a packet in its cell) except in the
    sub-cells the finer level feeds (``fed``, sorted: :func:`_sub_cell_keys` of the coalesced rows' sub-cells that
    take a fine packet); the packets those would have taken, and the ones that stream into the finer level, are the free
    ones. A packet the fine sub-steps (:func:`_arrival`) carry into a fine leaf is free except where a coarse wall
    row takes it whole: along a wall the coarse bounce-back keeps a packet in its cell where two fine sub-steps
    carry part of it into the next. Such a packet is swapped for the one the fine sub-steps bring to the sub-cell
    where the coarse step puts it, and so on until a free one (the maps are one to one and the chain never
    returns: mass crosses exactly). Returns the new (slot, pos); a chain through a face that is not a resting wall
    keeps its packet."""
    slot, pos = np.array(slot, dtype=np.int64, copy=True), np.array(pos, dtype=np.int64, copy=True)

    def taken(sl, ps):
        cell, row_slot, to, ok = _coarse_row(coarse, ps, sl, periodic)
        b, _, _ = locate_cells(coarse, cell, periodic)
        by_row = ok & (b >= 0) & (b < coarse.nleaves)
        at = np.flatnonzero(by_row)
        by_row[at] = ~_in_sorted(_sub_cell_keys(coarse, to[at], row_slot[at]), fed)
        return by_row, row_slot, to

    idx = np.arange(len(slot))
    by_row, row_slot, to = taken(slot, pos)
    idx, row_slot, to = idx[by_row], row_slot[by_row], to[by_row]
    for _ in range(16):
        if len(idx) == 0:
            break
        tag, _, _, s2, p2, ok = _arrival(fine, to, row_slot, 2, periodic)
        ok &= tag == COARSE_T
        idx, s2, p2 = idx[ok], s2[ok], p2[ok]
        by_row, row_slot, to = taken(s2, p2)
        done = ~by_row
        slot[idx[done]], pos[idx[done]] = s2[done], p2[done]
        idx, row_slot, to = idx[by_row], row_slot[by_row], to[by_row]
    if len(idx):
        raise RuntimeError("level interface: a chain of packets at a wall did not end")
    return slot, pos


def explosion_tables(fine: LevelView, coarse: LevelView, periodic, partial: bool = False, fed=None):
    """The populations a fine level pulls from its ghost cells in the coarser level during the two fine
    sub-steps of one coarse step, conservatively (Rohde et al. 2006): the coarse cells are cut into eight
    homogeneous fine packets that stream without colliding. Slot q of ghost cell h (read only by the fine leaf
    h + c_q) is at sub-step 1 slot q of h's coarse cell at t; at sub-step 2 what reached h at sub-step 1: slot q
    of the cell h - c_q at t (the fine state where that cell is a fine leaf, else its coarse cell's), or, where
    h - c_q lies beyond a resting wall, slot opp(q) of h's coarse cell (the packet the wall sent back,
    :func:`_arrival`).

    Returns two tables (one per sub-step) of (dst block, q, dst cell, source tag, src block, src cell, src slot,
    coarse stencil). ``partial``: the levels are a rank's region (:mod:`iceresist.parallel.levels`), and a ghost
    cell whose source is not held there is left out instead of refused. ``fed``: the coarse sub-cells the finer
    level feeds (:func:`coalescence`); a coarse packet a coarse row takes is then swapped for a free one
    (:func:`_take_free_packets`)."""
    fed = None if fed is None else np.sort(np.asarray(fed, dtype=np.int64))
    g = np.flatnonzero(fine.ghost_source == FROM_COARSER) + fine.nleaves
    if len(g) == 0:
        return None
    # only the ghost cells next to a leaf are read by one: the cells on the sides of each ghost block that face a
    # leaf block (ghost blocks lie in the fine level's block grid, so the leaf a cell's link reaches is in one of
    # its block's 26 neighbours)
    gi, hc = np.nonzero(next_to_leaves(fine, g))
    hb = g[gi]
    h = _cells_of(fine, g)[gi, hc]
    tables = ([], [])
    for q in range(1, 27):
        cq = C[q].astype(np.int64)
        tb, _, tin = locate_cells(fine, h + cq, periodic)
        keep = tin & (tb >= 0) & (tb < fine.nleaves)
        if not keep.any():
            continue
        hk, hbk, hck = h[keep], hb[keep], hc[keep]
        cb, cc, _ = locate_cells(coarse, hk >> 1, periodic)
        qq = np.full(len(hk), q)
        tables[0].append((hbk, qq, hck, np.full(len(hk), COARSE_T), cb, cc, qq, hk))
        tag, pb, pc, slot, pos, ok = _arrival(fine, hk, qq, 1, periodic)
        # a path through a face that is not a resting wall: h's own coarse cell, slot q
        tag, slot, pos = np.where(ok, tag, COARSE_T), np.where(ok, slot, q), np.where(ok[:, None], pos, hk)
        ob, oc, _ = locate_cells(coarse, pos >> 1, periodic)
        coarse_src = tag == COARSE_T
        tables[1].append((hbk, qq, hck, tag, np.where(coarse_src, ob, pb), np.where(coarse_src, oc, pc), slot, pos))
    if not tables[0]:
        return None
    out = []
    for t in tables:
        cols = [np.concatenate([row[k] for row in t]) for k in range(8)]
        if fed is not None:
            c = cols[3] == COARSE_T
            cols[6], cols[7] = cols[6].copy(), cols[7].copy()
            cols[6][c], cols[7][c] = _take_free_packets(fine, coarse, periodic, fed, cols[6][c], cols[7][c])
            cols[4][c], cols[5][c], _ = locate_cells(coarse, cols[7][c] >> 1, periodic)
        if partial:
            cols = [c[cols[4] >= 0] for c in cols]
        if (cols[4] < 0).any():
            raise InputError("a fine ghost cell has no coarse cell to take its packets from")
        out.append((*cols[:7], _coarse_stencil(coarse, cols[7], periodic)))
    return out


def coalescence_table(coarse: LevelView, fine: LevelView, periodic, partial: bool = False):
    """:func:`coalescence` without the keys of its rows."""
    return coalescence(coarse, fine, periodic, partial)[0]


def coalescence(coarse: LevelView, fine: LevelView, periodic, partial: bool = False):
    """The populations coarse leaves pull across the interface into the finer level, conservatively: coarse
    cell X's population q after a coarse step is the mean of what reached its eight fine sub-cells s in the two
    fine sub-steps, each packet taken where it last collided (:func:`_arrival`): the fine cell m = s - c_q at
    t + 1/2 where m is a fine leaf, else the fine cell o = m - c_q at t where o is, else o's coarse cell at t; a
    step whose source lies beyond a resting wall takes the packet the wall sent back (slot opp(q) of the cell
    itself). Written into slot q of the coarse cell X - c_q, read only by X; where X - c_q lies beyond a resting
    wall, into slot opp(q) of X itself, which only X's bounce-back reads. For every coarse leaf cell and q whose
    packets touch the fine level.

    In a row whose X - c_q lies beyond the wall, a sub-cell that no fine packet reaches takes X's own packet of slot
    opp(q) in that sub-cell, as the coarse bounce-back does; the fine leaves' pulls then leave those packets alone
    (:func:`_take_free_packets`).

    Returns the table, (dst block, dst slot, dst cell, tags (n, 8), src blocks (n, 8), src cells (n, 8), src slots
    (n, 8), coarse stencil), or None, and the keys of the sub-cells the finer level feeds (:func:`_sub_cell_keys`);
    ``partial`` as for :func:`explosion_tables`."""
    near = np.flatnonzero((coarse.forest.nbr_key[:coarse.nleaves] >= coarse.nleaves).any(axis=1))
    if len(near) == 0:
        return None, np.zeros(0, dtype=np.int64)
    X = _cells_of(coarse, near).reshape(-1, 3)
    # only a cell next to the finer level has packets that touch it: every sub-cell m or o lies in X's coarse cell
    # or one of its 26 neighbours, and the finer level's leaves lie under the coarse ghost blocks from the finer level
    from_finer = np.zeros(coarse.forest.nblocks, dtype=bool)
    from_finer[coarse.nleaves + np.flatnonzero(coarse.ghost_source == FROM_FINER)] = True
    next_to_finer = np.zeros(len(X), dtype=bool)
    for e in C[1:]:
        b, _, inside = locate_cells(coarse, X + e.astype(np.int64), periodic)
        next_to_finer |= inside & (b >= 0) & from_finer[np.maximum(b, 0)]
    X = X[next_to_finer]
    walls = _wall_faces(coarse)
    nc = np.array(coarse.forest.shape_cells, dtype=np.int64)
    rows, fine_src, keys = [], [], []
    for q in range(1, 27):
        cq = C[q].astype(np.int64)
        s = (2 * X[:, None, :] + CHILDREN[None, :, :]).reshape(-1, 3)      # (n * 8, 3) fine sub-cells
        tag, fb, fc, slot, pos, ok = (a.reshape(len(X), 8, *a.shape[1:])
                                      for a in _arrival(fine, s, np.full(len(s), q), 2, periodic))
        # where the coarse cell X pulls population q from: X - c_q, or its own slot opp(q) beyond a resting wall
        Y = X - cq
        crossed, all_walls = _beyond(Y, nc, walls, periodic)
        touch = (tag != COARSE_T).any(axis=1) & ok.all(axis=1) & (~crossed | all_walls)
        if not touch.any():
            continue
        tag, slot, pos, crossed = tag[touch], slot[touch], pos[touch], crossed[touch]
        fine_src.append((fb[touch], fc[touch]))
        s = s.reshape(len(X), 8, 3)[touch]
        # a row whose X - c_q lies beyond a resting wall: where no fine packet comes, the coarse bounce-back's
        # picture (X's own packet of slot opp(q) in the same sub-cell), as the rows the plain coarse step takes
        back = crossed[:, None] & (tag == COARSE_T)
        slot = np.where(back, OPP[q], slot)
        pos = np.where(back[..., None], s, pos)
        fed = tag != COARSE_T
        keys.append(_sub_cell_keys(coarse, s[fed], np.full(int(fed.sum()), q)))
        yb, yc, _ = locate_cells(coarse, np.where(crossed[:, None], X[touch], Y[touch]), periodic)
        dq = np.where(crossed, OPP[q], q)
        rows.append((yb, dq, yc, tag, slot, pos))
    if not rows:
        return None, np.zeros(0, dtype=np.int64)
    keys = np.concatenate(keys)
    yb, dq, yc, tag, slot, pos = (np.concatenate([r[k] for r in rows]) for k in range(6))
    fb, fc = (np.concatenate([r[k] for r in fine_src]) for k in range(2))
    coarse_src = tag == COARSE_T
    cb, cc, _ = locate_cells(coarse, pos >> 1, periodic)
    sb, sc = np.where(coarse_src, cb, fb), np.where(coarse_src, cc, fc)
    if partial:
        held = (yb >= 0) & (sb >= 0).all(axis=1)
        yb, yc, dq, tag, sb, sc, slot, pos = (a[held] for a in (yb, yc, dq, tag, sb, sc, slot, pos))
    if (yb < 0).any() or (sb < 0).any():
        raise InputError("a coarse cell next to the finer level has no neighbour to pull from")
    return (yb, dq, yc, tag, sb, sc, slot, _coarse_stencil(coarse, pos, periodic)), keys


def _apply_slots(table, dst, sources, weight: float = 1.0, linear: bool = False):
    """dst[b, q, c] = weight * sum over the table's source columns of sources[tag][sb, sq, sc] (in place); with
    ``linear`` a packet from the coarse level is its cell's value plus the central-difference gradient times the
    sub-cell's offset (the eight sub-cells of a coarse cell still sum to eight times its value)."""
    db, q, dc, tag, sb, sc, sq, (off, nbrs) = table
    if tag.ndim == 1:
        tag, sb, sc, sq = tag[:, None], sb[:, None], sc[:, None], sq[:, None]
        off = off[:, None, :]
        nbrs = [(b[:, None], c[:, None], ok[:, None]) for b, c, ok in nbrs]
    qq = sq
    acc = np.zeros(len(db), dtype=np.float64)
    for t, src in enumerate(sources):
        sel = tag == t
        if not sel.any():
            continue
        vals = np.zeros(tag.shape, dtype=np.float64)
        vals[sel] = src[sb[sel], qq[sel], sc[sel]]
        if linear and t == COARSE_T:
            for a in range(3):
                (bm, cm, okm), (bp, cp, okp) = nbrs[2 * a], nbrs[2 * a + 1]
                fm = src[bm[sel], qq[sel], cm[sel]].astype(np.float64)
                fp = src[bp[sel], qq[sel], cp[sel]].astype(np.float64)
                span = okm[sel].astype(np.float64) + okp[sel]
                grad = np.divide(fp - fm, span, out=np.zeros_like(fp), where=span > 0)
                vals[sel] += off[..., a][sel] * grad
        acc += vals.sum(axis=1)
    dst[db, q, dc] = (weight * acc).astype(dst.dtype)


def restriction_as_transfer(table, keep=None):
    """A :func:`restriction_table` in the form of the transfer kernel: every slot of every coarse ghost cell whose
    eight children are fine leaves (and, given ``keep``, a bool per ghost cell of the table, where it holds),
    eight packets of the fine level (tag 1) at weight 1/8 each (the kernel's ``weight``)."""
    if table is None:
        return None
    gb, gc, b, c, w = table
    full = (w > 0).all(axis=-1)
    if keep is not None:
        full &= keep
    gb, gc, b, c = gb[full], gc[full], b[full], c[full]
    n = len(gb)
    q = np.tile(np.arange(27), n)
    rep = lambda a: np.repeat(a, 27, axis=0)  # noqa: E731
    tag = np.full((n * 27, 8), FINE_T, dtype=np.int64)
    zeros = np.zeros((n * 27, 8), dtype=np.int64)
    stencil = (np.zeros((n * 27, 8, 3)), [(zeros, zeros, zeros.astype(bool))] * 6)
    return rep(gb), q, rep(gc), tag, rep(b), rep(c), np.broadcast_to(q[:, None], tag.shape), stencil


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
        feq = np.moveaxis(equilibrium_minus_w(rho, u[..., 0], u[..., 1], u[..., 2]), 0, -1)
        acc = feq + neq_scale * (acc - feq)
    dst[gb[have], :, gc[have]] = acc[have].astype(dst.dtype)


def _source_blocks(table, tag: int) -> np.ndarray:
    """The blocks a transfer table reads from the source array of ``tag`` (0: the coarse level at t, with its
    packets' neighbours; 1: the fine level at t; 2: the fine level at t + 1/2)."""
    _, _, _, tags, sb, _, _, (_, nbrs) = table
    tags, sb = np.asarray(tags), np.asarray(sb)
    if tags.ndim == 1:
        tags, sb = tags[:, None], sb[:, None]
        nbrs = [(np.asarray(b)[:, None], c, ok) for b, c, ok in nbrs]
    mine = tags == tag
    parts = [sb[mine]]
    if tag == 0:
        parts += [np.asarray(b)[mine] for b, _, _ in nbrs]
    out = np.concatenate([p.ravel() for p in parts]).astype(np.int64)
    return out[out >= 0]


class RefinedLBM:
    """The LBM on every level of ``octree`` (leaves of all levels fluid; walls and periodic faces as ``faces``).

    ``tau0`` and ``force0`` are the relaxation time and body-force acceleration of level 0 (lattice units of level
    0); each finer level gets tau and force by acoustic scaling. ``step()`` advances level 0 by one step and every
    level l by 2^l steps.

    ``solver_factory(level, forest, tau, force)``, if given, builds each level's solver instead of
    :class:`~iceresist.lbm.solver.LBMSolver`: anything with ``state`` (the populations f - w ``[block, q, cell]`` the
    next step pulls from), ``step()`` and ``initialize(rho, u)`` (the free surface on levels,
    :mod:`iceresist.freesurface.refined`).

    ``views``: the levels to hold (:func:`~iceresist.grid.levels.level_views`; default: every block of ``octree``,
    built here), ``partial``: whether they are an MPI rank's region
    (:class:`~iceresist.parallel.levels.LevelDecomposition`; default: whether ``views`` are given); the level
    transfers then leave out the cells whose sources lie beyond it. ``solid``: the solid cells of level 0
    (:func:`level_views`; ``views`` carry their own).
    """

    def __init__(self, octree: BlockOctree, *, tau0: float, force0=(0.0, 0.0, 0.0), faces: dict | None = None,
                 operator: str = "bgk", precision: str = "float64", rescale: bool = False,
                 scheme: str = "conservative", reconstruction: str = "linear", target=None, solver_factory=None,
                 views: list | None = None, solid=None, partial: bool | None = None):
        self.target = target or jit.cpu
        if self.target.is_cuda and scheme != "conservative":
            raise InputError("scheme: the interpolating level interface runs on the CPU only; use the conservative "
                             "scheme on CUDA")

        self.rescale = bool(rescale)
        if scheme not in SCHEMES:
            raise InputError(f"scheme must be one of {', '.join(SCHEMES)}, got {scheme!r}")
        self.scheme = scheme
        if reconstruction not in ("constant", "linear"):
            raise InputError(f"reconstruction must be 'constant' or 'linear', got {reconstruction!r}")
        self.reconstruction = reconstruction
        if self.rescale and scheme == "conservative":
            raise InputError("rescale: the conservative scheme moves whole packets across the interface (rescaling "
                             "a packet's non-equilibrium part changes the mass it carries; measured 15 % off in a "
                             "channel); use rescale=False, or scheme='interpolate' with rescale=True")
        self.octree = octree
        partial = views is not None if partial is None else bool(partial)
        if partial and scheme != "conservative":
            raise InputError("scheme: a rank's share of the levels runs the conservative level interface only")
        self.views = views if views is not None else level_views(octree, faces, solid)
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
            if solver_factory is None:
                self.solvers[lv] = LBMSolver(self.views[lv].forest, tau=tau, force=g, operator=operator,
                                             precision=precision, target=self.target)
            else:
                self.solvers[lv] = solver_factory(lv, self.views[lv].forest, tau, g)
            if scheme == "conservative":
                # no one reads a ghost block's update: before a level's step the transfers write every slot of its
                # ghost cells that a leaf pulls, and they read the leaves and the snapshots taken before the
                # step; so each level updates its leaves alone (the forest's first blocks). The interpolating
                # scheme reads the coarse ghosts' update (the half-step mean of the coarse state).
                self.solvers[lv].active_blocks = self.views[lv].nleaves
        if scheme == "interpolate":
            self.prolong = {lv: prolongation_table(self.views[lv], self.views[lv - 1], self.periodic)
                            for lv in self.levels[1:]}
            self.restrict = {lv: restriction_table(self.views[lv], self.views[lv + 1], self.periodic)
                             for lv in self.levels[:-1]}
        else:
            self.coalesce, self.explode = {}, {}
            for lv in self.levels[1:]:
                self.coalesce[lv - 1], fed = coalescence(self.views[lv - 1], self.views[lv], self.periodic, partial)
                self.explode[lv] = explosion_tables(self.views[lv], self.views[lv - 1], self.periodic, partial, fed)
            self.restrict = {lv: restriction_table(self.views[lv], self.views[lv + 1], self.periodic)
                             for lv in self.levels[:-1]}
            self._kernel_tables(precision)
        for lv in self.levels[1:]:
            if self.rescale and (self.tau[lv - 1] == 1.0 or self.tau[lv] == 1.0):
                raise InputError(f"tau = 1 on level {lv - 1 if self.tau[lv - 1] == 1.0 else lv}: its post-collision "
                                 "populations hold no stress to rescale across the level interface; choose a tau0 "
                                 "whose levels avoid 1 (e.g. tau0 = 0.6), or rescale=False")
        self.steppers = {lv: self.solvers[lv].step for lv in self.levels}
        self.iteration = 0

    def set_stepper(self, level: int, step):
        """Advance level ``level`` by ``step()`` (one step of that level) instead of its bare LBM step: a coupling
        that moves bodies on that level (:meth:`iceresist.coupling.FluidStructureCoupling.step` on the level's
        solver) sets its boundaries, steps the level's LBM and takes the forces at the level's own time step."""
        if level not in self.solvers:
            raise InputError(f"level {level} holds no leaves (levels {self.levels[0]}..{self.levels[-1]})")
        self.steppers[level] = step

    def neq_scale(self, fine: int, to_fine: bool) -> float:
        """Factor on the post-collision non-equilibrium populations across the interface of levels fine - 1 and
        ``fine`` (Dupuis and Chopard 2003), for the interpolating scheme: f_neq* scales as (tau - 1) dx, so coarse to fine times
        (tau_f - 1) / (2 (tau_c - 1)), fine to coarse its inverse; 1 without ``rescale`` (the paper's choice)."""
        if not self.rescale:
            return 1.0
        s = (self.tau[fine] - 1.0) / (2.0 * (self.tau[fine - 1] - 1.0))
        return s if to_fine else 1.0 / s

    def initialize(self, rho=1.0, u=(0.0, 0.0, 0.0)):
        for s in self.solvers.values():
            s.initialize(rho=rho, u=u)
        self.iteration = 0

    def _kernel_tables(self, precision: str):
        """The conservative transfer tables packed for the transfer kernel (:mod:`iceresist.lbm.exchange`) on the
        target, and a scratch copy of every level's populations (the coarse level at t, the fine one at t and
        t + 1/2)."""
        real = np.dtype(precision).type
        dev = self.target.to_device

        def packed(table):
            if table is None:
                return None
            p = pack_table(table, real)
            keys = ("db", "dq", "dc", "tag", "sb", "sc", "sq", "off", "nb", "nc", "nok")
            return len(p["db"]), tuple(dev(p[k]) for k in keys)

        self._transfer = transfer_launcher(self.target, real) if len(self.levels) > 1 else None   # one level: none
        self._real = real
        self._k_explode = {lv: None if t is None else (packed(t[0]), packed(t[1])) for lv, t in self.explode.items()}
        self._k_coalesce = {lv: packed(t) for lv, t in self.coalesce.items()}
        # the restricted values are read only next to the coarse leaves (a leaf pulls from its neighbours; the linear
        # reconstruction reads the neighbours of the coarse cells the packets come from, which are leaves): the
        # one-cell layer of the ghost blocks along the leaves (an eighth of their cells on the quick ship case)
        self._k_restrict = {}
        for lv, t in self.restrict.items():
            keep = None if t is None else next_to_leaves(self.views[lv], t[0][:, 0])
            self._k_restrict[lv] = packed(restriction_as_transfer(t, keep))
        shape = {lv: (self.views[lv].forest.nblocks, 27, 512) for lv in self.levels}
        # the copies the interfaces read: each coarse level at t, each finer one at t and t + 1/2 (none on one level)
        keys = sorted({(lv, "t") for lv in self.levels[:-1]}
                      | {(lv, k) for lv in self.levels[1:] for k in ("t", "half")})
        self._scratch = {(lv, k): dev(np.zeros(shape[lv], dtype=real)) for lv, k in keys}
        # the blocks each scratch copy must hold: those some table reads from it (a coarse packet's neighbours
        # included); a level's "t" copy serves both as the coarse level of the interface below it and the fine
        # level of the one above, so it holds both sets at either copy
        reads = {key: [] for key in self._scratch}
        for lv in self.levels[:-1]:
            finer = lv + 1
            tables = [self.coalesce[lv], *(self.explode[finer] or ())]
            for table in tables:
                if table is None:
                    continue
                for tag, key in ((0, (lv, "t")), (1, (finer, "t")), (2, (finer, "half"))):
                    reads[key].append(_source_blocks(table, tag))
        self._scratch_blocks = {}
        for key, parts in reads.items():
            blocks = np.unique(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)
            self._scratch_blocks[key] = (dev(blocks.astype(np.int64)), len(blocks))

    def _snapshot(self, scratch, state, key):
        """Copy into ``scratch`` the blocks of ``state`` that the transfer tables read from it (the rest of the
        scratch copy is never read)."""
        blocks, n = self._scratch_blocks[key]
        copy_blocks(self.target, scratch, state, blocks, n)

    def _launch(self, packed, dst, sources, weight=1.0, linear=False):
        if packed is None or packed[0] == 0:
            return
        n, cols = packed
        self._transfer(n, *cols, self._real(weight), np.int64(linear), *sources, dst)

    def _advance_conservative(self, lv: int):
        """Level lv from t to t + 1: its finer level first (two sub-steps, fed by exploded packets of level lv at
        t), then level lv, pulling the coalesced packets of the finer level. Every transfer is a kernel launch on
        the target; nothing crosses to the host."""
        s = self.solvers[lv]
        finer = lv + 1 if lv + 1 in self.solvers else None
        if finer is not None:
            sf = self.solvers[finer]
            linear = self.reconstruction == "linear"
            if linear:     # the gradient across the interface sees the fine level
                self._launch(self._k_restrict[lv], s.state, (sf.state, sf.state, sf.state), weight=0.125)
            c_t, f_t, f_half = self._scratch[(lv, "t")], self._scratch[(finer, "t")], self._scratch[(finer, "half")]
            self._snapshot(c_t, s.state, (lv, "t"))
            self._snapshot(f_t, sf.state, (finer, "t"))
            tables = self._k_explode[finer]
            # the finer level's "t" copy is also the coarse side of the interface below it: where the finer level
            # has a finer level of its own, its second sub-step snapshots itself at t + 1/2 into that copy, so the
            # coalescence (which reads the finer level at t there) runs before it; it writes level lv alone, which
            # that sub-step does not read. With two levels it runs last, after the finest level's ghost refill has
            # read level lv.
            early = finer + 1 in self.solvers
            for sub in (0, 1):
                if tables is not None:
                    self._launch(tables[sub], sf.state, (c_t, f_t, f_t), linear=linear)
                if sub == 1:
                    self._snapshot(f_half, sf.state, (finer, "half"))
                if sub == 1 and early:
                    self._coalesce(lv, linear)
                self._advance_conservative(finer)
            if not early:
                self._coalesce(lv, linear)
        self.steppers[lv]()

    def _coalesce(self, lv: int, linear: bool):
        """Level lv's slots that the finer level's packets fill (:func:`coalescence_table`), from the copies of
        level lv at t and of the finer level at t and t + 1/2."""
        sources = (self._scratch[(lv, "t")], self._scratch[(lv + 1, "t")], self._scratch[(lv + 1, "half")])
        self._launch(self._k_coalesce[lv], self.solvers[lv].state, sources, weight=0.125, linear=linear)

    def _advance(self, lv: int):
        if self.scheme == "conservative":
            return self._advance_conservative(lv)
        s = self.solvers[lv]
        if lv in self.restrict and self.restrict[lv] is not None:
            _apply(self.restrict[lv], s.state, self.solvers[lv + 1].state, self.neq_scale(lv + 1, False))
        finer = lv + 1 if lv + 1 in self.solvers else None
        before = s.state.copy() if finer is not None else None
        self.steppers[lv]()
        if finer is None:
            return
        table = self.prolong[finer]
        for half in (0.0, 0.5):
            if table is not None:
                src = before if half == 0.0 else 0.5 * (before + s.state)
                _apply(table, self.solvers[finer].state, src, self.neq_scale(finer, True))
            self._advance(finer)

    def step(self, n: int = 1):
        """Advance by ``n`` level-0 steps: level l by n 2^l steps (an octree whose coarsest leaves are finer than
        level 0, e.g. after a regrid, still steps by level-0 steps)."""
        for _ in range(int(n)):
            for _ in range(2 ** self.levels[0]):
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
