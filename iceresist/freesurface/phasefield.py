"""Phase-field LBM for the conservative Allen-Cahn equation (paper section 2.2, eqs. 4-10).

phi = sum_k h_k (eq. 5); h relaxes by BGK (eq. 6) towards

    h_k^eq = phi Gamma_k(u) + theta w_k c_k . n,                 (eqs. 7-8)
    theta  = (M / c_s^2) (1 - 4 (phi - phi_ave)^2) / W,          (eq. 9)
    tau_phi = 1/2 + M / c_s^2,                                   (eq. 10)

with phi_ave = 1/2 and n = grad phi / |grad phi| from the isotropic D3Q27
finite-difference stencil grad phi = (1/c_s^2) sum_q w_q c_q phi(x + c_q)
(Fakhari, Geier and Lee 2016; Fakhari et al. 2017, "improved locality" form with
the interface term inside h^eq). Its steady profile across a flat interface is
phi = 1/2 + 1/2 tanh(2 z / W).

One time step is two passes over the cells, so that the normal is taken from
phi at the new time level:

1. ``stream_cell``: h_k(x, t+1) = h_k^post(x - c_k, t) (pull streaming) into the
   other buffer, and phi(x, t+1) = sum_k of them (eq. 5);
2. ``collide_cell``: take n from the phi of pass 1 and collide the streamed h of
   the cell in place (eq. 6). Pass 2 reads only its own cell's h: the h of a cell
   is pulled from its neighbours once per step.

Walls (``nbr == -1``): h bounces back half-way (no flux of phi through a wall, so
sum phi is conserved to round-off), and the gradient stencil clamps to the
boundary cell along the wall normal: zero normal gradient, a neutral (90 degree)
contact angle.

Moving solids (``solid[block, cell] >= 0``, the index of the body covering the
cell, set by :mod:`iceresist.coupling`): h pulled from a solid cell bounces back
half-way as at a wall, solid cells are not updated, and the gradient stencil reads
the phi the coupling writes into them (phi at the mirror point across the surface:
zero normal gradient, neutral wetting). ``solid`` is -1 everywhere by default.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.errors import InputError
from iceresist.freesurface import kernel_key
from iceresist.freesurface.hlattice import HLattice
from iceresist.freesurface.hlattice import h_lattice as lookup_h_lattice
from iceresist.backends.launch import ActiveLauncher, BlockLauncher, CellLauncher
from iceresist.freesurface.layout import DIR_OF_OFFSET, build_neighbour
from iceresist.grid.forest import CELLS

PHI_AVE = 0.5


def tau_phi(mobility: float, lat: HLattice) -> float:
    """Relaxation time of h, paper eq. (10), lattice units (dt = 1)."""
    return 0.5 + mobility / lat.cs2


def _gradient_stencil(real):
    """(c_x, c_y, c_z, w / c_s^2) of the isotropic D3Q27 gradient stencil, as the kernels read them."""
    return (*(np.ascontiguousarray(L.C[:, a]) for a in range(3)), (L.W / L.CS2).astype(real))


def _stencils(real, lat: HLattice):
    """(q, c_x, c_y, c_z, w, opposite) of the h lattice and :func:`_gradient_stencil`, as the kernels read them."""
    hc = np.ascontiguousarray(lat.c, dtype=np.int64)
    return (lat.q, *(np.ascontiguousarray(hc[:, a]) for a in range(3)), np.array(lat.w, dtype=real),
            np.array(lat.opp, dtype=np.int64), *_gradient_stencil(real))


def build_normal(target, real):
    """Compile ``normal(phi, nbr, b, x, y, z) -> (nx, ny, nz)``: n = grad phi / |grad phi| by the isotropic D3Q27
    stencil, walls clamped (zero normal gradient); the sums run in the precision ``real`` (c_q as ``real``, so a
    float32 build holds no float64 arithmetic). Its last step, ``unit(gx, gy, gz)``, is returned too:
    ``(normal, unit)``."""
    _, neighbour_clamped = build_neighbour(target)
    gcx, gcy, gcz, gw = _gradient_stencil(real)
    gex, gey, gez = (a.astype(real) for a in (gcx, gcy, gcz))
    zero, one = real(0.0), real(1.0)
    tiny = real(1e-24) if real == np.float64 else real(1e-18)
    dev = target.device

    @dev
    def unit(gx, gy, gz):
        g2 = gx * gx + gy * gy + gz * gz
        if g2 > tiny:
            ig = one / math.sqrt(g2)
            return gx * ig, gy * ig, gz * ig
        return zero, zero, zero

    @dev
    def normal(phi, nbr, b, x, y, z):
        gx = zero
        gy = zero
        gz = zero
        for q in range(1, 27):
            bn, cn_ = neighbour_clamped(nbr, b, x, y, z, gcx[q], gcy[q], gcz[q])
            pn = gw[q] * phi[bn, cn_]
            gx += gex[q] * pn
            gy += gey[q] * pn
            gz += gez[q] * pn
        return unit(gx, gy, gz)

    return normal, unit


def build_phase_cells(target, real, lat: HLattice):
    """Compile the cell functions ``(stream_cell, collide_cell, init_cell)`` for ``target``.

    * ``stream_cell(b, c, h_in, h_out, phi, nbr, solid)``: h_out = pulled h, phi = their sum (pass 1);
    * ``collide_cell(b, c, h_out, phi, u, nbr, omega, kappa, solid)``: pass 2 in place, with
      omega = 1/tau_phi and kappa = M / (c_s^2 W);
    * ``init_cell(b, c, h_out, phi, u, nbr, kappa)``: h = h^eq(phi, u, n).

    Loops over the directions (one inlined neighbour look-up each) rather than
    unrolled code: 26 unrolled look-ups with their branches take minutes to compile
    and are memory bound anyway.
    """
    neighbour, _ = build_neighbour(target)
    nq, hcx, hcy, hcz, hw, hopp, *_ = _stencils(real, lat)
    hex_, hey, hez = (a.astype(real) for a in (hcx, hcy, hcz))  # c_k in the arithmetic precision
    zero, one, half, four = real(0.0), real(1.0), real(0.5), real(4.0)
    cs2, ics2, half_ics4 = real(lat.cs2), real(1.0 / lat.cs2), real(0.5 / lat.cs2 ** 2)
    dev = target.device
    int64 = np.int64

    @dev
    def pulled(h_in, nbr, solid, b, c, x, y, z, k):
        """h_k(x - c_k) from the post-collision buffer; half-way bounce-back where x - c_k is outside or solid."""
        bs, cs_ = neighbour(nbr, b, x, y, z, -hcx[k], -hcy[k], -hcz[k])
        if bs >= 0:
            if solid[bs, cs_] < 0:
                return h_in[bs, k, cs_]
        return h_in[b, hopp[k], c]

    normal, _ = build_normal(target, real)

    @dev
    def h_equilibrium(k, p, nx, ny, nz, th, ux, uy, uz, uu):
        """h_k^eq = phi Gamma_k(u) + theta w_k c_k . n (eqs. 7-8)."""
        cu = hex_[k] * ux + hey[k] * uy + hez[k] * uz
        cn = hex_[k] * nx + hey[k] * ny + hez[k] * nz
        return hw[k] * (p * (one + ics2 * cu + half_ics4 * (cu * cu - cs2 * uu)) + th * cn)

    @dev
    def stream_cell(b, c, h_in, h_out, phi, nbr, solid):
        b = int64(b)  # the CPU prange index may be unsigned; keep block ids signed
        if solid[b, c] >= 0:
            return
        z = c // 64
        y = (c // 8) % 8
        x = c % 8
        s = zero
        for k in range(nq):
            hk = pulled(h_in, nbr, solid, b, c, x, y, z, k)
            h_out[b, k, c] = hk
            s += hk
        phi[b, c] = s

    @dev
    def equilibrium_inputs(b, c, phi, u, nbr, kappa):
        """Cell coordinates, phi, interface normal n, theta of eq. (9) and u of cell c: the inputs of eq. (7)."""
        z = c // 64
        y = (c // 8) % 8
        x = c % 8
        p = phi[b, c]
        nx, ny, nz = normal(phi, nbr, b, x, y, z)
        dp = p - half
        th = kappa * (one - four * dp * dp)
        ux = u[b, 0, c]
        uy = u[b, 1, c]
        uz = u[b, 2, c]
        uu = ux * ux + uy * uy + uz * uz
        return x, y, z, p, nx, ny, nz, th, ux, uy, uz, uu

    @dev
    def collide_cell(b, c, h_out, phi, u, nbr, omega, kappa, solid):
        b = int64(b)  # the CPU prange index may be unsigned; keep block ids signed
        if solid[b, c] >= 0:
            return
        x, y, z, p, nx, ny, nz, th, ux, uy, uz, uu = equilibrium_inputs(b, c, phi, u, nbr, kappa)
        for k in range(nq):
            hk = h_out[b, k, c]
            h_out[b, k, c] = hk + omega * (h_equilibrium(k, p, nx, ny, nz, th, ux, uy, uz, uu) - hk)

    @dev
    def init_cell(b, c, h_out, phi, u, nbr, kappa):
        b = int64(b)  # the CPU prange index may be unsigned; keep block ids signed
        x, y, z, p, nx, ny, nz, th, ux, uy, uz, uu = equilibrium_inputs(b, c, phi, u, nbr, kappa)
        for k in range(nq):
            h_out[b, k, c] = h_equilibrium(k, p, nx, ny, nz, th, ux, uy, uz, uu)

    return stream_cell, collide_cell, init_cell


def build_phase_blocks(real, lat: HLattice):
    """Compile the CPU block forms ``(stream_block, collide_block, init_block)`` of passes 1 and 2 and of h = h^eq
    (the launchers call them once per block, ``CellLauncher(per_block=True)``): the same updates as
    :func:`build_phase_cells`,
    arranged so that LLVM vectorises them across the cells of a block.

    * pull: h_k of the 512 cells into a block scratch line by line (8 cells from the source line, the one
      cell that crosses the block's x face from the neighbour), then one select per cell between the pulled
      value and the half-way bounce-back (a source outside the domain or solid);
    * normal: from phi of the block and its halo in a 10^3 scratch (along a wall face the halo repeats the
      boundary cell, the cell form's clamp), the D3Q27 stencil applied as a product of three 1-D stencils (its
      weights factorise), in float64; the per-cell clamped stencil only in a block next to a hole in the forest;
    * collide: eq. (6) over the 512 cells for each k in the working precision (theta n per cell first); solid
      cells keep phi and h (a select).
    """
    neighbour, _ = build_neighbour(jit.cpu)
    dir_of = DIR_OF_OFFSET
    normal, unit = build_normal(jit.cpu, real)
    nq, hcx, hcy, hcz, hw, hopp, *_ = _stencils(real, lat)
    hex_, hey, hez = (a.astype(real) for a in (hcx, hcy, hcz))  # c_k in the arithmetic precision
    fxm, fxp = L.index_of(-1, 0, 0), L.index_of(1, 0, 0)
    fym, fyp = L.index_of(0, -1, 0), L.index_of(0, 1, 0)
    fzm, fzp = L.index_of(0, 0, -1), L.index_of(0, 0, 1)
    zero, one, half, four = real(0.0), real(1.0), real(0.5), real(4.0)
    cs2, ics2, half_ics4 = real(lat.cs2), real(1.0 / lat.cs2), real(0.5 / lat.cs2 ** 2)
    dev = jit.cpu.device
    rdtype = real
    sixth = 1.0 / 6.0

    @dev
    def clamp(v, low_open, high_open):
        """v, or the boundary cell 0 / 7 where v leaves the block through a wall face."""
        if v < 0 and not low_open:
            return 0
        if v >= 8 and not high_open:
            return 7
        return v

    @dev
    def gather(b, k, h_in, nbr, solid, tmp, ln, sl):
        """tmp[c] = h_k pulled into cell c of block b (bounce-back where the source is outside or solid)."""
        cx = hcx[k]
        cy = hcy[k]
        cz = hcz[k]
        ko = hopp[k]
        for z in range(8):
            for y in range(8):
                bm, sbase = neighbour(nbr, b, 0, y, z, 0, -cy, -cz)  # the source line, its cell x = 0
                if bm >= 0:
                    for x in range(8):
                        ln[x + 1] = h_in[bm, k, sbase + x]
                    for x in range(8):
                        sl[x + 1] = solid[bm, sbase + x]
                else:
                    for x in range(10):
                        ln[x] = zero
                        sl[x] = 0
                if cx == 1:  # cell x = 0 pulls from x = -1: the last cell of the line of the -x block
                    be, ce = neighbour(nbr, b, 0, y, z, -1, -cy, -cz)
                    if be >= 0:
                        ln[0] = h_in[be, k, ce]
                        sl[0] = solid[be, ce]
                    else:
                        sl[0] = 0
                elif cx == -1:
                    be, ce = neighbour(nbr, b, 7, y, z, 1, -cy, -cz)
                    if be >= 0:
                        ln[9] = h_in[be, k, ce]
                        sl[9] = solid[be, ce]
                    else:
                        sl[9] = 0
                c0 = 8 * (y + 8 * z)
                o = 1 - cx
                for x in range(8):
                    own = h_in[b, ko, c0 + x]
                    tmp[c0 + x] = ln[x + o] if sl[x + o] < 0 else own

    @dev
    def wrap(v):
        """(v within its block, the step -1, 0 or 1 to that block) of a cell coordinate v in -1..8."""
        if v < 0:
            return v + 8, -1
        if v > 7:
            return v - 8, 1
        return v, 0

    @dev
    def stream_clear(b, h_in, h_out, phi, nbr, acc):
        """Pass 1 for a block in which no source is solid (b and its neighbour blocks hold no solid cell): each
        line of 8 cells pulls from one source line, the cell that crosses the x face from the neighbour line; a
        source in no block (a wall, a hole in the forest) bounces back half-way, a whole line at once. The same
        values and the same sums as the general form."""
        for k in range(nq):
            cx = hcx[k]
            cy = hcy[k]
            cz = hcz[k]
            ko = hopp[k]
            for z in range(8):
                zs, bz = wrap(z - cz)
                for y in range(8):
                    ys, by = wrap(y - cy)
                    d = 13 + 3 * by + 9 * bz        # dir_of index of the offset (0, by, bz)
                    bm = b if d == 13 else nbr[b, dir_of[d]]
                    sbase = 8 * (ys + 8 * zs)
                    c0 = 8 * (y + 8 * z)
                    if cx == 0:
                        if bm >= 0:
                            for x in range(8):
                                v = h_in[bm, k, sbase + x]
                                h_out[b, k, c0 + x] = v
                                acc[c0 + x] += v
                        else:
                            for x in range(8):
                                v = h_in[b, ko, c0 + x]
                                h_out[b, k, c0 + x] = v
                                acc[c0 + x] += v
                        continue
                    # the cell at the x face pulls from the neighbour line (x = 0 from the -x side if cx = 1)
                    xe = 0 if cx == 1 else 7
                    be = nbr[b, dir_of[d - cx]]
                    v = h_in[be, k, sbase + 7 - xe] if be >= 0 else h_in[b, ko, c0 + xe]
                    h_out[b, k, c0 + xe] = v
                    acc[c0 + xe] += v
                    x0 = 1 - xe // 7            # the other 7 cells: x = 1..7 (cx = 1) or 0..6 (cx = -1)
                    if bm >= 0:
                        for x in range(x0, x0 + 7):
                            v = h_in[bm, k, sbase + x - cx]
                            h_out[b, k, c0 + x] = v
                            acc[c0 + x] += v
                    else:
                        for x in range(x0, x0 + 7):
                            v = h_in[b, ko, c0 + x]
                            h_out[b, k, c0 + x] = v
                            acc[c0 + x] += v
        for c in range(512):
            phi[b, c] = acc[c]

    @dev
    def stream_block(b, h_in, h_out, phi, nbr, solid, clear):
        """Pass 1 for block b: h_out = pulled h, phi = sum_k of them; a solid cell keeps its h and phi.
        ``clear[b]`` (:func:`build_clear_blocks`): neither b nor its neighbours hold a solid cell."""
        b = np.int64(b)
        acc = np.zeros(512, rdtype)
        if clear[b]:
            stream_clear(b, h_in, h_out, phi, nbr, acc)
            return
        tmp = np.empty(512, rdtype)
        ln = np.empty(10, rdtype)
        sl = np.empty(10, np.int32)
        covered = False
        for c in range(512):
            if solid[b, c] >= 0:
                covered = True
        for k in range(nq):
            gather(b, k, h_in, nbr, solid, tmp, ln, sl)
            for c in range(512):
                acc[c] += tmp[c]
            if covered:
                for c in range(512):
                    h_out[b, k, c] = tmp[c] if solid[b, c] < 0 else h_out[b, k, c]
            else:  # a plain store: no read of h_out
                for c in range(512):
                    h_out[b, k, c] = tmp[c]
        for c in range(512):
            phi[b, c] = acc[c] if solid[b, c] < 0 else phi[b, c]

    @dev
    def normals(b, phi, nbr, nx_, ny_, nz_, pad, sx, dx, t1, t2, t3):
        """The interface normal of every cell of block b (as ``normal`` of :func:`build_phase_cells`)."""
        # phi of the block and its halo; along an axis whose face is a wall the halo repeats the boundary cell
        # (the clamp of the cell form). A halo cell in a missing block after clamping (a hole in the forest)
        # leaves the clamp to the cell form.
        padded = True
        xlo = -1 if nbr[b, fxm] >= 0 else 0
        xhi = 8 if nbr[b, fxp] >= 0 else 7
        for pz in range(10):
            z = clamp(pz - 1, nbr[b, fzm] >= 0, nbr[b, fzp] >= 0)
            for py in range(10):
                y = clamp(py - 1, nbr[b, fym] >= 0, nbr[b, fyp] >= 0)
                row = 10 * (py + 10 * pz)
                bm, sbase = neighbour(nbr, b, 0, 0, 0, 0, y, z)
                bl, cl = neighbour(nbr, b, 0, 0, 0, xlo, y, z)
                bh, ch = neighbour(nbr, b, 0, 0, 0, xhi, y, z)
                if bm < 0 or bl < 0 or bh < 0:
                    padded = False
                    break
                for x in range(8):
                    pad[row + 1 + x] = phi[bm, sbase + x]
                pad[row] = phi[bl, cl]
                pad[row + 9] = phi[bh, ch]
            if not padded:
                break
        if padded:
            # The D3Q27 weights factorise, w_q = w1(c_x) w1(c_y) w1(c_z) with w1 = (1/6, 2/3, 1/6), so the stencil
            # (1/c_s^2) sum_q w_q c_q phi(x + c_q) is separable: grad_x = (1/2) S_y S_z D_x phi with the difference
            # D phi = phi(+1) - phi(-1) and the smoothing S phi = (phi(-1) + 4 phi + phi(+1)) / 6 along the axis
            # named; likewise y and z. The same sums as the 26-point stencil in another order (about 30 operations
            # per cell instead of 160).
            for pz in range(10):
                for py in range(10):
                    r = 10 * (py + 10 * pz)
                    o = 8 * (py + 10 * pz)
                    for x in range(8):
                        a = np.float64(pad[r + x])
                        m = np.float64(pad[r + x + 1])
                        p = np.float64(pad[r + x + 2])
                        sx[o + x] = (a + 4.0 * m + p) * sixth
                        dx[o + x] = p - a
            for pz in range(10):
                for y in range(8):
                    o = 8 * (y + 8 * pz)
                    lo = 8 * (y + 10 * pz)
                    mi = lo + 8
                    hi = lo + 16
                    for x in range(8):
                        t1[o + x] = (dx[lo + x] + 4.0 * dx[mi + x] + dx[hi + x]) * sixth
                        t2[o + x] = sx[hi + x] - sx[lo + x]
                        t3[o + x] = (sx[lo + x] + 4.0 * sx[mi + x] + sx[hi + x]) * sixth
            for z in range(8):
                for y in range(8):
                    lo = 8 * (y + 8 * z)
                    mi = lo + 64
                    hi = lo + 128
                    c0 = 8 * (y + 8 * z)
                    for x in range(8):
                        nx_[c0 + x] = 0.5 * (t1[lo + x] + 4.0 * t1[mi + x] + t1[hi + x]) * sixth
                        ny_[c0 + x] = 0.5 * (t2[lo + x] + 4.0 * t2[mi + x] + t2[hi + x]) * sixth
                        nz_[c0 + x] = 0.5 * (t3[hi + x] - t3[lo + x])
            for c in range(512):
                nx_[c], ny_[c], nz_[c] = unit(nx_[c], ny_[c], nz_[c])
        else:
            for c in range(512):
                nx_[c], ny_[c], nz_[c] = normal(phi, nbr, b, c % 8, (c // 8) % 8, c // 64)

    @dev
    def equilibrium_terms(b, phi, u, nbr, kappa, tx_, ty_, tz_, uu_):
        """theta n (eq. 9) and u . u of every cell of block b, in the working precision."""
        nx_ = np.empty(512, np.float64)  # the stencil sums in float64
        ny_ = np.empty(512, np.float64)
        nz_ = np.empty(512, np.float64)
        pad = np.empty(1000, rdtype)
        sx = np.empty(800, np.float64)
        dx = np.empty(800, np.float64)
        t1 = np.empty(640, np.float64)
        t2 = np.empty(640, np.float64)
        t3 = np.empty(640, np.float64)
        normals(b, phi, nbr, nx_, ny_, nz_, pad, sx, dx, t1, t2, t3)
        for c in range(512):
            dp = phi[b, c] - half
            th = kappa * (one - four * dp * dp)
            tx_[c] = rdtype(th * nx_[c])
            ty_[c] = rdtype(th * ny_[c])
            tz_[c] = rdtype(th * nz_[c])
            ux = u[b, 0, c]
            uy = u[b, 1, c]
            uz = u[b, 2, c]
            uu_[c] = ux * ux + uy * uy + uz * uz

    @dev
    def h_eq(b, c, k, phi, u, tx_, ty_, tz_, uu_):
        """h_k^eq of cell c of block b (eqs. 7-8) from the terms of ``equilibrium_terms``."""
        cx = hex_[k]
        cy = hey[k]
        cz = hez[k]
        cu = cx * u[b, 0, c] + cy * u[b, 1, c] + cz * u[b, 2, c]
        cn = cx * tx_[c] + cy * ty_[c] + cz * tz_[c]
        return hw[k] * (phi[b, c] * (one + ics2 * cu + half_ics4 * (cu * cu - cs2 * uu_[c])) + cn)

    @dev
    def collide_block(b, h_out, phi, u, nbr, omega, kappa, solid):
        """Pass 2 for block b: collide the streamed h in place towards h^eq(phi, u, n) (eqs. 6-9); a solid cell
        keeps its h."""
        b = np.int64(b)
        tx_ = np.empty(512, rdtype)
        ty_ = np.empty(512, rdtype)
        tz_ = np.empty(512, rdtype)
        uu_ = np.empty(512, rdtype)
        equilibrium_terms(b, phi, u, nbr, kappa, tx_, ty_, tz_, uu_)
        for k in range(nq):
            for c in range(512):
                hk = h_out[b, k, c]
                new = hk + omega * (h_eq(b, c, k, phi, u, tx_, ty_, tz_, uu_) - hk)
                h_out[b, k, c] = new if solid[b, c] < 0 else h_out[b, k, c]

    @dev
    def init_block(b, h_out, phi, u, nbr, kappa):
        """h = h^eq(phi, u, n) in every cell of block b (``init_cell`` of :func:`build_phase_cells`)."""
        b = np.int64(b)
        tx_ = np.empty(512, rdtype)
        ty_ = np.empty(512, rdtype)
        tz_ = np.empty(512, rdtype)
        uu_ = np.empty(512, rdtype)
        equilibrium_terms(b, phi, u, nbr, kappa, tx_, ty_, tz_, uu_)
        for k in range(nq):
            for c in range(512):
                h_out[b, k, c] = h_eq(b, c, k, phi, u, tx_, ty_, tz_, uu_)

    return stream_block, collide_block, init_block


def build_clear_blocks():
    """Compile ``(solid_block, clear_block)``, the CPU passes that find the blocks where pass 1 is a plain pull:

    * ``solid_block(b, solid, has)``: ``has[b]`` = 1 where a cell of b is covered by a solid (``solid >= 0``);
    * ``clear_block(b, has, nbr, clear)``: ``clear[b]`` = 1 where neither b nor any of its neighbour blocks
      holds a solid cell (no source of b is solid: each line of b pulls from one line, or bounces back whole
      where its source lies in no block)."""
    int8, int64 = np.int8, np.int64

    def solid_block(b, solid, has):
        b = int64(b)
        m = int8(0)
        for c in range(CELLS):
            if solid[b, c] >= 0:
                m = int8(1)
        has[b] = m

    def clear_block(b, has, nbr, clear):
        b = int64(b)
        m = int8(1) if has[b] == 0 else int8(0)
        for q in range(1, 27):
            bn = nbr[b, q]
            if bn >= 0:
                if has[bn] != 0:
                    m = int8(0)
        clear[b] = m

    return jit.cpu.device(solid_block), jit.cpu.device(clear_block)


@lru_cache(maxsize=None)
def clear_launchers():
    solid_block, clear_block = build_clear_blocks()
    k = kernel_key(jit.cpu, "h_clear")
    return (BlockLauncher(jit.cpu, solid_block, ("solid", "has"), label="h_clear", cache_key=k),
            BlockLauncher(jit.cpu, clear_block, ("has", "nbr", "clear"), label="h_clear", cache_key=k))


@lru_cache(maxsize=None)
def phase_launchers(target, precision: str, lattice_name: str, vector: bool = True):
    """Compile (once per target, precision and h lattice) the launchers ``(stream, collide, init)``; on the
    CPU passes 1 and 2 run in their block form (:func:`build_phase_blocks`) unless ``vector=False``."""
    real, lat = jit.real_type(precision), lookup_h_lattice(lattice_name)
    stream_cell, collide_cell, init_cell = build_phase_cells(target, real, lat)
    st_args, co_args = ("h_in", "h_out", "phi", "nbr", "solid"), ("h_out", "phi", "u", "nbr", "omega", "kappa", "solid")
    k = kernel_key(target, f"phase|{precision}|{lattice_name}|vector={bool(vector)}")
    init = CellLauncher(target, init_cell, ("h_out", "phi", "u", "nbr", "kappa"), label="h_init", cache_key=k)
    if target.is_cuda or not vector:
        return (CellLauncher(target, stream_cell, st_args, label="h_stream", cache_key=k),
                CellLauncher(target, collide_cell, co_args, label="h_collide", cache_key=k), init)
    stream_block, collide_block, _ = build_phase_blocks(real, lat)
    return (CellLauncher(target, stream_block, st_args + ("clear",), per_block=True, label="h_stream", cache_key=k),
            CellLauncher(target, collide_block, co_args, per_block=True, label="h_collide", cache_key=k), init)


@lru_cache(maxsize=None)
def active_phase_launchers(target, precision: str, lattice_name: str):
    """The launchers ``(stream, collide, init)`` of :func:`phase_launchers` over the blocks flagged in a mask
    passed first (:class:`~iceresist.backends.launch.ActiveLauncher`; :mod:`iceresist.freesurface.bulk`)."""
    real, lat = jit.real_type(precision), lookup_h_lattice(lattice_name)
    stream_cell, collide_cell, init_cell = build_phase_cells(target, real, lat)
    st_args, co_args = ("active", "h_in", "h_out", "phi", "nbr", "solid"), \
        ("active", "h_out", "phi", "u", "nbr", "omega", "kappa", "solid")
    init_args = ("active", "h_out", "phi", "u", "nbr", "kappa")
    k = kernel_key(target, f"phase_active|{precision}|{lattice_name}")
    if target.is_cuda:
        return (ActiveLauncher(target, stream_cell, st_args, label="h_stream", cache_key=k),
                ActiveLauncher(target, collide_cell, co_args, label="h_collide", cache_key=k),
                ActiveLauncher(target, init_cell, init_args, label="h_init", cache_key=k))
    stream_block, collide_block, init_block = build_phase_blocks(real, lat)
    return (ActiveLauncher(target, stream_block, st_args + ("clear",), per_block=True, label="h_stream", cache_key=k),
            ActiveLauncher(target, collide_block, co_args, per_block=True, label="h_collide", cache_key=k),
            ActiveLauncher(target, init_block, init_args, per_block=True, label="h_init", cache_key=k))


@lru_cache(maxsize=None)
def volume_launcher(target, lattice_name: str) -> BlockLauncher:
    """``launch(nblocks, h, phi, valid, solid, out)``: ``out[b]`` = sum over the cells of block b no solid covers
    of sum_k h_k where ``valid[b]`` (h holds the state), else of phi (a block the phase field left frozen,
    :mod:`iceresist.freesurface.bulk`), in float64 (the conserved phase volume of the block, cells^3), reduced on
    the target."""
    nq = lookup_h_lattice(lattice_name).q
    f64 = np.float64

    def volume_block(b, h, phi, valid, solid, out):
        acc = f64(0.0)
        if valid[b] != 0:
            for c in range(CELLS):
                if solid[b, c] < 0:
                    for k in range(nq):
                        acc += f64(h[b, k, c])
        else:
            for c in range(CELLS):
                if solid[b, c] < 0:
                    acc += f64(phi[b, c])
        out[b] = acc

    return BlockLauncher(target, target.device(volume_block), ("h", "phi", "valid", "solid", "out"),
                         label="water_volume", cache_key=kernel_key(target, f"water_volume|{lattice_name}"))


class PhaseField:
    """Phase field phi on a block forest, advanced by the conservative Allen-Cahn LBM (eqs. 5-10).

    ``forest``: the :class:`~iceresist.grid.BlockForest` (its ``nbr`` table; every block carries
    h and phi, gas blocks included); ``mobility`` M and
    ``width`` W in lattice units; ``h_lattice`` one of D3Q7/D3Q15/D3Q19/D3Q27; ``vector=False`` runs the
    per-cell form on the CPU too (the reference of the block form, :func:`build_phase_blocks`).
    Arrays live on the target: ``h`` (two buffers ``[block, k, cell]``) and ``phi[block, cell]``.
    ``step(u)`` takes the velocity ``u[block, 3, cell]`` (lattice units) the interface is
    advected with; in the gas it must hold the velocity extended from the liquid
    (:mod:`iceresist.freesurface.extension`).
    """

    def __init__(self, forest, *, mobility=0.05, width=3.0, h_lattice="D3Q15", precision="float32", target=jit.cpu,
                 vector: bool = True):
        if mobility <= 0:
            raise InputError(f"free_surface.mobility must be > 0 (lattice units), not {mobility}")
        if width < 2:
            raise InputError(f"free_surface.width must be >= 2 cells, not {width}")
        self.lat = lookup_h_lattice(h_lattice.name if isinstance(h_lattice, HLattice) else h_lattice)
        self.real = jit.real_type(precision)
        self.target = target
        self.mobility = float(mobility)
        self.width = float(width)
        self.tau = tau_phi(mobility, self.lat)
        self.forest = forest
        nbr = forest.nbr
        self.nblocks = int(nbr.shape[0])
        self._stream, self._collide, self._init = phase_launchers(target, precision, self.lat.name, vector)
        #: the block form of pass 1 takes the blocks it may pull plainly (:func:`build_clear_blocks`)
        self._block_form = vector and not target.is_cuda
        self.nbr = self._to_target(np.ascontiguousarray(nbr, dtype=np.int64))
        shape = (self.nblocks, self.lat.q, CELLS)
        self.h = self._to_target(np.zeros(shape, self.real))
        self.h_next = self._to_target(np.zeros(shape, self.real))
        self.phi = self._to_target(np.zeros((self.nblocks, CELLS), self.real))
        #: Body covering each cell (-1: none), ``[block, cell]`` int32; the coupling replaces it by its own table.
        self.solid = self._to_target(np.full((self.nblocks, CELLS), -1, np.int32))
        #: 1 where a block's h holds its state, 0 where phi does (a block left frozen by
        #: :mod:`iceresist.freesurface.bulk`), ``[block]`` int8: h is pulled and summed only where it is 1.
        self.valid = self._to_target(np.ones(self.nblocks, np.int8))
        self._active = None  # (stream, collide, init) over a block mask, made at the first masked step
        self._volume = None  # (launcher, per-block sums), made at the first volume()
        self._clear = None   # (launchers, has-solid and clear flags per block), made at the first block-form step

    @property
    def omega(self):
        return self.real(1.0 / self.tau)

    @property
    def kappa(self):
        return self.real(self.mobility / (self.lat.cs2 * self.width))

    def _to_target(self, a):
        return self.target.to_device(a)

    def _host(self, a) -> np.ndarray:
        return self.target.to_host(a)

    def _u(self, u):
        """The velocity ``u`` where the kernels read it: a host array is copied over (in the working precision),
        a target array is used as it is."""
        return self._to_target(np.ascontiguousarray(u, dtype=self.real)) if jit.is_host_array(u) else u

    def initialize(self, phi0: np.ndarray, u: np.ndarray) -> None:
        """Set phi (``[block, cell]``) and h = h^eq(phi, u, n)."""
        self.phi = self._to_target(np.array(phi0, dtype=self.real, order="C"))  # a copy: phi is state
        self._init(self.nblocks, self.h, self.phi, self._u(u), self.nbr, self.kappa)
        self.valid = self._to_target(np.ones(self.nblocks, np.int8))

    def _clear_blocks(self):
        """The blocks where the block form of pass 1 may pull plainly (:func:`build_clear_blocks`), host int8."""
        if self._clear is None:
            self._clear = (*clear_launchers(), np.zeros(self.nblocks, np.int8), np.zeros(self.nblocks, np.int8))
        solid_block, clear_block, has, clear = self._clear
        solid_block(self.nblocks, self.solid, has)
        clear_block(self.nblocks, has, self.nbr, clear)
        return clear

    def step(self, u) -> None:
        """One time step: h and phi(t+1) by pull streaming, then collide h with u (``[block, 3, cell]``)."""
        if self._block_form:
            self._stream(self.nblocks, self.h, self.h_next, self.phi, self.nbr, self.solid, self._clear_blocks())
        else:
            self._stream(self.nblocks, self.h, self.h_next, self.phi, self.nbr, self.solid)
        self._collide(self.nblocks, self.h_next, self.phi, self._u(u), self.nbr, self.omega, self.kappa, self.solid)
        self.h, self.h_next = self.h_next, self.h

    def _masked(self):
        if self._active is None:
            self._active = active_phase_launchers(self.target, np.dtype(self.real).name, self.lat.name)
        return self._active

    def _init_active(self, nblocks, active, h, phi, u, nbr, kappa) -> None:
        """h = h^eq(phi, u, n) in the blocks flagged in ``active``."""
        self._masked()[2](nblocks, active, h, phi, u, nbr, kappa)

    def stream_collide(self, u, active) -> None:
        """:meth:`step` in the blocks flagged in ``active`` (int8 per block, on the target) only. Every neighbour of a
        flagged block must hold h to pull (flagged, or refilled: :class:`~iceresist.freesurface.bulk.FrozenBulk`)."""
        stream, collide, _ = self._masked()
        n = self.nblocks
        if self._block_form:
            stream(n, active, self.h, self.h_next, self.phi, self.nbr, self.solid, self._clear_blocks())
        else:
            stream(n, active, self.h, self.h_next, self.phi, self.nbr, self.solid)
        collide(n, active, self.h_next, self.phi, self._u(u), self.nbr, self.omega, self.kappa, self.solid)
        self.h, self.h_next = self.h_next, self.h

    def phi_host(self) -> np.ndarray:
        """phi at the last completed pass 1, ``[block, cell]``, on the host."""
        return self._host(self.phi)

    def volume(self) -> float:
        """sum_k h_k over the cells not covered by a solid (the conserved phase volume, cells^3), in float64,
        summed per block on the target (no host copy of h)."""
        return float(self.volume_per_block().sum())

    def volume_per_block(self) -> np.ndarray:
        """The phase volume of each block (nblocks,), float64, on the host (:meth:`volume` before its sum)."""
        if self._volume is None:
            self._volume = (volume_launcher(self.target, self.lat.name),
                            self._to_target(np.zeros(self.nblocks, np.float64)))
        launch, out = self._volume
        launch(self.nblocks, self.h, self.phi, self.valid, self.solid, out)
        return np.asarray(self._host(out))
