"""The CPU run forms of the body passes ``mark`` and ``links`` (:mod:`iceresist.coupling.kernels`).

A launch row's run of cells is walked in the order of the per-cell launcher (x fastest), and a cell whose signed
distance is evaluated also tells how many of the next cells of its line along +x stay on its side of a threshold
(:func:`build_sdf_ahead`); those are then taken without evaluating them. A hull's cell box holds mostly cells deep
inside it or far outside it, and the passes act only near its surface.

How far a line may be followed:

* a box or one convex polyhedron (the distance inside is the largest of its face planes n_i . x + e_i, exactly;
  outside it is at least that): each plane's value changes along the line at the constant rate r_i = n_i . a, a the
  line's direction in the body frame. Inside, below a threshold B < 0, the line stays below B until the first plane
  with r_i > 0 reaches it, t < min (B - v_i) / r_i; outside, above a threshold A > 0, it stays above A while a plane
  with v_i > A stays there, t < max (v_i - A) / (-r_i) (unbounded where r_i >= 0). Along the length of a hull,
  whose side, bottom and deck are parallel to x, one evaluation passes over the whole line;
* a sphere: the distance changes by at most one per cell (Lipschitz), floor(d - A) or floor(B - d) cells;
* a union of convex pieces, or a row whose nearest periodic image changes along its lines: every cell evaluated.

The thresholds keep a margin (``MARK_MARGIN``) from the values the passes decide on, so that round-off between the
extrapolated and the evaluated distance cannot move a cell across them.
"""

from __future__ import annotations

from iceresist.backends import jit
from iceresist.coupling.cellfunctions import build_body_frame, build_box_distance, build_geometry_functions
from iceresist.coupling.geometry import BOX, CONVEX, SPHERE
from iceresist.grid import flags as FL
from iceresist.lbm.codegen import compile_source

#: Margin (lattice units) of the thresholds from the values a pass decides on (mark: the sign; links: the sign and
#: the depth), within which the next cells are still evaluated.
MARK_MARGIN = 0.01

#: How a row's lines may be followed (:func:`build_sdf_ahead`): cell by cell, by the Lipschitz bound, by the planes.
EVERY_CELL, LIPSCHITZ, PLANES = 0, 1, 2


def build_line_mode(real):
    """``line_mode(k, bint, body, planes, grid)``: how row k's lines may be followed (module docstring): ``PLANES``
    for a box or one convex polyhedron, ``LIPSCHITZ`` for a sphere, ``EVERY_CELL`` for a union of convex pieces
    (whose distance inside reads the nearest piece's sides) and wherever the nearest periodic image along x changes
    within the lines of row k's box."""
    half, zero = real(0.5), real(0.0)
    convex, box, sphere = CONVEX, BOX, SPHERE

    @jit.cpu.device
    def line_mode(k, bint, body, planes, grid):
        if grid[3] != 0:        # periodic along x: the nearest image must not change along a line
            lim = real(0.5) * real(grid[0]) - real(1.0)
            if abs(real(bint[k, 3]) + half - body[k, 0]) >= lim or abs(real(bint[k, 6]) + half - body[k, 0]) >= lim:
                return EVERY_CELL
        kind = bint[k, 0]
        if kind == sphere:
            return LIPSCHITZ
        if kind == box:
            return PLANES
        if kind == convex:
            first = bint[k, 1]
            for i in range(first, first + bint[k, 2]):
                nn = planes[i, 0] * planes[i, 0] + planes[i, 1] * planes[i, 1] + planes[i, 2] * planes[i, 2]
                if nn == zero or nn > real(1.5):     # a separator or a shared cap: a union of pieces
                    return EVERY_CELL
            return PLANES
        return EVERY_CELL

    return line_mode


def build_sdf_ahead(real):
    """``sdf_ahead(k, px, py, pz, below, above, mode, body, bint, planes, grid) -> (d, n)``: the signed distance d of
    world point p to body k, bit for bit that of ``sdf_at`` (:func:`iceresist.coupling.cellfunctions.
    build_geometry_functions`), and how many of the next points p + t e_x, t = 1 .. n, are sure to stay below
    ``below`` (where d < below) or above ``above`` (where d > above); n = 0 between them and in mode ``EVERY_CELL``.
    ``mode`` from :func:`build_line_mode` (module docstring)."""
    _, sdf_at, _ = build_geometry_functions(jit.cpu, real)
    _, body_point = build_body_frame(jit.cpu, real)
    box_distance = build_box_distance(jit.cpu, real)
    zero, big, cap = real(0.0), real(1e30), real(1 << 30)
    box = BOX

    @jit.cpu.device
    def plane_inside(t, v, r, below):
        """The bound t on the steps along the line while a plane of value v and rate r stays below ``below``."""
        if r > zero:
            return min(t, (below - v) / r)
        return t

    @jit.cpu.device
    def plane_outside(t, v, r, above):
        """The bound t on the steps along the line while some plane seen so far stays above ``above``."""
        if v > above:
            if r >= zero:
                return big
            return max(t, (v - above) / (-r))
        return t

    @jit.cpu.device
    def slab_inside(t, x, h, a, below):
        """``plane_inside`` of the two faces +-x - h of a box, rates +-a."""
        return plane_inside(plane_inside(t, x - h, a, below), -x - h, -a, below)

    @jit.cpu.device
    def slab_outside(t, x, h, a, above):
        """``plane_outside`` of the two faces +-x - h of a box, rates +-a."""
        return plane_outside(plane_outside(t, x - h, a, above), -x - h, -a, above)

    @jit.cpu.device
    def steps(t):
        """Whole cells within the bound t (at most ``cap``)."""
        return int(min(t, cap))

    @jit.cpu.device
    def sdf_ahead(k, px, py, pz, below, above, mode, body, bint, planes, grid):
        if mode != PLANES:
            d = sdf_at(k, px, py, pz, body, bint, planes, grid)
            if mode == LIPSCHITZ:
                if d > above:
                    return d, int(d - above)
                if d < below:
                    return d, int(below - d)
            return d, 0
        x, y, z = body_point(k, px, py, pz, body, grid)
        ax, ay, az = body[k, 3], body[k, 4], body[k, 5]               # R^T e_x: the line's direction, body frame
        if bint[k, 0] == box:
            hx, hy, hz = body[k, 18], body[k, 19], body[k, 20]
            d = box_distance(x, y, z, hx, hy, hz)
            # six planes: +-x_b - h_x etc., rates +-a
            if d < below:
                t = slab_inside(slab_inside(slab_inside(big, x, hx, ax, below), y, hy, ay, below), z, hz, az, below)
                return d, steps(t)
            if d > above:
                t = slab_outside(slab_outside(slab_outside(zero, x, hx, ax, above), y, hy, ay, above), z, hz, az,
                                 above)
                return d, steps(t)
            return d, 0
        # one convex polyhedron: the distance is the largest plane value (sdf_at's loop for one piece)
        first = bint[k, 1]
        last = first + bint[k, 2]
        d = -big
        for i in range(first, last):
            d = max(d, planes[i, 0] * x + planes[i, 1] * y + planes[i, 2] * z + planes[i, 3])
        if d < below:
            t = big
            for i in range(first, last):
                v = planes[i, 0] * x + planes[i, 1] * y + planes[i, 2] * z + planes[i, 3]
                t = plane_inside(t, v, planes[i, 0] * ax + planes[i, 1] * ay + planes[i, 2] * az, below)
            return d, steps(t)
        if d > above:
            t = zero
            for i in range(first, last):
                v = planes[i, 0] * x + planes[i, 1] * y + planes[i, 2] * z + planes[i, 3]
                t = plane_outside(t, v, planes[i, 0] * ax + planes[i, 1] * ay + planes[i, 2] * az, above)
            return d, steps(t)
        return d, 0

    return sdf_ahead


def _run_source(name: str, sig: str, cell: str) -> str:
    """Source of ``name(k, {sig})`` walking the run of row k's cell box (``bint[k, 10:12]``, x fastest, the order of
    the per-cell launcher) with ``cell`` (indented 8) at each cell (gx, gy, gz); ``known`` counts the cells ahead
    on the current line that the last evaluated one decided (0 at each new line), ``mode`` is row k's
    :func:`build_line_mode`."""
    return f"""def {name}(k, {sig}):
    lx = bint[k, 3]
    ly = bint[k, 4]
    hx = bint[k, 6]
    hy = bint[k, 7]
    nx = hx - lx + 1
    ny = hy - ly + 1
    s = bint[k, 10]
    e = bint[k, 11]
    if e <= s:
        return
    mode = line_mode(k, bint, body, planes, grid)
    gx = lx + s % nx
    gy = ly + (s // nx) % ny
    gz = bint[k, 5] + s // (nx * ny)
    known = 0
    inside = False
    for _ in range(e - s):
{cell}        gx += 1
        if gx > hx:
            gx = lx
            known = 0
            gy += 1
            if gy > hy:
                gy = ly
                gz += 1
"""


def _run_namespace(real) -> dict:
    return {"line_mode": build_line_mode(real), "sdf_ahead": build_sdf_ahead(real), "real": real,
            "half": real(0.5), "zero": real(0.0), "margin": real(MARK_MARGIN)}


def build_mark_run(real, argnames):
    """The CPU run form of ``mark`` (:func:`iceresist.coupling.kernels.build_visits`), ``mark_run(k, *argnames)``:
    the cells of row k's run, the same owners as the per-cell visit; a cell within ``MARK_MARGIN`` of the surface
    is evaluated, the cells its line keeps on one side of it taken as inside or outside without evaluating them."""
    cell = """        if known > 0:
            known -= 1
        else:
            d, known = sdf_ahead(k, real(gx) + half, real(gy) + half, real(gz) + half, -margin, margin, mode, body,
                                 bint, planes, grid)
            inside = d < zero
        if inside:
            b, c = lookup(gx, gy, gz, grid, block_map)
            if b >= 0:
                if flags0[b, c] & FLUID:
                    owner[b, c] = k
"""
    lookup = build_geometry_functions(jit.cpu, real)[0]
    ns = {**_run_namespace(real), "lookup": lookup, "FLUID": FL.FLUID}
    return compile_source(_run_source("mark_run", ", ".join(argnames), cell), "mark_run", ns, jit.cpu.device)


def build_link_run(real, visit_at, argnames, depth: float):
    """The CPU run form of a link visit, ``link_run(k, *argnames)``: row k's run in the order of the per-cell
    launcher, ``visit_at(k, gx, gy, gz, d, *argnames)`` (``links_at`` of
    :func:`iceresist.coupling.kernels.build_visits`, with the cell's signed distance d) called at each cell with
    -``depth`` <= d < 0, the only cells where the visit acts (``depth``: the larger of the film and mirror depths);
    the cells a line keeps farther than ``MARK_MARGIN`` outside the surface or deeper than ``depth`` inside it are
    passed over. The same forces, links and mirrored phi, without walking the cells deep inside a hull or far
    outside it in its box."""
    sig = ", ".join(argnames)
    cell = f"""        if known > 0:
            known -= 1
        else:
            d, known = sdf_ahead(k, real(gx) + half, real(gy) + half, real(gz) + half, -depth - margin, margin, mode,
                                 body, bint, planes, grid)
            if d < zero and d >= -depth:
                visit_at(k, gx, gy, gz, d, {sig})
"""
    ns = {**_run_namespace(real), "visit_at": visit_at, "depth": real(depth)}
    return compile_source(_run_source("link_run", sig, cell), "link_run", ns, jit.cpu.device)
