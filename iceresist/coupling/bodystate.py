"""The body state between the DEM and the lattice, on the target (paper section 2.4, steps 1 and 5).

Four per-item passes keep a coupled step on the device: nothing per body crosses between host and device.

* ``body_row(r, ...)`` (one item per launch row): the row's body in lattice units from the DEM state, the
  ``body``/``bint`` rows of :mod:`iceresist.coupling.kernels` (centre (x - origin) / dx, rotation of the unit
  quaternion, velocity v dt / dx, angular velocity omega dt, shape parameters; the cell box
  floor(x - e - 1/2) - 1 .. ceil(x + e - 1/2) + 1 with e = |R| h the half extents of the rotated bounding box,
  clipped to the domain on walled axes, at most one period long on periodic ones); a body launched as several
  rows gives row j of m the run ``run_of`` of its box's cells (``bint[r, 10:12]``, cells counted x fastest) and
  the planes that run touches as the row's box. The first row of a body writes the whole box to ``box[body]``.
* ``active_row(r, ...)``: flags ``active[block] = 1`` for every block the row's cell box of this step and of the
  previous one touch, dilated by one cell (the blocks where cells may be covered or uncovered). A step runs both
  passes of a row in one item, ``body_row_active`` (each reads only the ``bint`` row its own item wrote).
* ``row_sums(k, ...)`` (one item per body): F_s(t), M_s(t) (eqs. 18-19, lattice units) and the link count of
  body k summed over its rows into ``now[k]``, ``links[k]``; the rows are zeroed for the next links pass;
* ``fluid_loads(k, ...)`` (one item per body): F_fluid = (F_s(t) + F_s(t - dt)) / 2 and M_fluid likewise
  (eqs. 20-21) in newtons and newton metres into ``fluid[k]``, added to ``fluid_sum[k]`` (records average it),
  and written as the DEM's external load (eqs. 13-14) less the buoyancy ``buoy[k]`` = rho_f V g (zero where the
  fluid carries the hydrostatic pressure); ``fprev[k]`` keeps F_s(t) for the next step. On one process a step runs
  both body passes of a body in one item, ``row_loads`` (no sum over ranks between them).

``rows[r] = (body, run, runs)`` lists the launch rows (:func:`iceresist.coupling.coupler.tile_rows`).
``conv`` (float64): origin x, y, z (m), dx (m), dt / dx (s/m), dt (s). ``grid`` (int64): nx, ny, nz, and 1 for
periodic axes. ``load_scale`` (float64): the lattice force and torque units, F dt^2 / (rho dx^4) -> N and N m.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.backends import cache
from iceresist.backends.jit import cuda_api
from iceresist.backends.launch import BlockLauncher, build_block_sum6, cuda_launch, profiled
from iceresist.freesurface.layout import DIR_OF_OFFSET

BODY_ROW_ARGS = ("rows", "pos", "quat", "vel", "omega", "shape_int", "par_lat", "half_lat", "conv", "grid", "body",
                 "bint", "box")
#: ``body_row`` then ``active_row`` of the same row: one launch of a step.
BODY_ROW_ACTIVE_ARGS = BODY_ROW_ARGS + ("box_prev", "has_prev", "nblocks3", "block_map", "active")
ROW_SUMS_ARGS = ("row_ptr", "row_idx", "bforce", "btorque", "nlinks", "now", "links")
FLUID_LOADS_ARGS = ("now", "has_prev", "fprev", "load_scale", "buoy", "ext", "fluid", "fluid_sum")
#: ``row_sums`` then ``fluid_loads`` of the same body: one launch of a step on one process.
ROW_LOADS_ARGS = ROW_SUMS_ARGS + FLUID_LOADS_ARGS[1:]


def build_body_state(target, real):
    """Compile the device functions ``(body_row, body_row_active, row_sums, fluid_loads, row_loads)`` (module
    docstring)."""
    int64, int32, f64 = np.int64, np.int32, np.float64

    def run_of(plane, nz, j, m):
        """Cells [s, e) of run j of m of a box of ``nz`` planes of ``plane`` cells, counted x fastest from its low
        corner (the runs partition the box; run j holds cells j N // m to (j + 1) N // m, N = plane nz)."""
        n = plane * nz
        return (j * n) // m, ((j + 1) * n) // m

    run_of = target.device(run_of)

    def body_row(r, rows, pos, quat, vel, omega, shape_int, par_lat, half_lat, conv, grid, body, bint, box):
        r = int64(r)
        k = rows[r, 0]
        j = rows[r, 1]
        m = rows[r, 2]
        qw = f64(quat[k, 0])
        qx = f64(quat[k, 1])
        qy = f64(quat[k, 2])
        qz = f64(quat[k, 3])
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        w = qw / qn
        x = qx / qn
        y = qy / qn
        z = qz / qn
        rot = (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
               2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
               2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))
        for i in range(9):
            body[r, 3 + i] = rot[i]
        for a in range(3):
            p = (f64(pos[k, a]) - conv[a]) / conv[3]
            body[r, a] = p
            body[r, 12 + a] = f64(vel[k, a]) * conv[4]
            body[r, 15 + a] = f64(omega[k, a]) * conv[5]
            body[r, 18 + a] = par_lat[k, a]
            e = (abs(rot[3 * a]) * half_lat[k, 0] + abs(rot[3 * a + 1]) * half_lat[k, 1]
                 + abs(rot[3 * a + 2]) * half_lat[k, 2])
            lo = int64(math.floor(p - e - 0.5)) - 1
            hi = int64(math.ceil(p + e - 0.5)) + 1
            n = grid[a]
            if grid[3 + a] != 0:
                hi = min(hi, lo + n - 1)
            else:
                lo = max(lo, int64(0))
                hi = min(hi, n - 1)
            if j == 0:
                box[k, a] = lo
                box[k, 3 + a] = hi
            bint[r, 3 + a] = int32(lo)
            bint[r, 6 + a] = int32(hi)
        # the row's run of the box, and the row's box cut down to the planes the run touches
        plane = max(int64(bint[r, 6]) - bint[r, 3] + 1, int64(0)) * max(int64(bint[r, 7]) - bint[r, 4] + 1, int64(0))
        nz = max(int64(bint[r, 8]) - bint[r, 5] + 1, int64(0))
        first, end = run_of(plane, nz, j, m)
        if end > first:
            z0 = first // plane
            bint[r, 8] = int32(bint[r, 5] + (end - 1) // plane)
            bint[r, 5] = int32(bint[r, 5] + z0)
            bint[r, 10] = int32(first - z0 * plane)
            bint[r, 11] = int32(end - z0 * plane)
        else:
            bint[r, 10] = 0
            bint[r, 11] = 0
        bint[r, 0] = shape_int[k, 0]
        bint[r, 1] = shape_int[k, 1]
        bint[r, 2] = shape_int[k, 2]
        bint[r, 9] = int32(k)

    def mark_blocks(lx, ly, lz, hx, hy, hz, grid, nblocks3, block_map, active):
        """active = 1 on the blocks the cells lx..hx, ly..hy, lz..hz dilated by one cell touch. The three axes are
        written out: a helper per axis (a tuple return) spilled registers on sm_90."""
        for bz in range((lz - 1) >> 3, ((hz + 1) >> 3) + 1):
            cz = bz % nblocks3[2] if grid[5] != 0 else bz
            if cz < 0 or cz >= nblocks3[2]:
                continue
            for by in range((ly - 1) >> 3, ((hy + 1) >> 3) + 1):
                cy = by % nblocks3[1] if grid[4] != 0 else by
                if cy < 0 or cy >= nblocks3[1]:
                    continue
                for bx in range((lx - 1) >> 3, ((hx + 1) >> 3) + 1):
                    cx = bx % nblocks3[0] if grid[3] != 0 else bx
                    if cx < 0 or cx >= nblocks3[0]:
                        continue
                    b = block_map[cx, cy, cz]
                    if b >= 0:
                        active[b] = 1

    mark_blocks = target.device(mark_blocks)

    def active_row(r, rows, bint, box_prev, has_prev, grid, nblocks3, block_map, active):
        r = int64(r)
        if bint[r, 11] > bint[r, 10]:
            mark_blocks(int64(bint[r, 3]), int64(bint[r, 4]), int64(bint[r, 5]), int64(bint[r, 6]),
                        int64(bint[r, 7]), int64(bint[r, 8]), grid, nblocks3, block_map, active)
        if has_prev != 0:
            k = rows[r, 0]
            plane = (max(box_prev[k, 3] - box_prev[k, 0] + 1, int64(0))
                     * max(box_prev[k, 4] - box_prev[k, 1] + 1, int64(0)))
            s, e = run_of(plane, max(box_prev[k, 5] - box_prev[k, 2] + 1, int64(0)), rows[r, 1], rows[r, 2])
            if e > s:
                mark_blocks(box_prev[k, 0], box_prev[k, 1], box_prev[k, 2] + s // plane, box_prev[k, 3],
                            box_prev[k, 4], box_prev[k, 2] + (e - 1) // plane, grid, nblocks3, block_map, active)

    body_row_dev = target.device(body_row)
    active_row_dev = target.device(active_row)

    def body_row_active(r, rows, pos, quat, vel, omega, shape_int, par_lat, half_lat, conv, grid, body, bint, box,
                        box_prev, has_prev, nblocks3, block_map, active):
        body_row_dev(r, rows, pos, quat, vel, omega, shape_int, par_lat, half_lat, conv, grid, body, bint, box)
        active_row_dev(r, rows, bint, box_prev, has_prev, grid, nblocks3, block_map, active)

    def row_sums(k, row_ptr, row_idx, bforce, btorque, nlinks, now, links):
        k = int64(k)
        fx, fy, fz, mx, my, mz = f64(0.0), f64(0.0), f64(0.0), f64(0.0), f64(0.0), f64(0.0)
        nl = int64(0)
        for i in range(row_ptr[k], row_ptr[k + 1]):
            r = row_idx[i]
            fx += bforce[r, 0]
            fy += bforce[r, 1]
            fz += bforce[r, 2]
            mx += btorque[r, 0]
            my += btorque[r, 1]
            mz += btorque[r, 2]
            nl += nlinks[r, 0]
            for a in range(3):
                bforce[r, a] = 0.0
                btorque[r, a] = 0.0
            nlinks[r, 0] = 0
        now[k, 0] = fx
        now[k, 1] = fy
        now[k, 2] = fz
        now[k, 3] = mx
        now[k, 4] = my
        now[k, 5] = mz
        links[k] = nl

    def fluid_loads(k, now, has_prev, fprev, load_scale, buoy, ext, fluid, fluid_sum):
        k = int64(k)
        for a in range(6):
            v = now[k, a]
            avg = 0.5 * (v + fprev[k, a]) if has_prev != 0 else v
            fprev[k, a] = v
            if a < 3:
                load = avg * load_scale[0]
                ext[k, a] = load - buoy[k, a]
            else:
                load = avg * load_scale[0] * load_scale[1]
                ext[k, a] = load
            fluid[k, a] = load
            fluid_sum[k, a] += load

    row_sums_dev = target.device(row_sums)
    fluid_loads_dev = target.device(fluid_loads)

    def row_loads(k, row_ptr, row_idx, bforce, btorque, nlinks, now, links, has_prev, fprev, load_scale, buoy, ext,
                  fluid, fluid_sum):
        row_sums_dev(k, row_ptr, row_idx, bforce, btorque, nlinks, now, links)
        fluid_loads_dev(k, now, has_prev, fprev, load_scale, buoy, ext, fluid, fluid_sum)

    return (body_row_dev, target.device(body_row_active), row_sums_dev, fluid_loads_dev, target.device(row_loads))


def build_event_mask(target):
    """Compile ``near_mask(b, evt, nbr, near)``: bit o of ``near[b]`` (int32) is set where the block at offset o
    of b, o = (bx + 1) + 3 (by + 1) + 9 (bz + 1) (bit 13: b itself), had a covered or uncovered cell this step
    (``evt`` of the refill pass). A cell of b whose 26 neighbours lie in blocks without the bit has nothing to
    redistribute (:func:`reach_mask`)."""
    dir_of = DIR_OF_OFFSET
    int64, int32 = np.int64, np.int32

    def near_mask(b, evt, nbr, near):
        b = int64(b)
        m = int32(0)
        for o in range(27):
            bn = nbr[b, dir_of[o]]
            if bn >= 0:
                if evt[bn] != 0:
                    m |= int32(1) << int32(o)
        near[b] = m

    return target.device(near_mask)


def build_changed_blocks(target):
    """Compile ``changed_block(b, active, owner, owner_prev, full, changed)``: ``changed[b]`` = 1 where block b is
    active and one of its cells changed cover since the last step (covered now and not then, or the reverse), or
    where ``full`` asks for every active block (the first step, which sets the GHOST flags of the cells the bodies
    cover at the start). The refill and its flags change nothing in the other blocks: a cell that keeps its cover
    keeps its flags."""
    int8, int64 = np.int8, np.int64

    def changed_block(b, active, owner, owner_prev, full, changed):
        b = int64(b)
        m = int8(0)
        if active[b] != 0:
            if full != 0:
                m = int8(1)
            else:
                for c in range(512):
                    if (owner[b, c] >= 0) != (owner_prev[b, c] >= 0):
                        m = int8(1)
        changed[b] = m

    return target.device(changed_block)


def build_reach_mask(target):
    """Compile ``reach_mask(c) -> int32``: the bits (as :func:`build_event_mask`) of the blocks the 26 neighbours
    of cell c of a block lie in: its own block, and across each face, edge or corner the cell touches."""
    int32 = np.int32

    def reach_mask(c):
        x = c & 7
        y = (c >> 3) & 7
        z = c >> 6
        mx = 2 | (1 if x == 0 else 0) | (4 if x == 7 else 0)
        my = 2 | (1 if y == 0 else 0) | (4 if y == 7 else 0)
        mz = 2 | (1 if z == 0 else 0) | (4 if z == 7 else 0)
        # bit (i + 3 j + 9 k) for i in mx, j in my, k in mz: each axis's bits spread over the 27, then ANDed
        sx = mx * 0x1249249
        sy = (((my & 1) * 7) | ((my & 2) * 28) | ((my & 4) * 112)) * 0x40201
        sz = ((mz & 1) * 0x1FF) | ((mz & 2) * 0x1FF * 256) | ((mz & 4) * 0x1FF * 65536)
        return int32(sx & sy & sz)

    return target.device(reach_mask)


#: Threads of the CUDA ``row_loads``'s thread block per body (:func:`build_row_loads_cuda`).
ROW_THREADS = 64


def build_row_loads_cuda(target, fluid_loads):
    """CUDA: the launch ``row_loads(n, *ROW_LOADS_ARGS)`` with one thread block of :data:`ROW_THREADS` threads per
    body: the threads sum (and zero) strided runs of the body's rows, a shared-memory tree adds their sums in a fixed
    order, and thread 0 writes ``now``, ``links`` and the fluid loads (``fluid_loads``). The hull's hundreds of rows
    are then summed by 64 threads, not one."""
    f64 = np.float64
    block_sum6 = build_block_sum6(f64, ROW_THREADS)
    nt, zero = ROW_THREADS, f64(0.0)
    ns = {"cuda": cuda_api(), "block_sum6": block_sum6, "body_loads": fluid_loads, "nt": nt, "zero": zero,
          "int64": np.int64, "f64": f64}   # cuda: a global of the kernel, for the simulator
    exec("""def fluid_loads(n, row_ptr, row_idx, bforce, btorque, nlinks, now, links, has_prev, fprev, load_scale, buoy,
                ext, fluid, fluid_sum):
    k = cuda.blockIdx.x
    t = cuda.threadIdx.x
    fx = zero
    fy = zero
    fz = zero
    mx = zero
    my = zero
    mz = zero
    nl = zero
    for i in range(row_ptr[k] + t, row_ptr[k + 1], nt):
        r = row_idx[i]
        fx += bforce[r, 0]
        fy += bforce[r, 1]
        fz += bforce[r, 2]
        mx += btorque[r, 0]
        my += btorque[r, 1]
        mz += btorque[r, 2]
        nl += f64(nlinks[r, 0])
        for a in range(3):
            bforce[r, a] = zero
            btorque[r, a] = zero
        nlinks[r, 0] = 0
    fx, fy, fz, mx, my, mz = block_sum6(t, fx, fy, fz, mx, my, mz)
    nl, _, _, _, _, _ = block_sum6(t, nl, zero, zero, zero, zero, zero)
    if t == 0:
        now[k, 0] = fx
        now[k, 1] = fy
        now[k, 2] = fz
        now[k, 3] = mx
        now[k, 4] = my
        now[k, 5] = mz
        links[k] = int64(nl)
        body_loads(k, now, has_prev, fprev, load_scale, buoy, ext, fluid, fluid_sum)
""", ns)
    kern = target.kernel(ns["fluid_loads"], threads=nt)   # the build check and the launch budget name it so

    def launch(n, *args):
        cuda_launch(kern, int(n), nt, np.int64(n), *args)

    return profiled("fluid_loads", launch)


_LAUNCHERS: dict = {}

#: Modules whose source decides the compiled body-state launchers (the key of their on-disk kernel cache).
KEY_MODULES = ("iceresist.coupling.bodystate", "iceresist.freesurface.layout")


def body_state_launchers(target, real) -> dict:
    """``{"body_rows", "row_sums", "fluid_loads", "row_loads", "near_events", "changed_blocks"}``: launchers over
    launch rows (``body_row`` and ``active_row`` of each), bodies (three) and forest blocks (the last two), cached
    per target and precision. ``near_events`` gathers the event flags of each block and its 26 neighbours into a bit mask
    (:func:`build_event_mask`; the blocks a redistribution reaches); ``changed_blocks`` flags the active blocks
    where a cell changed cover (:func:`build_changed_blocks`)."""
    key = (target.name, target.simulator, np.dtype(real).name)
    if key not in _LAUNCHERS:
        _, body_row_active, row_sums, fluid_loads, row_loads = build_body_state(target, real)
        near = build_event_mask(target)
        changed = build_changed_blocks(target)
        k = None if target.is_cuda else cache.fingerprint(f"body_state|{np.dtype(real).name}", KEY_MODULES)
        _LAUNCHERS[key] = {
            "body_rows": BlockLauncher(target, body_row_active, BODY_ROW_ACTIVE_ARGS, label="body_rows",
                                       cache_key=k),
            "row_sums": BlockLauncher(target, row_sums, ROW_SUMS_ARGS, label="row_sums", cache_key=k),
            "fluid_loads": BlockLauncher(target, fluid_loads, FLUID_LOADS_ARGS, label="fluid_loads", cache_key=k),
            "row_loads": (build_row_loads_cuda(target, fluid_loads) if target.is_cuda else
                          BlockLauncher(target, row_loads, ROW_LOADS_ARGS, label="fluid_loads", cache_key=k)),
            "near_events": BlockLauncher(target, near, ("evt", "nbr", "near"), label="near_events", cache_key=k),
            "changed_blocks": BlockLauncher(target, changed, ("active", "owner", "owner_prev", "full", "changed"),
                                            label="changed_blocks", cache_key=k),
        }
    return _LAUNCHERS[key]
