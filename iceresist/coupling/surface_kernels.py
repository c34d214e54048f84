"""Kernels of the moving-boundary coupling with a free surface (paper sections 2.2 and 2.4).

With a :class:`~iceresist.freesurface.fluid.FreeSurfaceFluid` the coupling passes of
:mod:`iceresist.coupling.kernels` change where the liquid ends (phi < 1/2: GAS, no populations) and gain
the phase field (``phi[block, cell]``, ``h[block, k, cell]`` on the h lattice):

1. ``classify_refill_fs`` (per cell of the active blocks): a covered cell becomes GHOST; a cell that keeps
   its state keeps the flags the free surface gave it (liquid, NEAR_SURFACE or GAS); a cell a body
   uncovered gets phi from its neighbours (w-weighted mean of the phi of the cells uncovered before and
   now, extrapolated across the surface) and h at equilibrium, h_k = phi Gamma_k(u_wall) (eqs. 7-8 with
   the interface term left out); it is liquid (general path) where phi >= 1/2 and then gets the f refill of
   the single-phase rule from its liquid neighbours, else GAS with f = f^eq(rho0 = 1, u_wall);
2. ``redistribute_fs`` (per cell of the blocks next to events): a liquid cell takes its share of the mass
   excess of a newly covered liquid cell (and gives back that of a refilled liquid cell), as before; every
   cell not covered takes its share w_q / sum w of the phi of a newly covered cell (and gives back that of a
   refilled one), added to its rest population h_0: sum phi over the cells outside the bodies, the water volume,
   is unchanged by the motion of the bodies. A block whose phi, not h, is the state (:mod:`iceresist.freesurface.bulk`,
   deep in one phase) takes no share: nothing there would carry it away;
3. ``mirror`` (in the link pass, :func:`build_mirror`): a covered cell within ``MIRROR_DEPTH`` of the surface gets the
   phi at its mirror point across the surface, p = y - 2 s(y) grad s (s the signed distance), interpolated
   trilinearly from the cells outside the bodies. The gradient stencil of the phase field reads it: the
   normal derivative of phi at the surface vanishes (neutral wetting, a 90 degree contact angle, as at the
   walls of the domain); the h of the outside cells bounce back from covered cells
   (:mod:`iceresist.freesurface.phasefield`, ``solid``);
4. the link pass (:mod:`iceresist.coupling.kernels` with ``free_surface=True``) bounces back only on links
   to liquid cells, so the momentum exchange sums the gauge pressure and shear of the water over the wetted
   surface; the reference pressure rho0 c_s^2 left out of eq. (17) is that of the gas (eq. 11), so the dry
   part carries no force. Buoyancy is the integral of the hydrostatic pressure of the gravity body force.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.backends import jit
from iceresist.coupling.bodystate import build_reach_mask
from iceresist.coupling.cellfunctions import build_geometry_functions, build_refill_functions, build_sdf_difference
from iceresist.freesurface.layout import HALO1_SIDE, build_halo_or
from iceresist.grid import flags as FL
from iceresist.lattice import C, Q, W
from iceresist.lbm.boundary import GHOST


def build_surface_visits(target, real, hlat):
    """``classify_refill_fs, redistribute_fs`` (module docstring) for the h lattice ``hlat``."""
    lookup, sdf_at, wall_velocity = build_geometry_functions(target, real)
    stable, add_nonequilibrium = build_refill_functions(target, real)
    reach_mask = build_reach_mask(target)
    zero, half, one, three = real(0.0), real(0.5), real(1.0), real(3.0)
    c45, c15 = real(4.5), real(1.5)
    fluid, ghost, gas, near_surface = FL.FLUID, GHOST, FL.GAS, FL.NEAR_SURFACE
    nq = Q
    CXI, CYI, CZI = (np.ascontiguousarray(C[:, a]).astype(np.int64) for a in range(3))
    CXR, CYR, CZR = (np.ascontiguousarray(C[:, a]).astype(real) for a in range(3))
    WR = W.astype(real)
    nh = hlat.q
    hc = np.asarray(hlat.c, dtype=np.float64)
    HX, HY, HZ = (np.ascontiguousarray(hc[:, a]).astype(real) for a in range(3))
    HW = np.array(hlat.w, dtype=real)
    ics2, half_ics4, hcs2 = real(1.0 / hlat.cs2), real(0.5 / hlat.cs2 ** 2), real(hlat.cs2)
    dev = target.device

    @dev
    def phase_of(b, c, h):
        s = zero
        for k in range(nh):
            s += h[b, k, c]
        return s

    @dev
    def classify_refill_fs(b, c, borigin, body, grid, block_map, flags0, flags, owner, owner_prev, f, block_evt,
                           Fx, Fy, Fz, phi, h, valid):
        k = owner[b, c]
        if k >= 0:
            flags[b, c] = ghost
            if owner_prev[b, c] < 0:
                block_evt[b] = 1
            return
        fl = flags0[b, c]
        if (fl & fluid) == 0:
            flags[b, c] = fl
            return
        kp = owner_prev[b, c]
        if kp < 0:
            return
        block_evt[b] = 1
        gx = borigin[b, 0] * 8 + (c & 7)
        gy = borigin[b, 1] * 8 + ((c >> 3) & 7)
        gz = borigin[b, 2] * 8 + (c >> 6)
        ux, uy, uz, rx, ry, rz = wall_velocity(kp, real(gx) + half, real(gy) + half, real(gz) + half, body, grid)
        # phase field: phi from the cells outside the bodies (sum h where h is the state, phi in a frozen
        # block, whose h is stale: iceresist.freesurface.bulk), h at equilibrium
        wsum = zero
        psum = zero
        for q in range(1, nq):
            nb, nc = lookup(gx + CXI[q], gy + CYI[q], gz + CZI[q], grid, block_map)
            if nb < 0:
                continue
            if stable(nb, nc, flags0, owner, owner_prev):
                wsum += WR[q]
                psum += WR[q] * (phase_of(nb, nc, h) if valid[nb] != 0 else phi[nb, nc])
        p = phi[b, c]
        if wsum > zero:
            p = psum / wsum
        phi[b, c] = p
        uu = ux * ux + uy * uy + uz * uz
        for m in range(nh):
            cu = HX[m] * ux + HY[m] * uy + HZ[m] * uz
            h[b, m, c] = HW[m] * p * (one + ics2 * cu + half_ics4 * (cu * cu - hcs2 * uu))
        # flow: liquid with the single-phase refill, or gas at the reference density
        for m in range(nq):
            f[b, m, c] = zero
        rho = one
        inv = zero
        if p >= half:
            wsum = zero
            rsum = zero
            for q in range(1, nq):
                nb, nc = lookup(gx + CXI[q], gy + CYI[q], gz + CZI[q], grid, block_map)
                if nb < 0:
                    continue
                if not stable(nb, nc, flags0, owner, owner_prev) or (flags[nb, nc] & fluid) == 0:
                    continue
                w = WR[q]
                rn = add_nonequilibrium(f, b, c, nb, nc, w)
                wsum += w
                rsum += w * rn
            if wsum > zero:
                rho = rsum / wsum
                inv = one / wsum
            flags[b, c] = fl | near_surface
        else:
            flags[b, c] = gas
        vx = ux + half * Fx           # stored populations carry u + g / 2 (force density rho g)
        vy = uy + half * Fy
        vz = uz + half * Fz
        vv = vx * vx + vy * vy + vz * vz
        for m in range(nq):
            cu = CXR[m] * vx + CYR[m] * vy + CZR[m] * vz
            f[b, m, c] = f[b, m, c] * inv + WR[m] * ((rho - one) + rho * (three * cu + c45 * cu * cu - c15 * vv))

    @dev
    def redistribute_fs(b, c, near, borigin, grid, block_map, flags0, flags, owner, owner_prev, f, phi, h, valid):
        if (reach_mask(c) & near[b]) == 0:   # no neighbour in a block with an event
            return
        if not stable(b, c, flags0, owner, owner_prev):
            return
        liquid = (flags[b, c] & fluid) != 0
        gx = borigin[b, 0] * 8 + (c & 7)
        gy = borigin[b, 1] * 8 + ((c >> 3) & 7)
        gz = borigin[b, 2] * 8 + (c >> 6)
        accf = zero
        acch = zero
        for q in range(1, nq):
            hx, hy, hz = gx + CXI[q], gy + CYI[q], gz + CZI[q]
            yb, yc = lookup(hx, hy, hz, grid, block_map)
            if yb < 0:
                continue
            if (flags0[yb, yc] & fluid) == 0:
                continue
            now = owner[yb, yc] >= 0
            if now == (owner_prev[yb, yc] >= 0):
                continue
            # a newly covered cell was liquid if its phi (of the last step) was; a refilled one if flagged so
            y_liquid = phi[yb, yc] >= half if now else (flags[yb, yc] & fluid) != 0
            ph = phase_of(yb, yc, h) if valid[yb] != 0 else phi[yb, yc]   # phi is the state of a frozen block
            excess = zero
            if liquid and y_liquid:
                for m in range(nq):
                    excess += f[yb, m, yc]
            if not now:
                ph = -ph
                excess = -excess
            wh = zero
            wf = zero
            for m in range(1, nq):
                zb, zc = lookup(hx + CXI[m], hy + CYI[m], hz + CZI[m], grid, block_map)
                if zb >= 0:
                    if stable(zb, zc, flags0, owner, owner_prev):
                        wh += WR[m]
                        if (flags[zb, zc] & fluid) != 0:
                            wf += WR[m]
            acch += ph * WR[q] / wh
            if liquid and y_liquid:
                accf += excess * WR[q] / wf
        # Where h is the state the hand-over is advected and diffused by the phase field. A frozen block
        # (iceresist.freesurface.bulk) has nothing to carry it away: each cell a moving body covers would hand on
        # what its neighbours gave it, and the excess would pile up ahead of the body (in the quick tier-2 case
        # phi grew by 0.1 per record ahead of the keel, up to NaN). There phi keeps 1 (or 0): a body in the
        # frozen liquid covers and uncovers as many liquid cells.
        if valid[b] != 0:
            h[b, 0, c] += acch
        if liquid:
            f[b, 0, c] += accf

    return classify_refill_fs, redistribute_fs


def build_redistribute_block(real, hlat):
    """The CPU block form ``redistribute_fs_block(b, near, ...)`` of ``redistribute_fs`` (:func:`build_surface_visits`,
    the same arguments without the cell): the event cells (a fluid cell of the forest whose cover changed in the
    last step) of the block and a one-cell halo go into a 10^3 scratch row by row, are ORed over the 26 offsets
    across the 512 cells, and only the cells next to an event run the per-cell visit; the others would add
    nothing (of the 221 k cells of the quick tier-2 case's event blocks, a few thousand are next to one of its
    ~200 events per step)."""
    lookup, _, _ = build_geometry_functions(jit.cpu, real)
    _, redistribute_fs = build_surface_visits(jit.cpu, real, hlat)
    fluid = FL.FLUID
    int8 = np.int8
    side = HALO1_SIDE
    halo_or = build_halo_or()

    def redistribute_fs_block(b, near, borigin, grid, block_map, flags0, flags, owner, owner_prev, f, phi, h, valid):
        b = np.int64(b)
        ev = np.empty(side ** 3, int8)
        gx0 = borigin[b, 0] * 8
        for pz in range(side):
            for py in range(side):
                gy = borigin[b, 1] * 8 + py - 1
                gz = borigin[b, 2] * 8 + pz - 1
                row = side * (py + side * pz)
                for x in range(side):
                    ev[row + x] = int8(0)
                # three runs of the row: x = -1, 0..7, 8 (global gx0 - 1 ...), one look-up each
                for run in range(3):
                    x0 = -1 if run == 0 else (0 if run == 1 else 8)
                    n = 8 if run == 1 else 1
                    yb, yc = lookup(gx0 + x0, gy, gz, grid, block_map)
                    if yb < 0:
                        continue
                    for x in range(n):
                        if (flags0[yb, yc + x] & fluid) != 0 and (owner[yb, yc + x] >= 0) != (owner_prev[yb, yc + x] >= 0):
                            ev[row + 1 + x0 + x] = int8(1)
        nm = np.empty(512, int8)
        halo_or(ev, nm)
        for c in range(512):
            if nm[c]:
                redistribute_fs(b, c, near, borigin, grid, block_map, flags0, flags, owner, owner_prev, f, phi, h,
                                valid)

    return jit.cpu.device(redistribute_fs_block)


def build_mirror(target, real):
    """``mirror(k, b, c, yx, yy, yz, s, body, bint, planes, grid, block_map, flags0, owner, phi)``: step 3 of the
    module docstring for the covered cell (b, c) of row k, centre (yx, yy, yz), signed distance s (within
    ``MIRROR_DEPTH`` of the surface; the caller checks). The link pass calls it for each covered cell it visits
    (:func:`iceresist.coupling.kernels.build_visits`): it reads phi only outside the bodies and writes it only
    inside, and the links read no phi, so one visit does both."""
    lookup = build_geometry_functions(target, real)[0]
    sdf_difference = build_sdf_difference(target, real)
    zero, half, one, eps = real(0.0), real(0.5), real(1.0), real(1e-12)
    fluid = FL.FLUID

    @target.device
    def mirror(k, b, c, yx, yy, yz, s, body, bint, planes, grid, block_map, flags0, owner, phi):
        nx, ny, nz = sdf_difference(k, yx, yy, yz, body, bint, planes, grid)
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nn < eps:
            return
        d = -(s + s) / nn
        px, py, pz = yx + d * nx - half, yy + d * ny - half, yz + d * nz - half     # in cell-index coordinates
        ix, iy, iz = int(math.floor(px)), int(math.floor(py)), int(math.floor(pz))
        tx, ty, tz = px - real(ix), py - real(iy), pz - real(iz)
        acc = zero
        wsum = zero
        for corner in range(8):
            ax = corner & 1
            ay = (corner >> 1) & 1
            az = corner >> 2
            nb, nc = lookup(ix + ax, iy + ay, iz + az, grid, block_map)
            if nb < 0:
                continue
            if (flags0[nb, nc] & fluid) == 0 or owner[nb, nc] >= 0:
                continue
            w = (tx if ax else one - tx) * (ty if ay else one - ty) * (tz if az else one - tz)
            acc += w * phi[nb, nc]
            wsum += w
        if wsum > real(1e-3):
            phi[b, c] = acc / wsum

    return mirror
