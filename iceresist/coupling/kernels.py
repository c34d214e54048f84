"""Kernels of the moving-boundary coupling, one source for CPU and CUDA (paper section 2.4, eqs. 16-19).

Everything is in lattice units: cell (i, j, k) has its centre at (i + 1/2, j + 1/2, k + 1/2); a body's
position, velocity (cells per step) and angular velocity (rad per step) are lattice values.

Arrays the kernels share:

* ``body[n, 21]`` (real): centre of mass (0-2), rotation body -> world, row-major (3-11), velocity (12-14),
  angular velocity (15-17), shape parameters (18-20: sphere radius or box half extents);
* ``bint[n, 12]`` (int32): shape kind, first plane, plane count, then the cell box lo (3) and hi (3) the
  row may touch (global cell indices, inclusive; beyond the domain on periodic axes), the body the row
  belongs to, and the run of the box's cells the row visits (a large body is launched as several rows, each a
  run of its box's cells, :func:`iceresist.coupling.coupler.tile_rows`);
* ``planes[m, 4]`` (real): face planes n . p + d of convex bodies in the body frame;
* ``grid[6]`` (int64): nx, ny, nz and 1 for periodic axes; ``block_map[nbx, nby, nbz]``: block index or -1;
* ``owner[nblocks, 512]`` (int32): the body covering a cell now (-1: none), ``owner_prev`` the same one step
  earlier; ``flags0`` the static flags of the forest, ``flags`` the table the fused kernel reads.

Passes of one coupling step, each a launch:

1. ``mark`` (per body over its cell box; on the CPU walked along x lines that pass over the cells whose side of the
   surface is known, :mod:`iceresist.coupling.runs`): owner = body where the signed distance at the cell centre < 0;
2. ``classify_refill`` (per cell of the active blocks): flags = GHOST where covered, else the static flags;
   a cell a body uncovered gets equilibrium populations at the body's velocity there and the weighted
   mean density of its fluid neighbours, plus their mean non-equilibrium part (the refill);
3. ``redistribute`` (per cell of the blocks next to a block with a covered or uncovered cell): a fluid cell next
   to a newly covered cell takes its share w_q / sum w of that cell's mass excess rho - 1, and next to a
   refilled cell gives back its share of that cell's excess, so that the sum of rho - 1 over the fluid is
   unchanged; the share goes into the rest population. Gathering (each cell writes only itself) makes it race-free;
   a cell whose 26 neighbours lie in no block with such a cell returns at once (the 27-bit ``near`` mask per block,
   :func:`iceresist.coupling.bodystate.build_event_mask`);
4. ``links`` (per body over its cell box; on CUDA over the list of the covered cells near the surface that
   ``mark`` appends to, :func:`build_link_list`): for every covered cell y and direction q with a fluid cell
   x = y + c_q, the link distance q_d in (0, 1] from x to the surface along -c_q (in closed form for spheres,
   boxes, convex polyhedra and their unions, :func:`iceresist.coupling.cellfunctions.build_link_root`), the
   interpolated bounce-back population of eq. (16) with the wall velocity
   v + omega x r at the wall point, written into slot q of y (the fused kernel pulls it from there), and the
   momentum exchange of eq. (17), summed into force and torque (eqs. 18-19) about the centre of mass. With a
   free surface the same visit of a covered cell near the surface mirrors phi into it
   (:func:`iceresist.coupling.surface_kernels.build_mirror`).

Populations are f - w (rho0 = 1). Eq. (16) keeps its form for f - w (its coefficients sum to one and
w_q = w_opp). In eq. (17) written for f - w the link gains the constant 2 w_q c_opp, the force of the
reference pressure rho0 c_s^2, which sums to zero over a closed surface; it is left out, so the force is that
of the gauge pressure (exact zero for a body at rest in fluid at rest, also where a body touches a wall).

Contact film: where a body touches another body or a wall, no fluid cell is left between them, so the face in
contact has no links and carries no pressure. Alone, that presses a submerged body onto what it touches with
the gauge pressure times the contact area: a 41 mm cube touching a plate 6 cm under the surface felt 3.2 x its
buoyancy, on the tank floor -3.9 x. A real contact keeps a film of water at the pressure around it. With
``film[0] = 1`` the links pass closes the surface: a link from a covered cell y of body k to a cell of another
body, a static solid or a wall face adds the momentum exchange of fluid at rest, -2 w_q (rho_film - 1) c_q
(eq. 17 for f = w rho, gauge part), with rho_film the mean density of the liquid neighbours of y, or where y
has none the hydrostatic density exp(3 g (z_s - z)) of the still water (``film[1]`` = g, ``film[2]`` = z_s, lattice
units; no gravity: rho_film = 1). Torque about the centre of mass at the link midpoint.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.backends import cache
from iceresist.backends.jit import cuda_api as jit_cuda_api
from iceresist.backends.launch import ActiveLauncher, BodyLauncher, ItemLauncher, build_accumulate
from iceresist.coupling.bodystate import build_reach_mask
from iceresist.coupling.cellfunctions import (MIRROR_DEPTH, build_geometry_functions, build_link_root,
                                              build_refill_functions)
from iceresist.coupling.runs import build_link_run, build_mark_run
from iceresist.coupling.surface_kernels import build_mirror, build_redistribute_block, build_surface_visits
from iceresist.grid import flags as FL
from iceresist.lattice import C, OPP, Q, W
from iceresist.lbm.boundary import GHOST

#: Regula-falsi (Illinois) iterations for the link distance where its closed form finds no entry (round-off at a
#: cell centre on the surface); exact after one for planar faces.
ROOT_ITERATIONS = 5
#: Smallest link distance used (avoids 1/(2q) blowing up where a cell centre lies on the surface).
Q_MIN = 1e-3

MARK_ARGS = ("bint", "body", "planes", "grid", "block_map", "flags0", "owner")
LINK_ARGS = ("bint", "body", "planes", "grid", "block_map", "flags0", "owner", "f", "bforce", "btorque", "nlinks",
             "flags", "film", "nowned")
REFILL_ARGS = ("active", "borigin", "body", "grid", "block_map", "flags0", "flags", "owner", "owner_prev", "f",
               "block_evt", "Fx", "Fy", "Fz")
REDIST_ARGS = ("active", "near", "borigin", "grid", "block_map", "flags0", "owner", "owner_prev", "f")
POISON_ARGS = ("active", "flags0", "owner", "owner_prev", "f")
REFILL_FS_ARGS = REFILL_ARGS + ("phi", "h", "valid")
REDIST_FS_ARGS = ("active", "near", "borigin", "grid", "block_map", "flags0", "flags", "owner", "owner_prev", "f",
                  "phi", "h", "valid")
LINK_FS_ARGS = LINK_ARGS + ("phi",)
#: The CUDA link list (:func:`build_link_list`): ``cells[i] = (row, cell of the row's box run)`` (int32),
#: ``svals[i]`` its signed distance, ``ncells[0]`` the cells listed this step (ncells[1]: those beyond the list).
LIST_ARGS = ("cells", "svals", "ncells")
#: Covered cells deeper than this (lattice units of signed distance) have no neighbour outside their body, so
#: the links pass skips them (no link, no contact film).
FILM_DEPTH = 2.0
#: The deepest covered cells the link pass acts on: links and film, or the mirror with a free surface.
LINK_DEPTH = max(FILM_DEPTH, MIRROR_DEPTH)


def build_visits(target, real, free_surface: bool = False):
    """The per-cell functions of the passes (see the module docstring); ``free_surface``: links only to liquid
    cells (``flags`` has the FLUID bit, :mod:`iceresist.freesurface`)."""
    lookup, sdf_at, wall_velocity = build_geometry_functions(target, real)
    link_root = build_link_root(target, real)
    reach_mask = build_reach_mask(target)
    accumulate = build_accumulate(target)
    stable, add_nonequilibrium = build_refill_functions(target, real)
    zero, half, one, two, three, six = (real(v) for v in (0.0, 0.5, 1.0, 2.0, 3.0, 6.0))
    c45, c15, qmin, nan, fdepth = real(4.5), real(1.5), real(Q_MIN), real(np.nan), real(FILM_DEPTH)
    mdepth = real(MIRROR_DEPTH)
    mirror = build_mirror(target, real)
    fluid, ghost, niter, nq = FL.FLUID, GHOST, ROOT_ITERATIONS, Q
    CXI, CYI, CZI = (np.ascontiguousarray(C[:, a]).astype(np.int64) for a in range(3))
    CXR, CYR, CZR = (np.ascontiguousarray(C[:, a]).astype(real) for a in range(3))
    WR = W.astype(real)
    OPPI = OPP.astype(np.int64)
    dev = target.device

    @dev
    def mark(k, gx, gy, gz, bint, body, planes, grid, block_map, flags0, owner):
        b, c = lookup(gx, gy, gz, grid, block_map)
        if b < 0:
            return
        if (flags0[b, c] & fluid) == 0:
            return
        if sdf_at(k, real(gx) + half, real(gy) + half, real(gz) + half, body, bint, planes, grid) < zero:
            owner[b, c] = k

    fs = bool(free_surface)

    @dev
    def add_load(bforce, btorque, k, Fx, Fy, Fz, rx, ry, rz):
        """Force F on row k and its torque r x F about the centre of mass (eqs. 18-19)."""
        accumulate(bforce, k, 0, Fx)
        accumulate(bforce, k, 1, Fy)
        accumulate(bforce, k, 2, Fz)
        accumulate(btorque, k, 0, ry * Fz - rz * Fy)
        accumulate(btorque, k, 1, rz * Fx - rx * Fz)
        accumulate(btorque, k, 2, rx * Fy - ry * Fx)

    @dev
    def liquid(xb, xc, flags0, owner, flags):
        """Cell (xb, xc) holds flow populations: fluid in the forest, no body on it, liquid with a free surface."""
        if xb < 0:
            return False
        if (flags0[xb, xc] & fluid) == 0 or owner[xb, xc] >= 0:
            return False
        return not fs or (flags[xb, xc] & fluid) != 0

    @dev
    def touches(k, hx, hy, hz, xb, xc, bint, grid, flags0, owner):
        """Cell (hx, hy, hz), found at (xb, xc) by ``lookup``, is a wall (outside a closed face, a static solid)
        or covered by another body than that of row k."""
        if xb >= 0:
            o = owner[xb, xc]
            if o == k:
                return False
            if (flags0[xb, xc] & fluid) == 0:
                return True
            return o >= 0 and bint[o, 9] != bint[k, 9]
        # no block there: a wall only beyond a closed face
        return (((hx < 0 or hx >= grid[0]) and grid[3] == 0) or ((hy < 0 or hy >= grid[1]) and grid[4] == 0)
                or ((hz < 0 or hz >= grid[2]) and grid[5] == 0))

    @dev
    def film_density(gx, gy, gz, grid, block_map, flags0, owner, f, flags, film):
        """rho_film of covered cell (gx, gy, gz): mean density of its liquid neighbours, else hydrostatic."""
        rsum = zero
        n = 0
        for q in range(1, nq):
            xb, xc = lookup(gx + CXI[q], gy + CYI[q], gz + CZI[q], grid, block_map)
            if not liquid(xb, xc, flags0, owner, flags):
                continue
            r = one
            for p in range(nq):
                r += f[xb, p, xc]
            rsum += r
            n += 1
        if n > 0:
            return rsum / real(n)
        depth = film[2] - (real(gz) + half)
        if depth <= zero:
            return one
        return math.exp(three * film[1] * depth)

    @dev
    def links_at(k, gx, gy, gz, s_in, bint, body, planes, grid, block_map, flags0, owner, f, bforce, btorque, nlinks,
                 flags, film, nowned):
        """``links`` of cell (gx, gy, gz) at signed distance ``s_in`` from body k (the run form has it)."""
        # a cell deeper than FILM_DEPTH (> sqrt(3), the longest link) inside its convex body has every neighbour
        # inside it too (the signed distance changes by at most the link length): no link and no film there
        if s_in <= -fdepth:
            return
        b, c = lookup(gx, gy, gz, grid, block_map)
        if b < 0:
            return
        if owner[b, c] != k:
            return
        link_cell(k, gx, gy, gz, b, c, real(gx) + half, real(gy) + half, real(gz) + half, s_in, bint, body, planes,
                  grid, block_map, flags0, owner, f, bforce, btorque, nlinks, flags, film, nowned)

    @dev
    def links(k, gx, gy, gz, bint, body, planes, grid, block_map, flags0, owner, f, bforce, btorque, nlinks, flags,
              film, nowned):
        s_in = sdf_at(k, real(gx) + half, real(gy) + half, real(gz) + half, body, bint, planes, grid)
        links_at(k, gx, gy, gz, s_in, bint, body, planes, grid, block_map, flags0, owner, f, bforce, btorque, nlinks,
                 flags, film, nowned)

    @dev
    def links_fs_at(k, gx, gy, gz, s_in, bint, body, planes, grid, block_map, flags0, owner, f, bforce, btorque,
                    nlinks, flags, film, nowned, phi):
        """``links_at`` with the phase field's mirror (:func:`iceresist.coupling.surface_kernels.build_mirror`) in
        the same visit of each covered cell: one walk over the body's cell box instead of two."""
        b, c = lookup(gx, gy, gz, grid, block_map)
        if b < 0:
            return
        if owner[b, c] != k:
            return
        yx, yy, yz = real(gx) + half, real(gy) + half, real(gz) + half
        if s_in >= -mdepth:
            mirror(k, b, c, yx, yy, yz, s_in, body, bint, planes, grid, block_map, flags0, owner, phi)
        if s_in <= -fdepth:
            return
        link_cell(k, gx, gy, gz, b, c, yx, yy, yz, s_in, bint, body, planes, grid, block_map, flags0, owner, f,
                  bforce, btorque, nlinks, flags, film, nowned)

    @dev
    def links_fs(k, gx, gy, gz, bint, body, planes, grid, block_map, flags0, owner, f, bforce, btorque, nlinks,
                 flags, film, nowned, phi):
        s_in = sdf_at(k, real(gx) + half, real(gy) + half, real(gz) + half, body, bint, planes, grid)
        links_fs_at(k, gx, gy, gz, s_in, bint, body, planes, grid, block_map, flags0, owner, f, bforce, btorque,
                    nlinks, flags, film, nowned, phi)

    @dev
    def link_cell(k, gx, gy, gz, b, c, yx, yy, yz, s_in, bint, body, planes, grid, block_map, flags0, owner, f,
                  bforce, btorque, nlinks, flags, film, nowned):
        """The links of covered cell (b, c) of row k at (gx, gy, gz), centre (yx, yy, yz), signed distance s_in."""
        # forces from the forest's first ``nowned`` blocks only (an MPI rank's own; its halo's are another rank's)
        mine = b < nowned
        near = film[0] != zero
        nfilm = 0
        kb = bint[k, 9]
        lcx = c & 7
        lcy = (c >> 3) & 7
        lcz = c >> 6
        for q in range(1, nq):
            hx, hy, hz = gx + CXI[q], gy + CYI[q], gz + CZI[q]
            ax, ay, az = lcx + CXI[q], lcy + CYI[q], lcz + CZI[q]
            if ax >= 0 and ax < 8 and ay >= 0 and ay < 8 and az >= 0 and az < 8:
                xb, xc = b, ax + 8 * (ay + 8 * az)      # in the cell's own block: no look-up in the forest
            else:
                xb, xc = lookup(hx, hy, hz, grid, block_map)
            if xb >= 0:
                o = owner[xb, xc]
                if o >= 0:
                    if bint[o, 9] == kb:
                        continue    # the same body (any of its rows): no link and no film (the common case)
            if not liquid(xb, xc, flags0, owner, flags):
                if near:
                    if touches(k, hx, hy, hz, xb, xc, bint, grid, flags0, owner):
                        nfilm += 1
                continue
            cx, cy, cz = CXR[q], CYR[q], CZR[q]
            px, py, pz = yx + cx, yy + cy, yz + cz
            # link distance: where x - t c_q, t in [0, 1], enters the body, in closed form (at most 0 where the
            # fluid cell's centre is inside the body by round-off: q_d = Q_MIN); where round-off leaves none (t < 0),
            # Q_MIN if that centre is inside, else the root of the SDF (Illinois regula falsi)
            t = link_root(k, px, py, pz, cx, cy, cz, body, bint, planes, grid)
            if t < zero:
                t0, s0 = zero, sdf_at(k, px, py, pz, body, bint, planes, grid)
                t1, s1 = one, s_in
                if s0 <= zero:
                    t = qmin
                else:
                    for _ in range(niter):
                        t = (t0 * s1 - t1 * s0) / (s1 - s0)
                        st = sdf_at(k, px - t * cx, py - t * cy, pz - t * cz, body, bint, planes, grid)
                        if st > zero:
                            t0, s0 = t, st
                            s1 = s1 * half
                        else:
                            t1, s1 = t, st
                            s0 = s0 * half
                    t = (t0 * s1 - t1 * s0) / (s1 - s0)
            qd = min(max(t, qmin), one)
            ux, uy, uz, rx, ry, rz = wall_velocity(k, px - qd * cx, py - qd * cy, pz - qd * cz, body, grid)
            o = OPPI[q]
            gopp = f[xb, o, xc]
            mom = six * WR[q] * (cx * ux + cy * uy + cz * uz)
            if qd <= half:
                x2b, x2c = lookup(gx + 2 * CXI[q], gy + 2 * CYI[q], gz + 2 * CZI[q], grid, block_map)
                if liquid(x2b, x2c, flags0, owner, flags):
                    fnew = two * qd * gopp + (one - two * qd) * f[x2b, o, x2c] + mom
                else:
                    fnew = gopp + mom
            else:
                inv = one / (two * qd)
                fnew = inv * (gopp + mom) + (one - inv) * f[xb, q, xc]
            f[b, q, c] = fnew
            # eq. (17): (c_opp - u_w) f*_opp(x) - (c_q - u_w) f_q(x, t+1), reference pressure left out
            s = gopp + fnew
            d = gopp - fnew
            Fx = -cx * s - ux * d
            Fy = -cy * s - uy * d
            Fz = -cz * s - uz * d
            if mine:
                add_load(bforce, btorque, k, Fx, Fy, Fz, rx, ry, rz)
                accumulate(nlinks, k, 0, 1)
        if nfilm == 0 or not mine:
            return
        gauge = film_density(gx, gy, gz, grid, block_map, flags0, owner, f, flags, film) - one
        if gauge == zero:
            return
        for q in range(1, nq):
            hx, hy, hz = gx + CXI[q], gy + CYI[q], gz + CZI[q]
            xb, xc = lookup(hx, hy, hz, grid, block_map)
            if not touches(k, hx, hy, hz, xb, xc, bint, grid, flags0, owner):
                continue
            cx, cy, cz = CXR[q], CYR[q], CZR[q]
            ux, uy, uz, rx, ry, rz = wall_velocity(k, yx + half * cx, yy + half * cy, yz + half * cz, body, grid)
            p = -two * WR[q] * gauge
            Fx = p * cx
            Fy = p * cy
            Fz = p * cz
            add_load(bforce, btorque, k, Fx, Fy, Fz, rx, ry, rz)

    @dev
    def classify_refill(b, c, borigin, body, grid, block_map, flags0, flags, owner, owner_prev, f, block_evt,
                        Fx, Fy, Fz):
        k = owner[b, c]
        if k >= 0:
            flags[b, c] = ghost
            if owner_prev[b, c] < 0:
                block_evt[b] = 1
            return
        fl = flags0[b, c]
        flags[b, c] = fl
        kp = owner_prev[b, c]
        if kp < 0 or (fl & fluid) == 0:
            return
        block_evt[b] = 1
        gx = borigin[b, 0] * 8 + (c & 7)
        gy = borigin[b, 1] * 8 + ((c >> 3) & 7)
        gz = borigin[b, 2] * 8 + (c >> 6)
        ux, uy, uz, rx, ry, rz = wall_velocity(kp, real(gx) + half, real(gy) + half, real(gz) + half, body, grid)
        for p in range(nq):
            f[b, p, c] = zero
        wsum = zero
        rsum = zero
        for q in range(1, nq):
            nb, nc = lookup(gx + CXI[q], gy + CYI[q], gz + CZI[q], grid, block_map)
            if nb < 0:
                continue
            if not stable(nb, nc, flags0, owner, owner_prev):
                continue
            w = WR[q]
            rho = add_nonequilibrium(f, b, c, nb, nc, w)
            wsum += w
            rsum += w * rho
        rho = one
        inv = zero
        if wsum > zero:
            rho = rsum / wsum
            inv = one / wsum
        vx = ux + half * Fx / rho        # stored populations carry u + F / (2 rho)
        vy = uy + half * Fy / rho
        vz = uz + half * Fz / rho
        uu = vx * vx + vy * vy + vz * vz
        for p in range(nq):
            cu = CXR[p] * vx + CYR[p] * vy + CZR[p] * vz
            f[b, p, c] = f[b, p, c] * inv + WR[p] * ((rho - one) + rho * (three * cu + c45 * cu * cu - c15 * uu))

    @dev
    def redistribute(b, c, near, borigin, grid, block_map, flags0, owner, owner_prev, f):
        if (reach_mask(c) & near[b]) == 0:   # no neighbour in a block with an event
            return
        if not stable(b, c, flags0, owner, owner_prev):
            return
        gx = borigin[b, 0] * 8 + (c & 7)
        gy = borigin[b, 1] * 8 + ((c >> 3) & 7)
        gz = borigin[b, 2] * 8 + (c >> 6)
        acc = zero
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
            excess = zero
            for p in range(nq):
                excess += f[yb, p, yc]
            if not now:
                excess = -excess
            wy = zero
            for p in range(1, nq):
                zb, zc = lookup(hx + CXI[p], hy + CYI[p], hz + CZI[p], grid, block_map)
                if zb >= 0:
                    if stable(zb, zc, flags0, owner, owner_prev):
                        wy += WR[p]
            acc += excess * WR[q] / wy
        f[b, 0, c] += acc

    @dev
    def poison(b, c, flags0, owner, owner_prev, f):
        if owner[b, c] >= 0 and owner_prev[b, c] < 0 and (flags0[b, c] & fluid) != 0:
            for p in range(nq):
                f[b, p, c] = nan

    return (mark, (links_fs if fs else links), classify_refill, redistribute, poison,
            (links_fs_at if fs else links_at))


#: Modules whose source decides the compiled coupling code (visits, geometry, lattice constants, flags); the key
#: of the kernel cache.
KEY_MODULES = ("iceresist.coupling.kernels", "iceresist.coupling.runs", "iceresist.coupling.surface_kernels",
               "iceresist.coupling.cellfunctions", "iceresist.coupling.bodystate", "iceresist.coupling.geometry",
               "iceresist.grid.flags", "iceresist.lattice", "iceresist.lbm.boundary", "iceresist.freesurface.hlattice")


def build_link_list(target, real, links_at, free_surface: bool):
    """CUDA: ``(mark_listed, links_listed)``, the ``mark`` visit that also lists the covered cells the links pass acts
    on, and the links pass over that list (one thread per listed cell instead of a walk over every cell of each
    body's box, where most threads of a warp found nothing to do).

    * ``mark_listed(k, gx, gy, gz, *MARK_ARGS, *LIST_ARGS)``: ``mark``; a cell it covers at a signed distance the
      links pass acts on (above -FILM_DEPTH, or with a free surface at least -MIRROR_DEPTH for the mirror) takes
      the next place of the list (an atomic count, so the order of the list is not fixed; a cell is listed once
      per row of its body that visits it, as the box walk visits it);
    * ``links_listed(i, stride, ncells, cells, svals, *LINK_ARGS[, phi])``: ``links_at`` of the listed cells i,
      i + stride, ... (a thread of ``stride`` threads) with their stored signed distances (the bodies have not moved
      since ``mark``); the launch's threads are fixed, not the list's length, which the host does not read.

    A cell beyond the list's length is counted in ``ncells[1]`` and not listed: the coupling sizes the list so
    that this cannot happen and reports it if it does (:meth:`FluidStructureCoupling.check_link_list`)."""
    lookup, sdf_at, _ = build_geometry_functions(target, real)
    ns = {"cuda": jit_cuda_api()}   # a global of the function, so that the simulator can swap it
    exec("def claim(a, j):\n    return cuda.atomic.add(a, j, 1)\n", ns)
    claim = target.device(ns["claim"])
    zero, half = real(0.0), real(0.5)
    fdepth, mdepth = real(FILM_DEPTH), real(MIRROR_DEPTH)
    fluid = FL.FLUID
    fs = bool(free_surface)
    int32, int64 = np.int32, np.int64
    dev = target.device

    @dev
    def mark_listed(k, gx, gy, gz, bint, body, planes, grid, block_map, flags0, owner, cells, svals, ncells):
        b, c = lookup(gx, gy, gz, grid, block_map)
        if b < 0:
            return
        if (flags0[b, c] & fluid) == 0:
            return
        s = sdf_at(k, real(gx) + half, real(gy) + half, real(gz) + half, body, bint, planes, grid)
        if s >= zero:
            return
        owner[b, c] = k
        if s > -fdepth or (fs and s >= -mdepth):
            i = claim(ncells, 0)
            if i < cells.shape[0]:
                nx = int64(bint[k, 6]) - bint[k, 3] + 1
                ny = int64(bint[k, 7]) - bint[k, 4] + 1
                cells[i, 0] = int32(k)
                cells[i, 1] = int32((gx - bint[k, 3]) + nx * ((gy - bint[k, 4]) + ny * (gz - bint[k, 5])))
                svals[i] = s
            else:
                claim(ncells, 1)

    @dev
    def listed(i, cells, bint):
        """(row, gx, gy, gz) of listed cell i."""
        k = int64(cells[i, 0])
        j = int64(cells[i, 1])
        nx = int64(bint[k, 6]) - bint[k, 3] + 1
        ny = int64(bint[k, 7]) - bint[k, 4] + 1
        return k, bint[k, 3] + j % nx, bint[k, 4] + (j // nx) % ny, bint[k, 5] + j // (nx * ny)

    if fs:
        @dev
        def links_listed(i, stride, ncells, cells, svals, bint, body, planes, grid, block_map, flags0, owner, f,
                         bforce, btorque, nlinks, flags, film, nowned, phi):
            for e in range(i, min(int64(ncells[0]), int64(cells.shape[0])), stride):
                k, gx, gy, gz = listed(e, cells, bint)
                links_at(k, gx, gy, gz, svals[e], bint, body, planes, grid, block_map, flags0, owner, f, bforce,
                         btorque, nlinks, flags, film, nowned, phi)
    else:
        @dev
        def links_listed(i, stride, ncells, cells, svals, bint, body, planes, grid, block_map, flags0, owner, f,
                         bforce, btorque, nlinks, flags, film, nowned):
            for e in range(i, min(int64(ncells[0]), int64(cells.shape[0])), stride):
                k, gx, gy, gz = listed(e, cells, bint)
                links_at(k, gx, gy, gz, svals[e], bint, body, planes, grid, block_map, flags0, owner, f, bforce,
                         btorque, nlinks, flags, film, nowned)

    return mark_listed, links_listed


def variant_of(real, h_lattice=None, free_surface: bool = False) -> str:
    """The key of a launcher family: precision, free-surface flag and h lattice."""
    return f"{np.dtype(real).name}|fs={bool(free_surface)}|{None if h_lattice is None else h_lattice.name}"


_CACHE: dict = {}


def coupling_launchers(target, real, h_lattice=None):
    """Compiled launchers ``mark, links, refill, redistribute, poison`` (cached per target and precision); with
    the h lattice of a free surface (``h_lattice``, an :class:`~iceresist.freesurface.hlattice.HLattice`) the
    free-surface variants ``links`` (which also mirrors phi, taking it last), ``refill`` and ``redistribute``
    (:mod:`iceresist.coupling.surface_kernels`)."""
    key = (target.name, target.simulator, np.dtype(real).name, None if h_lattice is None else h_lattice.name)
    if key not in _CACHE:
        fs = h_lattice is not None
        k = None if target.is_cuda else cache.fingerprint(variant_of(real, h_lattice, fs), KEY_MODULES)
        mark, links, refill, redist, poison, links_at = build_visits(target, real, free_surface=fs)
        link_args = LINK_FS_ARGS if fs else LINK_ARGS
        if target.is_cuda:     # mark lists the cells the links pass visits (build_link_list)
            mark_listed, links_listed = build_link_list(target, real, links_at, fs)
            launchers = {"mark": BodyLauncher(target, mark_listed, MARK_ARGS + LIST_ARGS, label="mark"),
                         "links": ItemLauncher(target, links_listed, ("stride", "ncells", "cells", "svals") + link_args,
                                               label="links")}
        else:
            launchers = {"mark": BodyLauncher(target, build_mark_run(real, MARK_ARGS), MARK_ARGS, per_row=True,
                                              label="mark", cache_key=k),
                         "links": BodyLauncher(target, build_link_run(real, links_at, link_args, LINK_DEPTH),
                                               link_args, per_row=True, label="links", cache_key=k)}
        launchers["poison"] = ActiveLauncher(target, poison, POISON_ARGS, label="poison", cache_key=k)
        if not fs:
            launchers["refill"] = ActiveLauncher(target, refill, REFILL_ARGS, label="refill", cache_key=k)
            launchers["redistribute"] = ActiveLauncher(target, redist, REDIST_ARGS, label="redistribute",
                                                       cache_key=k)
        else:
            refill_fs, redist_fs = build_surface_visits(target, real, h_lattice)
            launchers["refill"] = ActiveLauncher(target, refill_fs, REFILL_FS_ARGS, label="refill_fs", cache_key=k)
            if target.is_cuda:
                launchers["redistribute"] = ActiveLauncher(target, redist_fs, REDIST_FS_ARGS,
                                                           label="redistribute_fs")
            else:       # the block form: only the cells next to an event visited
                launchers["redistribute"] = ActiveLauncher(target, build_redistribute_block(real, h_lattice),
                                                           REDIST_FS_ARGS, per_block=True, label="redistribute_fs",
                                                           cache_key=k)
        _CACHE[key] = launchers
    return _CACHE[key]
