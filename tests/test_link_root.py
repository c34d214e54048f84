"""The link distance of eq. (16) in closed form (iceresist.coupling.cellfunctions.build_link_root): for a sphere,
a rotated box and a convex polyhedron, where the segment x - t c_q from a cell centre outside the body to the
covered cell centre enters the body, against the root of the shape's own signed distance
(iceresist.coupling.geometry, ``sdf``: the first entry along the link, by sampling and bisection to 1e-12 in
float64), over every link of the body's surface, and for a union of convex pieces (where a link may cross the
body twice)."""

import numpy as np
import pytest
from numba import njit

from iceresist.backends import jit
from iceresist.coupling.cellfunctions import build_link_root
from iceresist.coupling.geometry import Box, ConvexPolyhedron, ConvexUnion, Sphere, pack
from iceresist.lattice import C


def _rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _tables(geometry, centre, rot):
    """``body``, ``bint``, ``planes``, ``grid`` of one body (lattice units, dx = 1) as the coupling lays them out."""
    kinds, pars, first, count, planes, _ = pack([geometry])
    body = np.zeros((1, 21))
    body[0, :3] = centre
    body[0, 3:12] = rot.reshape(-1)
    body[0, 18:21] = pars[0]
    bint = np.zeros((1, 12), np.int32)
    bint[0, :3] = kinds[0], first[0], count[0]
    return body, bint, np.ascontiguousarray(planes), np.array([64, 64, 64, 0, 0, 0], np.int64)


@pytest.fixture(scope="module")
def roots():
    link_root = build_link_root(jit.cpu, np.float64)

    @njit
    def all_roots(p, c, body, bint, planes, grid, out):
        for i in range(len(out)):
            out[i] = link_root(0, p[i, 0], p[i, 1], p[i, 2], c[i, 0], c[i, 1], c[i, 2], body, bint, planes, grid)

    def run(p, c, body, bint, planes, grid):
        out = np.empty(len(p))
        all_roots(p, c, body, bint, planes, grid, out)
        return out

    return run


def _links(geometry, centre, rot):
    """Every link (x outside, y = x - c_q inside) of the body's surface: x, c_q, and where x - t c_q first enters
    the body."""
    g = np.arange(64) + 0.5
    cells = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    sdf = lambda p: geometry.sdf((p - centre) @ rot)  # noqa: E731  (rot: body -> world)
    inside = sdf(cells) < 0
    near = cells[inside & (sdf(cells) > -2.0)]
    xs, cs = [], []
    for q in range(1, 27):
        x = near + C[q]
        out = sdf(x) > 0
        xs.append(x[out])
        cs.append(np.broadcast_to(C[q].astype(float), x[out].shape))
    x, c = np.concatenate(xs), np.concatenate(cs)
    # the first entry: the first sample of 400 along the link inside (a non-convex union may be crossed twice),
    # then bisection between it and the sample before
    ts = np.linspace(0.0, 1.0, 401)
    inside = np.stack([sdf(x - t * c) <= 0 for t in ts], axis=1)
    j = inside.argmax(axis=1)
    lo, hi = ts[j - 1], ts[j]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        outside = sdf(x - mid[:, None] * c) > 0
        lo, hi = np.where(outside, mid, lo), np.where(outside, hi, mid)
    return x, c, 0.5 * (lo + hi)


OCTAHEDRON = np.array([[6.0, 0, 0], [-6, 0, 0], [0, 5, 0], [0, -5, 0], [0, 0, 4], [0, 0, -4.5]])


@pytest.mark.parametrize("geometry", [Sphere(5.3), Box((9.0, 6.4, 4.2)), ConvexPolyhedron(OCTAHEDRON)],
                         ids=["sphere", "box", "polyhedron"])
def test_link_distance_in_closed_form_is_the_root_of_the_signed_distance(roots, geometry):
    centre, rot = np.array([31.3, 30.8, 32.6]), _rotation((1.0, 2.0, 0.5), 0.7)
    x, c, exact = _links(geometry, centre, rot)
    assert len(x) > 500
    t = roots(x, c, *_tables(geometry, centre, rot))
    assert np.abs(t - exact).max() < 1e-9
    assert (t > 0).all() and (t <= 1).all()


def test_link_distance_into_a_union_of_convex_pieces(roots):
    """An L of two boxes (a shared cap, stored at twice its length) and a wedge beside them, rotated: the entry into
    the union is the first entry into a piece the link crosses."""
    a = np.array([[x, y, z] for x in (-8.0, 0.0) for y in (-3.0, 3.0) for z in (-2.0, 2.0)])
    b = np.array([[x, y, z] for x in (0.0, 6.0) for y in (-3.0, 3.0) for z in (-2.0, 7.0)])
    w = np.array([[6.0, -3, -2], [6, 3, -2], [6, -3, 2], [6, 3, 2], [11, 0, -2], [11, 0, 2]])
    union = ConvexUnion([a, b, w], 1.0)
    assert (pack([union])[4][:, :3] == 0).all(axis=1).sum() == 2
    centre, rot = np.array([32.4, 31.7, 30.9]), _rotation((0.3, -1.0, 0.6), 0.5)
    x, c, exact = _links(union, centre, rot)
    assert len(x) > 500
    t = roots(x, c, *_tables(union, centre, rot))
    assert np.abs(t - exact).max() < 1e-9



def _union():
    a = np.array([[x, y, z] for x in (-8.0, 0.0) for y in (-3.0, 3.0) for z in (-2.0, 2.0)])
    b = np.array([[x, y, z] for x in (0.0, 6.0) for y in (-3.0, 3.0) for z in (-2.0, 7.0)])
    w = np.array([[6.0, -3, -2], [6, 3, -2], [6, -3, 2], [6, 3, 2], [11, 0, -2], [11, 0, 2]])
    return ConvexUnion([a, b, w], 1.0)


@pytest.mark.parametrize("geometry", [Sphere(5.3), Box((9.0, 6.4, 4.2)), ConvexPolyhedron(OCTAHEDRON), "union"],
                         ids=["sphere", "box", "polyhedron", "union"])
def test_link_distance_from_a_point_inside_is_at_most_zero(roots, geometry):
    """The link pass (iceresist.coupling.kernels, ``link_cell``) takes the closed form before the fluid cell's own
    signed distance, which only its fallback (t < 0) reads: a fluid cell whose centre lies inside the body (where
    the covering differs from the signed distance by round-off) must come out at t <= 0, which the pass clamps
    to Q_MIN as it did when it read that distance first. Every point of a quarter-cell lattice inside the rotated
    body, with each of the 26 links, gives t <= 0 (to 1e-12). Planted: the sphere's larger root, and the
    polyhedron's entry taken as the latest crossing of any plane (nd != 0 instead of nd > 0): fail for the sphere,
    the polyhedron and the union."""
    if geometry == "union":
        geometry = _union()
    centre, rot = np.array([31.3, 30.8, 32.6]), _rotation((1.0, 2.0, 0.5), 0.7)
    g = np.arange(16, 48, 0.5) + 0.125
    points = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    p = points[geometry.sdf((points - centre) @ rot) < 0]
    assert len(p) > 1000
    x = np.repeat(p, 26, axis=0)
    c = np.tile(C[1:].astype(float), (len(p), 1))
    t = roots(x, c, *_tables(geometry, centre, rot))
    assert t.max() <= 1e-12

@pytest.mark.parametrize("geometry", [Sphere(5.3), Box((9.0, 6.4, 4.2)), ConvexPolyhedron(OCTAHEDRON), "union"],
                         ids=["sphere", "box", "polyhedron", "union"])
def test_central_difference_of_the_signed_distance_in_one_pass(geometry):
    """``build_sdf_difference`` (the phi mirror's normal, iceresist.coupling.surface_kernels) against the six
    evaluations of ``sdf_at`` it replaces, sdf(p + e/2) - sdf(p - e/2) along each world axis, at every point of a
    quarter-cell lattice within 2 of the surface of a rotated body (float64): equal to 1e-12, the union by the six
    evaluations themselves. Planted: the columns of R taken for its rows as the world axes in the body frame: fails
    for the sphere, the box and the polyhedron (the union takes the six evaluations)."""
    from iceresist.coupling.cellfunctions import build_geometry_functions, build_sdf_difference

    if geometry == "union":
        a = np.array([[x, y, z] for x in (-8.0, 0.0) for y in (-3.0, 3.0) for z in (-2.0, 2.0)])
        b = np.array([[x, y, z] for x in (0.0, 6.0) for y in (-3.0, 3.0) for z in (-2.0, 7.0)])
        w = np.array([[6.0, -3, -2], [6, 3, -2], [6, -3, 2], [6, 3, 2], [11, 0, -2], [11, 0, 2]])
        geometry = ConvexUnion([a, b, w], 1.0)
    centre, rot = np.array([31.3, 30.8, 32.6]), _rotation((1.0, 2.0, 0.5), 0.7)
    sdf_difference = build_sdf_difference(jit.cpu, np.float64)
    sdf_at = build_geometry_functions(jit.cpu, np.float64)[1]

    @njit
    def evaluate(p, body, bint, planes, grid, out):
        for i in range(len(p)):
            out[i, 0:3] = sdf_difference(0, p[i, 0], p[i, 1], p[i, 2], body, bint, planes, grid)
            for a in range(3):
                e = np.zeros(3)
                e[a] = 0.5
                out[i, 3 + a] = (sdf_at(0, p[i, 0] + e[0], p[i, 1] + e[1], p[i, 2] + e[2], body, bint, planes, grid)
                                 - sdf_at(0, p[i, 0] - e[0], p[i, 1] - e[1], p[i, 2] - e[2], body, bint, planes, grid))

    g = np.arange(16, 48, 0.25) + 0.125
    points = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    s = geometry.sdf((points - centre) @ rot)
    p = points[(s < 0) & (s > -2.0)]
    assert len(p) > 5000
    out = np.empty((len(p), 6))
    evaluate(p, *_tables(geometry, centre, rot), out)
    assert np.abs(out[:, :3]).max() > 0.5
    assert np.abs(out[:, :3] - out[:, 3:]).max() < 1e-12
