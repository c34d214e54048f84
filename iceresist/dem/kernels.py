"""DEM kernels written once as scalar per-item device functions, launched per sphere or per body.

One sub-step of length h (velocity Verlet for the translation, leapfrog in angular momentum with the
DLM free rotor of :mod:`iceresist.dem.quaternion` for the rotation; paper eqs. 13-15):

1. ``drift`` (per body): v += h/2 F / (m + m_a), L += h/2 T, x += h v, free rotor over h, omega = R I^-1 R^T L;
   a kinematic body moves with its prescribed velocity and angular velocity instead;
2. ``place`` (per sphere): world centre of each sphere and its cell-hash bucket (on CUDA also counted into the
   bucket's tally, the grid sort's first pass);
3. grid sort (:mod:`iceresist.dem.search`);
4. ``contact`` (per sphere): gathers the contact forces on itself from the 27 neighbour cells and the walls,
   re-matches the tangential history by partner id, writes force, torque about its body's centre of mass
   and elastic energy; the pair is always evaluated from the lower sphere index so both partners compute
   bitwise the same force (Newton's third law holds exactly);
5. ``gather`` (per body): sums its spheres' forces and torques (gather, no scatter), adds gravity, the held
   external force/torque (F_fluid, M_fluid) and tier-1 hydrodynamics, and kicks v and L by the second half step
   (on CUDA a thread block per body sums its spheres, :func:`build_gather_cuda`).

The CPU launcher runs the item in a ``prange`` loop; the CUDA launcher gives each item one thread.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

from iceresist.backends import cache
from iceresist.backends.jit import cuda_api
from iceresist.backends.launch import ItemLauncher, build_block_sum6, cuda_launch, profiled
from iceresist.dem.contact import build_contact_force
from iceresist.dem.hydro import build_hydro_force
from iceresist.dem.quaternion import build_quaternion
from iceresist.dem.search import build_cell_hash, build_cell_index, build_grid_sort, build_tally

cuda = cuda_api()  # cuda.blockIdx / cuda.threadIdx in the CUDA gather (a module global, for the simulator)

DRIFT_ARGS = ["h", "pos", "vel", "vpred", "quat", "angmom", "omega", "inertia", "inv_meff", "kin", "pvel",
              "pomega", "force", "torque"]
PLACE_ARGS = ["soff", "sbody", "pos", "quat", "xs", "key", "inv_cell", "mask", "tally"]
CONTACT_ARGS = ["xs", "srad", "sbody", "pos", "vpred", "omega", "inv_mdamp", "kin", "mat", "start", "count",
                "order", "mask", "inv_cell", "walls", "n_walls", "params", "h",
                "hp_old", "hxi_old", "hn_old", "hp_new", "hxi_new", "hn_new", "sforce", "storque", "senergy",
                "snew", "sover"]
# (CPython passes calls with more than 30 arguments as *args, which numba cannot inline: keep lists short)
#: Modules whose source decides the compiled DEM code (device functions, constants); the key of the kernel cache.
KEY_MODULES = ("iceresist.dem.kernels", "iceresist.dem.contact", "iceresist.dem.hydro", "iceresist.dem.quaternion",
               "iceresist.dem.search")
GATHER_ARGS = ["h", "do_kick", "bfirst", "bcount", "sforce", "storque", "mass", "kin", "ext", "env", "pos",
               "quat", "vel", "omega", "angmom", "volume", "blen", "bhalf", "vfirst", "vcount", "voff", "vvol",
               "bcontact", "bcsum", "force", "torque", "inv_meff"]
COUNT_ARGS = ["hp", "hn", "scount"]


def build_items(target, real):
    """Per-item device functions ``drift``, ``place``, ``contact``, ``gather``, ``count`` for a target and
    precision."""
    zero, half, one = real(0), real(0.5), real(1)
    sqrt = math.sqrt
    rotate, rotate_inv, mul, free_rotor, spin_world, omega_world = build_quaternion(target, real)
    contact_force = build_contact_force(target, real)
    hydro_force = build_hydro_force(target, real, rotate)
    cell_hash = build_cell_hash(target)
    cell_index = build_cell_index(target)
    tally_sphere = build_tally(target)

    @target.device
    def drift(b, h, pos, vel, vpred, quat, angmom, omega, inertia, inv_meff, kin, pvel, pomega, force, torque):
        """Half kick, drift and free rotor; ``vpred``/``omega`` get the velocities predicted at the end of the
        sub-step (half-step value plus h/2 of the last force), which the dashpot and friction use."""
        qw = quat[b, 0]
        qx = quat[b, 1]
        qy = quat[b, 2]
        qz = quat[b, 3]
        if kin[b] != 0:
            for k in range(3):
                vel[b, k] = pvel[b, k]
                vpred[b, k] = pvel[b, k]
                omega[b, k] = pomega[b, k]
                pos[b, k] += h * pvel[b, k]
            qw, qx, qy, qz = spin_world(qw, qx, qy, qz, pomega[b, 0], pomega[b, 1], pomega[b, 2], h)
        else:
            hh = half * h
            im = inv_meff[b]
            for k in range(3):
                vel[b, k] += hh * im * force[b, k]
                angmom[b, k] += hh * torque[b, k]
                pos[b, k] += h * vel[b, k]
                vpred[b, k] = vel[b, k] + hh * im * force[b, k]
            Lx = angmom[b, 0]
            Ly = angmom[b, 1]
            Lz = angmom[b, 2]
            i0 = inertia[b, 0]
            i1 = inertia[b, 1]
            i2 = inertia[b, 2]
            qw, qx, qy, qz = free_rotor(qw, qx, qy, qz, Lx, Ly, Lz, i0, i1, i2, h)
            wx, wy, wz = omega_world(qw, qx, qy, qz, Lx + hh * torque[b, 0], Ly + hh * torque[b, 1],
                                     Lz + hh * torque[b, 2], i0, i1, i2)
            omega[b, 0] = wx
            omega[b, 1] = wy
            omega[b, 2] = wz
        quat[b, 0] = qw
        quat[b, 1] = qx
        quat[b, 2] = qy
        quat[b, 3] = qz

    @target.device
    def place(i, soff, sbody, pos, quat, xs, key, inv_cell, mask, tally):
        b = sbody[i]
        rx, ry, rz = rotate(quat[b, 0], quat[b, 1], quat[b, 2], quat[b, 3], soff[i, 0], soff[i, 1], soff[i, 2])
        x = pos[b, 0] + rx
        y = pos[b, 1] + ry
        z = pos[b, 2] + rz
        xs[i, 0] = x
        xs[i, 1] = y
        xs[i, 2] = z
        k = cell_hash(cell_index(x, inv_cell), cell_index(y, inv_cell), cell_index(z, inv_cell), mask)
        key[i] = k
        tally_sphere(tally, k)

    @target.device
    def point_velocity(b, pos, vel, omega, px, py, pz):
        rx = px - pos[b, 0]
        ry = py - pos[b, 1]
        rz = pz - pos[b, 2]
        return (vel[b, 0] + omega[b, 1] * rz - omega[b, 2] * ry,
                vel[b, 1] + omega[b, 2] * rx - omega[b, 0] * rz,
                vel[b, 2] + omega[b, 0] * ry - omega[b, 1] * rx)

    @target.device
    def find_old(i, partner, hp_old, hxi_old, hn_old):
        for k in range(hn_old[i]):
            if hp_old[i, k] == partner:
                return (hxi_old[i, k, 0], hxi_old[i, k, 1], hxi_old[i, k, 2], 1)
        return (zero, zero, zero, 0)

    @target.device
    def contact(i, xs, srad, sbody, pos, vel, omega, inv_mdamp, kin, mat, start, count, order, mask, inv_cell,
                walls, n_walls, params, h, hp_old, hxi_old, hn_old, hp_new, hxi_new, hn_new, sforce, storque,
                senergy, snew, sover):
        bi = sbody[i]
        kin_i = kin[bi]
        xi = xs[i, 0]
        yi = xs[i, 1]
        zi = xs[i, 2]
        ri = srad[i]
        cx = cell_index(xi, inv_cell)
        cy = cell_index(yi, inv_cell)
        cz = cell_index(zi, inv_cell)
        cap = hp_new.shape[1]
        nn = 0
        fx = zero
        fy = zero
        fz = zero
        tx = zero
        ty = zero
        tz = zero
        en = zero
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    ccx = cx + dx
                    ccy = cy + dy
                    ccz = cz + dz
                    bucket = cell_hash(ccx, ccy, ccz, mask)
                    s0 = start[bucket]
                    for t in range(s0, s0 + count[bucket]):
                        j = order[t]
                        bj = sbody[j]
                        if bj == bi or (kin_i != 0 and kin[bj] != 0):
                            continue
                        xj = xs[j, 0]
                        yj = xs[j, 1]
                        zj = xs[j, 2]
                        if cell_index(xj, inv_cell) != ccx or cell_index(yj, inv_cell) != ccy or cell_index(zj, inv_cell) != ccz:
                            continue
                        rsum = ri + srad[j]
                        ex = xj - xi
                        ey = yj - yi
                        ez = zj - zi
                        d2 = ex * ex + ey * ey + ez * ez
                        if d2 >= rsum * rsum:
                            continue
                        # evaluate the pair from the lower index a toward b
                        if i < j:
                            sgn = one
                            ba = bi
                            bb = bj
                            xa = xi
                            ya = yi
                            za = zi
                            ra = ri
                        else:
                            sgn = -one
                            ba = bj
                            bb = bi
                            xa = xj
                            ya = yj
                            za = zj
                            ra = srad[j]
                            ex = -ex
                            ey = -ey
                            ez = -ez
                        d = sqrt(d2)
                        nx = ex / d
                        ny = ey / d
                        nz = ez / d
                        delta = rsum - d
                        arm = ra - half * delta
                        pcx = xa + arm * nx
                        pcy = ya + arm * ny
                        pcz = za + arm * nz
                        vax, vay, vaz = point_velocity(ba, pos, vel, omega, pcx, pcy, pcz)
                        vbx, vby, vbz = point_velocity(bb, pos, vel, omega, pcx, pcy, pcz)
                        m_eff = one / (inv_mdamp[ba] + inv_mdamp[bb])   # the dashpot's effective mass
                        p = 0 if (mat[ba] == 0 and mat[bb] == 0) else 1
                        ox, oy, oz, found = find_old(i, j, hp_old, hxi_old, hn_old)
                        Fx, Fy, Fz, nxx, nxy, nxz, e = contact_force(
                            nx, ny, nz, delta, vax - vbx, vay - vby, vaz - vbz, m_eff, ox, oy, oz,
                            params[p, 0], params[p, 1], params[p, 2], params[p, 3], h)
                        if found == 0 and i < j:
                            snew[i] += 1
                        if nn < cap:
                            hp_new[i, nn] = j
                            hxi_new[i, nn, 0] = nxx
                            hxi_new[i, nn, 1] = nxy
                            hxi_new[i, nn, 2] = nxz
                            nn += 1
                        else:
                            sover[i] += 1
                        Fx *= sgn
                        Fy *= sgn
                        Fz *= sgn
                        lx = pcx - pos[bi, 0]
                        ly = pcy - pos[bi, 1]
                        lz = pcz - pos[bi, 2]
                        fx += Fx
                        fy += Fy
                        fz += Fz
                        tx += ly * Fz - lz * Fy
                        ty += lz * Fx - lx * Fz
                        tz += lx * Fy - ly * Fx
                        en += half * e
        if kin_i == 0:
            for w in range(n_walls):
                nwx = walls[w, 3]
                nwy = walls[w, 4]
                nwz = walls[w, 5]
                dist = (xi - walls[w, 0]) * nwx + (yi - walls[w, 1]) * nwy + (zi - walls[w, 2]) * nwz
                delta = ri - dist
                if delta <= zero:
                    continue
                arm = ri - half * delta
                pcx = xi - arm * nwx
                pcy = yi - arm * nwy
                pcz = zi - arm * nwz
                vax, vay, vaz = point_velocity(bi, pos, vel, omega, pcx, pcy, pcz)
                ox, oy, oz, found = find_old(i, -1 - w, hp_old, hxi_old, hn_old)
                Fx, Fy, Fz, nxx, nxy, nxz, e = contact_force(
                    -nwx, -nwy, -nwz, delta, vax, vay, vaz, one / inv_mdamp[bi], ox, oy, oz,
                    params[1, 0], params[1, 1], params[1, 2], params[1, 3], h)
                if found == 0:
                    snew[i] += 1
                if nn < cap:
                    hp_new[i, nn] = -1 - w
                    hxi_new[i, nn, 0] = nxx
                    hxi_new[i, nn, 1] = nxy
                    hxi_new[i, nn, 2] = nxz
                    nn += 1
                else:
                    sover[i] += 1
                lx = pcx - pos[bi, 0]
                ly = pcy - pos[bi, 1]
                lz = pcz - pos[bi, 2]
                fx += Fx
                fy += Fy
                fz += Fz
                tx += ly * Fz - lz * Fy
                ty += lz * Fx - lx * Fz
                tz += lx * Fy - ly * Fx
                en += e
        hn_new[i] = nn
        sforce[i, 0] = fx
        sforce[i, 1] = fy
        sforce[i, 2] = fz
        storque[i, 0] = tx
        storque[i, 1] = ty
        storque[i, 2] = tz
        senergy[i] = en

    @target.device
    def sphere_sum(a, s0, s1):
        """(sum of a[s, 0], a[s, 1], a[s, 2] over s0 <= s < s1) in four interleaved partial sums: a body of many
        spheres (the hull's thousands) is summed by one thread, and four independent sums keep four rows' loads in
        flight at once instead of one after the other (on a GPU each waits a memory latency)."""
        x0 = zero
        y0 = zero
        z0 = zero
        x1 = zero
        y1 = zero
        z1 = zero
        x2 = zero
        y2 = zero
        z2 = zero
        x3 = zero
        y3 = zero
        z3 = zero
        s = s0
        while s + 4 <= s1:
            x0 += a[s, 0]
            y0 += a[s, 1]
            z0 += a[s, 2]
            x1 += a[s + 1, 0]
            y1 += a[s + 1, 1]
            z1 += a[s + 1, 2]
            x2 += a[s + 2, 0]
            y2 += a[s + 2, 1]
            z2 += a[s + 2, 2]
            x3 += a[s + 3, 0]
            y3 += a[s + 3, 1]
            z3 += a[s + 3, 2]
            s += 4
        while s < s1:
            x0 += a[s, 0]
            y0 += a[s, 1]
            z0 += a[s, 2]
            s += 1
        return (x0 + x1) + (x2 + x3), (y0 + y1) + (y2 + y3), (z0 + z1) + (z2 + z3)

    @target.device
    def gather(b, h, do_kick, bfirst, bcount, sforce, storque, mass, kin, ext, env, pos, quat, vel, omega, angmom,
               volume, blen, bhalf, vfirst, vcount, voff, vvol, bcontact, bcsum, force, torque, inv_meff):
        """ext[b] = (F_fluid, M_fluid); env = (water level, rho_w, C_d, C_a, water on, g_x, g_y, g_z);
        bcontact[b] = (contact force, contact torque); a kicking call (a sub-step) adds bcontact[b] to bcsum[b]."""
        fx, fy, fz = sphere_sum(sforce, bfirst[b], bfirst[b] + bcount[b])
        tx, ty, tz = sphere_sum(storque, bfirst[b], bfirst[b] + bcount[b])
        body_loads(b, fx, fy, fz, tx, ty, tz, h, do_kick, mass, kin, ext, env, pos, quat, vel, omega, angmom, volume,
                   blen, bhalf, vfirst, vcount, voff, vvol, bcontact, bcsum, force, torque, inv_meff)

    @target.device
    def body_loads(b, fx, fy, fz, tx, ty, tz, h, do_kick, mass, kin, ext, env, pos, quat, vel, omega, angmom, volume,
                   blen, bhalf, vfirst, vcount, voff, vvol, bcontact, bcsum, force, torque, inv_meff):
        """``gather`` of body b once its spheres' contact force (fx, fy, fz) and torque (tx, ty, tz) are summed."""
        bcontact[b, 0] = fx
        bcontact[b, 1] = fy
        bcontact[b, 2] = fz
        bcontact[b, 3] = tx
        bcontact[b, 4] = ty
        bcontact[b, 5] = tz
        if do_kick != 0:
            bcsum[b, 0] += fx
            bcsum[b, 1] += fy
            bcsum[b, 2] += fz
            bcsum[b, 3] += tx
            bcsum[b, 4] += ty
            bcsum[b, 5] += tz
        if kin[b] == 0:
            m = mass[b]
            fx += m * env[5] + ext[b, 0]
            fy += m * env[6] + ext[b, 1]
            fz += m * env[7] + ext[b, 2]
            tx += ext[b, 3]
            ty += ext[b, 4]
            tz += ext[b, 5]
            madd = zero
            if env[4] > zero:
                hfx, hfy, hfz, htx, hty, htz, madd = hydro_force(b, pos, quat, vel, omega, volume, blen, bhalf, vfirst,
                                                                  vcount, voff, vvol, env)
                fx += hfx
                fy += hfy
                fz += hfz
                tx += htx
                ty += hty
                tz += htz
            force[b, 0] = fx
            force[b, 1] = fy
            force[b, 2] = fz
            torque[b, 0] = tx
            torque[b, 1] = ty
            torque[b, 2] = tz
            im = one / (m + madd)
            inv_meff[b] = im
            if do_kick != 0:
                hh = half * h
                vel[b, 0] += hh * im * fx
                vel[b, 1] += hh * im * fy
                vel[b, 2] += hh * im * fz
                angmom[b, 0] += hh * tx
                angmom[b, 1] += hh * ty
                angmom[b, 2] += hh * tz

    @target.device
    def count(i, hp, hn, scount):
        """scount[i] = the contacts of sphere i in its history slots, a sphere partner once and a wall twice (the
        sum over the spheres is then twice the contacts: each pair is seen from both spheres)."""
        n = 0
        for k in range(min(hn[i], hp.shape[1])):
            n += 1 if hp[i, k] >= 0 else 2
        scount[i] = n

    return drift, place, contact, gather, count, body_loads


#: Threads of the CUDA gather's thread block per body (:func:`build_gather_cuda`).
GATHER_THREADS = 64


def build_gather_cuda(target, real, body_loads):
    """CUDA: the launch ``gather(n, *GATHER_ARGS)`` with one thread block of :data:`GATHER_THREADS` threads per
    body: the threads sum strided runs of the body's spheres, a shared-memory tree adds their sums (in a fixed
    order: the same sums on every run), and thread 0 finishes the body (``body_loads``). The hull's thousands of
    spheres are then summed by 64 threads, not one."""
    block_sum6 = build_block_sum6(real, GATHER_THREADS)
    zero = real(0)
    nt = GATHER_THREADS

    def dem_gather(n, h, do_kick, bfirst, bcount, sforce, storque, mass, kin, ext, env, pos, quat, vel, omega,
                   angmom, volume, blen, bhalf, vfirst, vcount, voff, vvol, bcontact, bcsum, force, torque, inv_meff):
        b = cuda.blockIdx.x
        t = cuda.threadIdx.x
        s0 = bfirst[b]
        fx = zero
        fy = zero
        fz = zero
        tx = zero
        ty = zero
        tz = zero
        for s in range(s0 + t, s0 + bcount[b], nt):
            fx += sforce[s, 0]
            fy += sforce[s, 1]
            fz += sforce[s, 2]
            tx += storque[s, 0]
            ty += storque[s, 1]
            tz += storque[s, 2]
        fx, fy, fz, tx, ty, tz = block_sum6(t, fx, fy, fz, tx, ty, tz)
        if t == 0:
            body_loads(b, fx, fy, fz, tx, ty, tz, h, do_kick, mass, kin, ext, env, pos, quat, vel, omega, angmom,
                       volume, blen, bhalf, vfirst, vcount, voff, vvol, bcontact, bcsum, force, torque, inv_meff)

    kern = target.kernel(dem_gather, threads=nt)

    def launch(n, *args):
        cuda_launch(kern, int(n), nt, np.int64(n), *args)

    return profiled("dem_gather", launch)


#: CPU launches with fewer items than this run on one thread, per launcher. A launch on all threads waits
#: for every worker: on a 2-core x86 VM shared with other work that wait was about 12-15 ms per launch, while
#: placing 10k spheres takes 0.2 ms and their contacts about 6 ms on one thread, so the cheap per-body and
#: per-sphere passes stay on one thread at any realistic size, and the contact pass uses all threads only where
#: its one-thread time (about 0.6 us per sphere) clearly exceeds two such waits.
PARALLEL_FROM = {"drift": 1 << 20, "place": 1 << 20, "gather": 1 << 20, "contact": 1 << 15, "count": 1 << 20}


def use_parallel(kind: str, n: int) -> bool:
    """Whether a CPU launch of ``n`` items of ``kind`` runs on all numba threads (else on one)."""
    return n >= PARALLEL_FROM[kind]


def build_launchers(target, real):
    """Return a dict of launchers ``drift``, ``place``, ``contact``, ``gather``, ``count`` and ``sort`` (grid).

    Each item runs over bodies or spheres (:class:`~iceresist.backends.launch.ItemLauncher`, labelled
    ``dem_<kind>``); on the CPU one prange kernel serves every launch and, below ``PARALLEL_FROM[kind]`` items,
    runs with one thread (no wait for the workers; the prange build ran the contact pass about 1.5x faster on one
    thread than a plain ``range`` loop did). It compiles on its first call, from the on-disk kernel cache
    (:mod:`iceresist.backends.cache`) where that is on."""
    *fns, body_loads = build_items(target, real)
    items = dict(zip(("drift", "place", "contact", "gather", "count"), fns))
    args = {"drift": DRIFT_ARGS, "place": PLACE_ARGS, "contact": CONTACT_ARGS, "gather": GATHER_ARGS,
            "count": COUNT_ARGS}
    key = None if target.is_cuda else cache.fingerprint(np.dtype(real).name, KEY_MODULES)
    launchers = {kind: ItemLauncher(target, item, args[kind], label=f"dem_{kind}", cache_key=key,
                                    parallel=partial(use_parallel, kind))
                 for kind, item in items.items()}
    launchers["sort"] = profiled("dem_sort", build_grid_sort(target))
    if target.is_cuda:      # a thread block per body (the hull's spheres summed in parallel)
        launchers["gather"] = build_gather_cuda(target, real, body_loads)
    return launchers
