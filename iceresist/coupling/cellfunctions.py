"""Device functions the coupling passes share, with and without a free surface.

:mod:`iceresist.coupling.kernels` (the passes of a coupling step) and :mod:`iceresist.coupling.surface_kernels`
(their free-surface forms) both build on these: the geometry of a body seen from a cell (``lookup``, ``sdf_at``,
``wall_velocity``) and the refill of a cell a body uncovers (``stable``, ``add_nonequilibrium``). Conventions (lattice
units, the ``body``/``bint``/``grid`` arrays) are those of :mod:`iceresist.coupling.kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.coupling.geometry import BOX, SPHERE
from iceresist.grid import flags as FL
from iceresist.lattice import C, Q, W

#: Covered cells deeper than this (lattice units of signed distance) keep their phi: the gradient stencil of a
#: cell outside reaches only covered cells within sqrt(3) of the surface.
MIRROR_DEPTH = 2.0


def build_offset(target, real):
    """``offset(k, px, py, pz, body, grid) -> p - x_s`` of body k (lattice units), the nearest image on periodic
    axes."""
    half = real(0.5)

    @target.device
    def offset(k, px, py, pz, body, grid):
        dx = px - body[k, 0]
        dy = py - body[k, 1]
        dz = pz - body[k, 2]
        if grid[3] != 0:
            L = real(grid[0])
            dx -= L * real(math.floor(dx / L + half))
        if grid[4] != 0:
            L = real(grid[1])
            dy -= L * real(math.floor(dy / L + half))
        if grid[5] != 0:
            L = real(grid[2])
            dz -= L * real(math.floor(dz / L + half))
        return dx, dy, dz

    return offset


def build_body_frame(target, real):
    """``(to_body, body_point)``: ``to_body(k, vx, vy, vz, body) -> R^T v``, a world vector in body k's frame, and
    ``body_point(k, px, py, pz, body, grid) -> R^T (p - x_s)``, a world point (the nearest periodic image,
    :func:`build_offset`)."""
    offset = build_offset(target, real)

    @target.device
    def to_body(k, vx, vy, vz, body):
        return (body[k, 3] * vx + body[k, 6] * vy + body[k, 9] * vz,
                body[k, 4] * vx + body[k, 7] * vy + body[k, 10] * vz,
                body[k, 5] * vx + body[k, 8] * vy + body[k, 11] * vz)

    @target.device
    def body_point(k, px, py, pz, body, grid):
        dx, dy, dz = offset(k, px, py, pz, body, grid)
        return to_body(k, dx, dy, dz, body)

    return to_body, body_point


def build_box_distance(target, real):
    """``box_distance(x, y, z, hx, hy, hz)``: signed distance of body-frame point (x, y, z) to the box of half
    extents h about the origin (exact inside and outside)."""
    zero = real(0.0)

    @target.device
    def box_distance(x, y, z, hx, hy, hz):
        qx = abs(x) - hx
        qy = abs(y) - hy
        qz = abs(z) - hz
        mx = max(qx, zero)
        my = max(qy, zero)
        mz = max(qz, zero)
        return math.sqrt(mx * mx + my * my + mz * mz) + min(max(qx, max(qy, qz)), zero)

    return box_distance


def build_geometry_functions(target, real):
    """Small device functions: ``lookup`` of a global cell, ``sdf_at`` a world point, ``wall_velocity``."""
    half, zero, two, big = real(0.5), real(0.0), real(2.0), real(1e30)
    sphere_kind, box_kind = SPHERE, BOX
    dev = target.device

    @dev
    def lookup(gx, gy, gz, grid, block_map):
        """(block, cell) of global cell (gx, gy, gz); block -1 outside the domain or in no block."""
        nx, ny, nz = grid[0], grid[1], grid[2]
        if gx < 0 or gx >= nx:
            if grid[3] == 0:
                return -1, 0
            gx = gx % nx
        if gy < 0 or gy >= ny:
            if grid[4] == 0:
                return -1, 0
            gy = gy % ny
        if gz < 0 or gz >= nz:
            if grid[5] == 0:
                return -1, 0
            gz = gz % nz
        b = block_map[gx >> 3, gy >> 3, gz >> 3]
        return b, (gx & 7) + 8 * ((gy & 7) + 8 * (gz & 7))

    offset = build_offset(target, real)
    _, body_point = build_body_frame(target, real)
    box_distance = build_box_distance(target, real)

    @dev
    def sdf_at(k, px, py, pz, body, bint, planes, grid):
        """Signed distance (lattice units) of world point p to body k, negative inside."""
        x, y, z = body_point(k, px, py, pz, body, grid)
        kind = bint[k, 0]
        if kind == sphere_kind:
            return math.sqrt(x * x + y * y + z * z) - body[k, 18]
        if kind == box_kind:
            return box_distance(x, y, z, body[k, 18], body[k, 19], body[k, 20])
        # convex pieces (geometry.ConvexUnion): dp = max over a piece's planes, ds = the same without its caps
        # (rows of normal length 2, shared with the next piece); outside: min over the pieces of dp; inside a
        # piece: min of ds over the pieces that hold p (the distance to the surface, not to a seam). One piece
        # without caps is the plain convex polyhedron.
        d_out = big
        d_in = big
        dp = -big
        ds = -big
        first = bint[k, 1]
        last = first + bint[k, 2]
        for i in range(first, last + 1):
            if i == last or (planes[i, 0] == zero and planes[i, 1] == zero and planes[i, 2] == zero):
                d_out = min(d_out, dp)
                if dp < zero:
                    d_in = min(d_in, ds)
                dp = -big
                ds = -big
            else:
                nx, ny, nz = planes[i, 0], planes[i, 1], planes[i, 2]
                v = nx * x + ny * y + nz * z + planes[i, 3]
                if nx * nx + ny * ny + nz * nz > two:
                    dp = max(dp, half * v)
                else:
                    dp = max(dp, v)
                    ds = max(ds, v)
        if d_in < big:
            return d_in
        return d_out

    @dev
    def wall_velocity(k, px, py, pz, body, grid):
        """Velocity v + omega x r of body k at world point p, and r = p - x_s."""
        rx, ry, rz = offset(k, px, py, pz, body, grid)
        ox, oy, oz = body[k, 15], body[k, 16], body[k, 17]
        return (body[k, 12] + oy * rz - oz * ry, body[k, 13] + oz * rx - ox * rz,
                body[k, 14] + ox * ry - oy * rx, rx, ry, rz)

    return lookup, sdf_at, wall_velocity


def build_sdf_difference(target, real):
    """``sdf_difference(k, px, py, pz, body, bint, planes, grid) -> (gx, gy, gz)``: the central differences of
    ``sdf_at`` (:func:`build_geometry_functions`) at world point p with a step of 1/2 each side, sdf(p + e/2) -
    sdf(p - e/2) along each world axis e: the same values, to round-off, from one rotation into the body frame
    (the world axes there are the rows of R) and, for one convex polyhedron, one loop over its planes, each plane's
    value at the six points being its value at p plus or minus half its rate along the axis. A union of convex
    pieces and a periodic domain (whose nearest image may change between the points) take the six distances."""
    _, sdf_at, _ = build_geometry_functions(target, real)
    _, body_point = build_body_frame(target, real)
    box_distance = build_box_distance(target, real)
    zero, half, big = real(0.0), real(0.5), real(1e30)
    sphere, box = SPHERE, BOX

    @target.device
    def sphere_difference(x, y, z, ex, ey, ez):
        return (math.sqrt((x + ex) ** 2 + (y + ey) ** 2 + (z + ez) ** 2)
                - math.sqrt((x - ex) ** 2 + (y - ey) ** 2 + (z - ez) ** 2))

    @target.device
    def sdf_difference(k, px, py, pz, body, bint, planes, grid):
        kind = bint[k, 0]
        one_piece = grid[3] == 0 and grid[4] == 0 and grid[5] == 0
        if one_piece and kind != sphere and kind != box:
            for i in range(bint[k, 1], bint[k, 1] + bint[k, 2]):
                nn = planes[i, 0] * planes[i, 0] + planes[i, 1] * planes[i, 1] + planes[i, 2] * planes[i, 2]
                if nn == zero or nn > real(1.5):     # a separator or a shared cap: a union of pieces
                    one_piece = False
        if not one_piece:
            return (sdf_at(k, px + half, py, pz, body, bint, planes, grid)
                    - sdf_at(k, px - half, py, pz, body, bint, planes, grid),
                    sdf_at(k, px, py + half, pz, body, bint, planes, grid)
                    - sdf_at(k, px, py - half, pz, body, bint, planes, grid),
                    sdf_at(k, px, py, pz + half, body, bint, planes, grid)
                    - sdf_at(k, px, py, pz - half, body, bint, planes, grid))
        x, y, z = body_point(k, px, py, pz, body, grid)
        # half a world axis in the body frame: row a of R (R^T e_a)
        xx, xy, xz = half * body[k, 3], half * body[k, 4], half * body[k, 5]
        yx, yy, yz = half * body[k, 6], half * body[k, 7], half * body[k, 8]
        zx, zy, zz = half * body[k, 9], half * body[k, 10], half * body[k, 11]
        if kind == sphere:
            return (sphere_difference(x, y, z, xx, xy, xz), sphere_difference(x, y, z, yx, yy, yz),
                    sphere_difference(x, y, z, zx, zy, zz))
        if kind == box:
            hx, hy, hz = body[k, 18], body[k, 19], body[k, 20]
            return (box_distance(x + xx, y + xy, z + xz, hx, hy, hz) - box_distance(x - xx, y - xy, z - xz, hx, hy, hz),
                    box_distance(x + yx, y + yy, z + yz, hx, hy, hz) - box_distance(x - yx, y - yy, z - yz, hx, hy, hz),
                    box_distance(x + zx, y + zy, z + zz, hx, hy, hz) - box_distance(x - zx, y - zy, z - zz, hx, hy, hz))
        xp, xm, yp, ym, zp, zm = -big, -big, -big, -big, -big, -big
        for i in range(bint[k, 1], bint[k, 1] + bint[k, 2]):
            nx, ny, nz = planes[i, 0], planes[i, 1], planes[i, 2]
            v = nx * x + ny * y + nz * z + planes[i, 3]
            rx = nx * xx + ny * xy + nz * xz
            ry = nx * yx + ny * yy + nz * yz
            rz = nx * zx + ny * zy + nz * zz
            xp, xm = max(xp, v + rx), max(xm, v - rx)
            yp, ym = max(yp, v + ry), max(ym, v - ry)
            zp, zm = max(zp, v + rz), max(zm, v - rz)
        return xp - xm, yp - ym, zp - zm

    return sdf_difference


def build_link_root(target, real):
    """``link_root(k, px, py, pz, cx, cy, cz, body, bint, planes, grid) -> t``: where the segment p - t c,
    t in [0, 1], from a cell centre p outside body k to the centre p - c of a covered cell enters the body, in
    closed form (the link distance q_d of eq. 16): a sphere by the smaller root of |o - t d|^2 = r^2, a box by the
    latest entry into its three slabs, a convex polyhedron by the latest entry through the planes facing p,
    max over n . d > 0 of (n . o + e) / (n . d) (o = p - x_s and d = c in the body frame), a union of convex
    pieces by the first entry into a piece the segment crosses. A p inside the body (by round-off) gives t <= 0.
    Returns -1 where round-off leaves no entry in [0, 1]: the caller then finds the root on the signed distance."""
    zero, one, big = real(0.0), real(1.0), real(1e30)
    sphere_kind, box_kind = SPHERE, BOX
    to_body, body_point = build_body_frame(target, real)
    dev = target.device

    @dev
    def slab_entry(o, d, h):
        """Earliest t with |o - t d| <= h along one axis of a box (-big where d is 0: no bound)."""
        if d == zero:
            return -big
        return min((o - h) / d, (o + h) / d)

    @dev
    def link_root(k, px, py, pz, cx, cy, cz, body, bint, planes, grid):
        ox, oy, oz = body_point(k, px, py, pz, body, grid)
        ex, ey, ez = to_body(k, cx, cy, cz, body)
        kind = bint[k, 0]
        if kind == sphere_kind:
            r = body[k, 18]
            dd = ex * ex + ey * ey + ez * ez
            od = ox * ex + oy * ey + oz * ez
            disc = od * od - dd * (ox * ox + oy * oy + oz * oz - r * r)
            return (od - math.sqrt(max(disc, zero))) / dd
        if kind == box_kind:
            return max(slab_entry(ox, ex, body[k, 18]), max(slab_entry(oy, ey, body[k, 19]),
                                                          slab_entry(oz, ez, body[k, 20])))
        # convex pieces (one, or a union separated by rows of normal 0): the segment lies in a piece for
        # t_in <= t <= t_out; it enters the union where it first enters a piece it crosses. A cap stored at twice
        # its length (geometry.ConvexUnion) gives the same ratio v / (n . d).
        t = big
        t_in = -big
        t_out = big
        first = bint[k, 1]
        last = first + bint[k, 2]
        for i in range(first, last + 1):
            if i == last or (planes[i, 0] == zero and planes[i, 1] == zero and planes[i, 2] == zero):
                if t_in <= t_out and t_out >= zero and t_in <= one:
                    t = min(t, t_in)
                t_in = -big
                t_out = big
            else:
                nx, ny, nz = planes[i, 0], planes[i, 1], planes[i, 2]
                nd = nx * ex + ny * ey + nz * ez
                v = nx * ox + ny * oy + nz * oz + planes[i, 3]
                if nd > zero:
                    t_in = max(t_in, v / nd)
                elif nd < zero:
                    t_out = min(t_out, v / nd)
                elif v > zero:
                    t_out = -big        # parallel to a face it lies outside of: never in this piece
        if t == big:
            return -one                 # no entry found (round-off): the caller finds the root on the SDF
        return t

    return link_root


def build_refill_functions(target, real):
    """Device functions the single-phase and the free-surface refill share.

    * ``stable(b, c, flags0, owner, owner_prev)``: the cell is fluid in the forest and no body covered it in this
      or the previous step, so its populations can be read;
    * ``add_nonequilibrium(f, b, c, nb, nc, w)``: f[b, :, c] += w (f_n - f^eq(rho_n, u_n)) of the neighbour
      (nb, nc), populations in the f - w form; returns rho_n (the refill of the module docstring).
    """
    zero, one, three = real(0.0), real(1.0), real(3.0)
    c45, c15 = real(4.5), real(1.5)
    fluid, nq = FL.FLUID, Q
    CXR, CYR, CZR = (np.ascontiguousarray(C[:, a]).astype(real) for a in range(3))
    WR = W.astype(real)
    dev = target.device

    @dev
    def stable(b, c, flags0, owner, owner_prev):
        return (flags0[b, c] & fluid) != 0 and owner[b, c] < 0 and owner_prev[b, c] < 0

    @dev
    def add_nonequilibrium(f, b, c, nb, nc, w):
        rho = one
        jx = zero
        jy = zero
        jz = zero
        for p in range(nq):
            g = f[nb, p, nc]
            rho += g
            jx += CXR[p] * g
            jy += CYR[p] * g
            jz += CZR[p] * g
        vx, vy, vz = jx / rho, jy / rho, jz / rho
        uu = vx * vx + vy * vy + vz * vz
        for p in range(nq):
            cu = CXR[p] * vx + CYR[p] * vy + CZR[p] * vz
            geq = WR[p] * ((rho - one) + rho * (three * cu + c45 * cu * cu - c15 * uu))
            f[b, p, c] += w * (f[nb, p, nc] - geq)
        return rho

    return stable, add_nonequilibrium
