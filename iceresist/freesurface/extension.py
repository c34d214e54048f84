"""The velocity the phase field sees in the gas (paper section 2.2).

The cumulant LBM runs only where phi >= 1/2, so the fluid velocity is undefined
in the gas; yet the gas half of the diffuse interface (phi from 1/2 down to ~0.02
over about 1.5 W = 4.5 cells) must move with the liquid, or the profile is
sheared and the interface lags. We extend the liquid velocity into the gas layer
by layer: pass k gives every gas cell that has a neighbour filled by pass k-1
(liquid = pass 0) the w_q-weighted mean velocity of those neighbours. In pass 1
each liquid neighbour x + c_q contributes the velocity extrapolated linearly along
the link, 2 u(x + c_q) - u(x + 2 c_q), where x + 2 c_q is liquid too (else
u(x + c_q)): the phi = 1/2 surface lies between the last liquid and the first gas
cell, and a copied velocity would move it with the liquid velocity of up to one
cell below it, a first-order error in the kinematic condition (a standing wave of
16-32 cells per wavelength ran 3-6 % slow with the copy, docs/VALIDATION.md).
Passes 2 and more copy (a constant velocity across the rest of the profile). After
``layers`` passes (default 3, covering phi > 0.02 for W = 3) the remaining gas
cells get u = 0; their phi is below 2 % of the jump, so their velocity barely
moves phi, and conservation of sum phi does not depend on u at all.

Each pass is race-free on both targets: it reads only cells filled by earlier
passes (``dist <= k - 1``) and writes only cells still unfilled.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.backends.launch import CellLauncher
from iceresist.freesurface import kernel_key
from iceresist.freesurface.layout import HAS_LIQUID, build_neighbour

UNFILLED = 127


def build_extension_cell(target, real):
    """``extend_cell(b, c, phi, u, dist, nbr, layer, near)``; layer 0 marks liquid (dist 0) and clears gas velocity.

    ``near[b]``: the phase bits of block b and its neighbours (:func:`iceresist.freesurface.fluid.build_block_phases`).
    Layers 1-3 fill gas cells at most 3 cells from the liquid, so only blocks with both gas and liquid in reach
    (``near[b] == 3``) can change in them: the others return at once."""
    neighbour, _ = build_neighbour(target)
    cx, cy, cz = (np.ascontiguousarray(L.C[:, a]) for a in range(3))
    w = L.W.astype(real)
    zero, half, two = real(0.0), real(0.5), real(2.0)
    int64, int8 = np.int64, np.int8
    unfilled = UNFILLED

    @target.device
    def extend_cell(b, c, phi, u, dist, nbr, layer, near):
        b = int64(b)
        if layer == 0:
            if phi[b, c] >= half:
                dist[b, c] = int8(0)
            else:
                dist[b, c] = int8(unfilled)
                u[b, 0, c] = zero
                u[b, 1, c] = zero
                u[b, 2, c] = zero
            return
        if near[b] != 3 or dist[b, c] <= layer - 1:
            return
        z = c // 64
        y = (c // 8) % 8
        x = c % 8
        sw = zero
        sx = zero
        sy = zero
        sz = zero
        for q in range(1, 27):
            bn, cn = neighbour(nbr, b, x, y, z, cx[q], cy[q], cz[q])
            if bn >= 0:
                if dist[bn, cn] <= layer - 1:
                    vx = u[bn, 0, cn]
                    vy = u[bn, 1, cn]
                    vz = u[bn, 2, cn]
                    if layer == 1:
                        b2, c2 = neighbour(nbr, b, x, y, z, 2 * cx[q], 2 * cy[q], 2 * cz[q])
                        if b2 >= 0:
                            if dist[b2, c2] == 0:
                                vx = two * vx - u[b2, 0, c2]
                                vy = two * vy - u[b2, 1, c2]
                                vz = two * vz - u[b2, 2, c2]
                    sw += w[q]
                    sx += w[q] * vx
                    sy += w[q] * vy
                    sz += w[q] * vz
        if sw > zero:
            u[b, 0, c] = sx / sw
            u[b, 1, c] = sy / sw
            u[b, 2, c] = sz / sw
            dist[b, c] = int8(layer)

    return extend_cell


def build_extension_block(real):
    """The CPU block form of :func:`build_extension_cell`, ``extend_block(b, phi, u, dist, nbr, layer, near)``: the
    same update of the 512 cells of block b, arranged so that LLVM vectorises it across the cells. ``dist`` and u
    of the block and a halo (two cells deep in pass 1, which extrapolates along the link, one after) are copied
    into a scratch row by row (three runs of cells per row, one block look-up each; a cell outside the domain
    counts as unfilled), then each direction q adds its neighbour's
    weighted velocity to the sums of every cell at one constant offset, q in the order of the cell form: the same
    sums, cell by cell. Layer 0 in a block with no gas in reach (``near[b]`` = :data:`HAS_LIQUID`) only marks its
    cells liquid: phi >= 1/2 in all of them."""
    neighbour, _ = build_neighbour(jit.cpu)
    cx, cy, cz = (np.ascontiguousarray(L.C[:, a]) for a in range(3))
    w = L.W.astype(real)
    zero, two = real(0.0), real(2.0)
    int64, int8 = np.int64, np.int8
    unfilled = UNFILLED
    liquid_only = np.int8(HAS_LIQUID)   # no gas in reach
    side = 12                                    # 8 cells and a halo of 2 either side
    off = np.array([cx[q] + side * (cy[q] + side * cz[q]) for q in range(27)], dtype=np.int64)
    extend_cell = build_extension_cell(jit.cpu, real)
    dev = jit.cpu.device

    @dev
    def extend_block(b, phi, u, dist, nbr, layer, near):
        b = int64(b)
        if layer == 0:
            if near[b] == liquid_only:  # no gas in b (nor around it): every cell is liquid, u stays
                for c in range(512):
                    dist[b, c] = int8(0)
                return
            for c in range(512):
                extend_cell(b, c, phi, u, dist, nbr, layer, near)
            return
        if near[b] != 3:
            return
        todo = False
        for c in range(512):
            if dist[b, c] > layer - 1:
                todo = True
        if not todo:
            return
        halo = 2 if layer == 1 else 1
        pd = np.empty(side ** 3, np.int8)
        pux = np.empty(side ** 3, real)
        puy = np.empty(side ** 3, real)
        puz = np.empty(side ** 3, real)
        for pz in range(2 - halo, 10 + halo):
            for py in range(2 - halo, 10 + halo):
                row = 2 + side * (py + side * pz)       # scratch index of the row's cell x = 0
                # a row of the scratch in three runs: x = -halo..-1 (the -x block), 0..7, 8..7 + halo (the +x
                # block), one block look-up per run
                for run in range(3):
                    if run == 0:
                        bn, cn = neighbour(nbr, b, 0, py - 2, pz - 2, -halo, 0, 0)
                        x0 = -halo
                        n = halo
                    elif run == 1:
                        bn, cn = neighbour(nbr, b, 0, py - 2, pz - 2, 0, 0, 0)
                        x0 = 0
                        n = 8
                    else:
                        bn, cn = neighbour(nbr, b, 8, py - 2, pz - 2, 0, 0, 0)
                        x0 = 8
                        n = halo
                    if bn >= 0:
                        for x in range(n):
                            pd[row + x0 + x] = dist[bn, cn + x]
                            pux[row + x0 + x] = u[bn, 0, cn + x]
                            puy[row + x0 + x] = u[bn, 1, cn + x]
                            puz[row + x0 + x] = u[bn, 2, cn + x]
                    else:
                        for x in range(n):
                            pd[row + x0 + x] = int8(unfilled)
                            pux[row + x0 + x] = zero
                            puy[row + x0 + x] = zero
                            puz[row + x0 + x] = zero
        sw = np.zeros(512, real)
        sx = np.zeros(512, real)
        sy = np.zeros(512, real)
        sz = np.zeros(512, real)
        prev = layer - 1
        # the lines of 8 cells that can change: an unfilled cell and a filled cell in the line or the 8 lines
        # around it (the 3 x 3 lines whose cells are its cells' neighbours); the others are not summed
        filled = np.zeros(100, np.bool_)               # per scratch line (py, pz) in 1..10
        for pz in range(1, 11):
            for py in range(1, 11):
                i0 = 1 + side * (py + side * pz)
                f = False
                for x in range(10):
                    if pd[i0 + x] <= prev:
                        f = True
                filled[(py - 1) + 10 * (pz - 1)] = f
        todo_line = np.zeros(64, np.bool_)
        for z in range(8):
            for y in range(8):
                open_ = False
                for x in range(8):
                    if dist[b, x + 8 * (y + 8 * z)] > prev:
                        open_ = True
                reach = False
                for dz in range(3):
                    for dy in range(3):
                        if filled[(y + dy) + 10 * (z + dz)]:
                            reach = True
                todo_line[y + 8 * z] = open_ and reach
        for q in range(1, 27):
            o = off[q]
            wq = w[q]
            for z in range(8):
                for y in range(8):
                    if not todo_line[y + 8 * z]:
                        continue
                    i0 = 2 + side * ((y + 2) + side * (z + 2))
                    c0 = 8 * (y + 8 * z)
                    for x in range(8):
                        i = i0 + x + o
                        if pd[i] <= prev:
                            vx = pux[i]
                            vy = puy[i]
                            vz = puz[i]
                            if layer == 1:
                                j = i + o
                                if pd[j] == 0:
                                    vx = two * vx - pux[j]
                                    vy = two * vy - puy[j]
                                    vz = two * vz - puz[j]
                            sw[c0 + x] += wq
                            sx[c0 + x] += wq * vx
                            sy[c0 + x] += wq * vy
                            sz[c0 + x] += wq * vz
        for c in range(512):
            if dist[b, c] > prev and sw[c] > zero:
                u[b, 0, c] = sx[c] / sw[c]
                u[b, 1, c] = sy[c] / sw[c]
                u[b, 2, c] = sz[c] / sw[c]
                dist[b, c] = int8(layer)

    return extend_block


@lru_cache(maxsize=None)
def extension_launcher(target, precision: str, vector: bool = True) -> CellLauncher:
    """The launcher of one extension pass: per cell on CUDA (and with ``vector=False``), per block on the CPU
    (:func:`build_extension_block`)."""
    args = ("phi", "u", "dist", "nbr", "layer", "near")
    k = kernel_key(target, f"extension|{precision}|vector={bool(vector)}")
    if target.is_cuda or not vector:
        return CellLauncher(target, build_extension_cell(target, jit.real_type(precision)), args, label="extension",
                            cache_key=k)
    return CellLauncher(target, build_extension_block(jit.real_type(precision)), args, per_block=True,
                        label="extension", cache_key=k)


def extend_velocity(launch: CellLauncher, nblocks: int, phi, u, dist, nbr, layers: int = 3, near=None,
                    first: int = 0) -> None:
    """Overwrite ``u[block, 3, cell]`` in the gas (phi < 1/2) with the velocity extended from the liquid.

    ``dist[block, cell]`` (int8 work array) ends as the pass that filled each cell (0 liquid,
    127 beyond ``layers``). ``near`` (int8 per block, see :func:`build_extension_cell`): None visits every block.
    ``first``: the first pass to run (1 where the velocity pass already ran layer 0,
    :func:`iceresist.freesurface.fluid.velocity_layer0_launcher`).
    """
    if near is None:
        near = np.full(nblocks, 3, np.int8)
    for layer in range(int(first), layers + 1):
        launch(nblocks, phi, u, dist, nbr, np.int64(layer), near)
