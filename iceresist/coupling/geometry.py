"""Shapes of the coupled solids as signed distance functions in the body frame (paper section 2.4).

The body frame is the DEM's: origin at the centre of mass, axes along the principal axes
(:class:`iceresist.dem.RigidShape`, ``model_com_m`` and ``model_to_body``). Distances are
negative inside, positive outside:

* sphere: |p| - r (exact);
* box with half extents h: the exact box distance, |max(|p| - h, 0)| + min(max_k(|p_k| - h_k), 0);
* convex polyhedron: max over the face planes n_i . p + d_i (|n_i| = 1). Exact inside the solid and
  outside wherever the nearest surface point lies inside a face; near edges and vertices, outside, it
  underestimates the distance (by at most a factor 1/sqrt(3) next to a corner). Its zero level set is the
  exact surface, so the link distances q found by root finding along the links are exact.
* union of convex pieces (a solid that is not convex, e.g. a hull mesh cut into slabs): the min over the pieces
  of each piece's max over its planes. The pieces' planes follow one another in the plane table, each piece
  closed by a separator row (normal 0, :data:`SEPARATOR`). Its zero level set is the union's surface; inside, a
  seam between two pieces reads close to 0 (each piece's cap is near), never above.

Each shape packs into a row of parameters and, for polyhedra, a table of planes, which the kernels of
:mod:`iceresist.coupling.kernels` read; the NumPy ``sdf`` methods here are their reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from iceresist.errors import InputError

SPHERE, BOX, CONVEX = 0, 1, 2
#: The offset of a separator row in the plane table (its normal is 0): the end of one convex piece.
SEPARATOR = 1.0e30


@dataclass(frozen=True)
class Sphere:
    """A sphere of radius ``radius_m`` about the centre of mass."""

    radius_m: float
    kind: int = field(default=SPHERE, init=False)

    def __post_init__(self):
        if not self.radius_m > 0:
            raise InputError(f"Sphere radius_m must be positive, got {self.radius_m!r}")

    def parameters(self):
        return np.array([self.radius_m, 0.0, 0.0]), np.zeros((0, 4))

    def half_extent_m(self):
        return np.full(3, self.radius_m)

    def volume_m3(self):
        return 4.0 / 3.0 * np.pi * self.radius_m ** 3

    def sdf(self, p):
        return np.linalg.norm(np.asarray(p, dtype=float), axis=-1) - self.radius_m


@dataclass(frozen=True)
class Box:
    """A box of edge lengths ``size_m`` (body axes) centred on the centre of mass (``iceresist.dem.box``)."""

    size_m: tuple
    kind: int = field(default=BOX, init=False)

    def __post_init__(self):
        s = np.asarray(self.size_m, dtype=float)
        if s.shape != (3,) or not (s > 0).all():
            raise InputError(f"Box size_m must be three positive lengths, got {self.size_m!r}")

    def parameters(self):
        return 0.5 * np.asarray(self.size_m, dtype=float), np.zeros((0, 4))

    def half_extent_m(self):
        return 0.5 * np.asarray(self.size_m, dtype=float)

    def volume_m3(self):
        return float(np.prod(self.size_m))

    def sdf(self, p):
        d = np.abs(np.asarray(p, dtype=float)) - self.half_extent_m()
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
        return outside + np.minimum(d.max(axis=-1), 0.0)


@dataclass(frozen=True)
class ConvexPolyhedron:
    """A convex solid from its vertices in the model frame, moved into the body frame of ``shape``
    (``iceresist.dem.convex_polyhedron``: p_body = model_to_body^T (p_model - model_com))."""

    vertices_m: np.ndarray
    model_com_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    model_to_body: np.ndarray = field(default_factory=lambda: np.eye(3))
    kind: int = field(default=CONVEX, init=False)

    @classmethod
    def of_shape(cls, vertices_m, shape):
        """The polyhedron of ``vertices_m`` (model frame) in the body frame of a DEM ``RigidShape``."""
        return cls(np.asarray(vertices_m, dtype=float), np.asarray(shape.model_com_m, dtype=float),
                   np.asarray(shape.model_to_body, dtype=float))

    def body_vertices(self):
        v = np.asarray(self.vertices_m, dtype=float)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
            raise InputError("ConvexPolyhedron vertices_m must be an (n >= 4, 3) array in metres")
        return (v - self.model_com_m) @ self.model_to_body

    def parameters(self):
        from scipy.spatial import ConvexHull

        eq = ConvexHull(self.body_vertices()).equations       # n . p + d <= 0 inside, |n| = 1
        eq = np.unique(np.round(eq, 12), axis=0)                # coplanar triangles give one plane
        return np.zeros(3), eq

    def half_extent_m(self):
        return np.abs(self.body_vertices()).max(axis=0)

    def volume_m3(self):
        from scipy.spatial import ConvexHull

        return float(ConvexHull(self.body_vertices()).volume)

    def sdf(self, p):
        _, eq = self.parameters()
        p = np.asarray(p, dtype=float)
        return (p @ eq[:, :3].T + eq[:, 3]).max(axis=-1)


@dataclass(frozen=True)
class ConvexUnion:
    """A union of convex pieces, each given by its vertices in the model frame, moved into the body frame of
    ``shape`` as :class:`ConvexPolyhedron`; ``volume`` (m^3) is the solid's own (the pieces may overlap)."""

    pieces_m: tuple
    volume: float
    model_com_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    model_to_body: np.ndarray = field(default_factory=lambda: np.eye(3))
    kind: int = field(default=CONVEX, init=False)

    @classmethod
    def of_shape(cls, pieces_m, volume_m3, shape):
        return cls(tuple(np.asarray(p, dtype=float) for p in pieces_m), float(volume_m3),
                   np.asarray(shape.model_com_m, dtype=float), np.asarray(shape.model_to_body, dtype=float))

    def _polys(self):
        return [ConvexPolyhedron(p, self.model_com_m, self.model_to_body) for p in self.pieces_m]

    def parameters(self):
        """Each piece's planes, a separator row after each but the last; a cap shared with another piece (all
        its vertices on a plane x = const of the model frame that another piece also has) stored at twice its
        length, so the kernels leave it out of the distance inside."""
        sep = np.array([[0.0, 0.0, 0.0, SEPARATOR]])
        ends = [(p[:, 0].min(), p[:, 0].max()) for p in self.pieces_m]
        cuts = [x for lo, hi in ends for x in (lo, hi)]
        shared = {x for x in cuts if sum(abs(c - x) <= 1e-12 * (1.0 + abs(x)) for c in cuts) > 1}
        rows = []
        for piece, poly in zip(self.pieces_m, self._polys()):
            eq = poly.parameters()[1].copy()
            body = poly.body_vertices()
            for r in range(len(eq)):
                on = np.abs(body @ eq[r, :3] + eq[r, 3]) <= 1e-9 * (1.0 + np.abs(body).max())
                xs = piece[on, 0]
                if len(xs) and any(np.all(np.abs(xs - c) <= 1e-12 * (1.0 + abs(c))) for c in shared):
                    eq[r] *= 2.0
            rows += [eq, sep]
        return np.zeros(3), np.concatenate(rows[:-1])  # no separator after the last piece

    def half_extent_m(self):
        return np.abs(np.concatenate([poly.body_vertices() for poly in self._polys()])).max(axis=0)

    def volume_m3(self):
        return self.volume

    def sdf(self, p):
        """The kernels' rule (:func:`iceresist.coupling.cellfunctions`): outside the min over the pieces,
        inside the min over the pieces that hold p of their distance without the shared caps."""
        _, eq = self.parameters()
        p = np.asarray(p, dtype=float)
        ends = np.flatnonzero((eq[:, :3] == 0).all(axis=1))
        out, inside = np.inf, np.full(p.shape[:-1], np.inf)
        for rows in np.split(eq, ends):
            rows = rows[(rows[:, :3] != 0).any(axis=1)]
            cap = (rows[:, :3] ** 2).sum(axis=1) > 2.0
            v = p @ rows[:, :3].T + rows[:, 3]
            v = np.where(cap, 0.5 * v, v)
            dp, ds = v.max(axis=-1), np.where(cap, -np.inf, v).max(axis=-1)
            out = np.minimum(out, dp)
            inside = np.where(dp < 0, np.minimum(inside, ds), inside)
        return np.where(np.isfinite(inside), inside, out)


def pack(geometries):
    """Kinds (n,), parameters (n, 3), first plane and plane count (n,), planes (m, 4), body-frame half extents (n, 3)."""
    kinds, pars, first, count, planes, half = [], [], [], [], [], []
    m = 0
    for g in geometries:
        if not isinstance(g, (Sphere, Box, ConvexPolyhedron, ConvexUnion)):
            raise InputError(f"coupled geometry must be Sphere, Box, ConvexPolyhedron or ConvexUnion, got "
                             f"{type(g).__name__}")
        par, pl = g.parameters()
        kinds.append(g.kind)
        pars.append(par)
        first.append(m)
        count.append(len(pl))
        planes.append(pl)
        half.append(g.half_extent_m())
        m += len(pl)
    planes = np.concatenate(planes) if m else np.zeros((1, 4))
    return (np.array(kinds, dtype=np.int32), np.array(pars, dtype=float), np.array(first, dtype=np.int32),
            np.array(count, dtype=np.int32), planes, np.array(half, dtype=float))
