"""Rigid bodies made of spheres placed on the body surface (Bell, Yu and Mucha 2005; paper section 2.3).

A :class:`RigidShape` carries what the DEM needs of one body, all in SI units:

* mass, volume and the principal moments of inertia of the *solid* (not of the spheres);
* the sphere centres in the principal (body) frame, origin at the centre of mass, and one radius;
* volume samples (sub-cells) in the body frame for the tier-1 buoyancy of :mod:`iceresist.dem.hydro`;
* ``model_com_m`` and ``model_to_body``: where the centre of mass sits in the frame the shape was
  described in (box centre, ship coordinates) and the rotation from that frame to the principal one.

Sphere centres are set back from the surface by one radius, so that the envelope of the spheres is the
solid's surface with rounded edges: a box of side ``a`` with ``n`` spheres per edge has ``r = a / (2 n)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from iceresist.errors import InputError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RigidShape:
    """Mass properties and sphere/volume samples of one rigid body (SI units)."""

    name: str
    mass_kg: float
    volume_m3: float
    inertia_kg_m2: np.ndarray  # (3,) principal moments of the solid
    sphere_offsets_m: np.ndarray  # (n, 3) sphere centres, body (principal) frame, origin at the centre of mass
    sphere_radius_m: float
    sample_offsets_m: np.ndarray  # (m, 3) volume-sample centres, body frame
    sample_volumes_m3: np.ndarray  # (m,) volume of each sample; they sum to volume_m3
    sample_half_extent_m: np.ndarray  # (3,) half size of a sample box along the body axes
    model_com_m: np.ndarray = field(default_factory=lambda: np.zeros(3))  # centre of mass in the model frame
    model_to_body: np.ndarray = field(default_factory=lambda: np.eye(3))  # columns: principal axes in the model frame
    face_pairs: int = 1  # spheres on the largest flat face: the sphere pairs of a face-to-face contact

    @property
    def n_spheres(self) -> int:
        return len(self.sphere_offsets_m)

    @property
    def density_kg_m3(self) -> float:
        return self.mass_kg / self.volume_m3

    def inertia_tensor_model(self) -> np.ndarray:
        """Inertia tensor about the centre of mass in the model frame (kg m^2)."""
        V = self.model_to_body
        return V @ np.diag(self.inertia_kg_m2) @ V.T


def _principal_frame(inertia: np.ndarray):
    """Principal moments and a proper rotation whose columns are the principal axes.

    A tensor that is already diagonal keeps the model axes (so a box stays aligned with its own axes even when
    moments are equal and any frame would do).
    """
    off = inertia - np.diag(np.diag(inertia))
    if np.abs(off).max() <= 1e-12 * np.abs(np.diag(inertia)).max():
        return np.diag(inertia).copy(), np.eye(3)
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    return moments, axes


def _check_positive(name: str, value: float) -> float:
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be a positive number, got {value!r}")
    return float(value)


def box(size_m, density_kg_m3: float, spacing_m: float | None = None, samples_per_edge: int = 4,
        spheres_per_edge: int | None = None, name: str = "box") -> RigidShape:
    """A box ``size_m = (lx, ly, lz)`` of uniform density, spheres on its surface.

    Give either ``spacing_m`` (sphere diameter; edges get ``round(l / spacing)`` spheres, at least 2) or
    ``spheres_per_edge`` (the same number on every edge, radius from the shortest edge). Inertia is the
    analytic solid box: I_x = m (ly^2 + lz^2) / 12 and cyclic. ``samples_per_edge`` sets the volume samples.
    """
    size = np.asarray(size_m, dtype=float).reshape(3)
    for k, v in enumerate(size):
        _check_positive(f"box size[{k}] (m)", v)
    rho = _check_positive("density_kg_m3", density_kg_m3)
    if spheres_per_edge is not None:
        n = np.full(3, max(2, int(spheres_per_edge)))
        radius = float((size / (2 * n)).min())
    else:
        spacing = _check_positive("spacing_m", spacing_m if spacing_m is not None else size.min() / 3)
        n = np.maximum(2, np.rint(size / spacing).astype(int))
        radius = float((size / (2 * n)).min())
    axes = [np.linspace(-size[k] / 2 + radius, size[k] / 2 - radius, n[k]) for k in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    on_surface = np.zeros(gx.shape, dtype=bool)
    for k, g in enumerate((gx, gy, gz)):
        idx = np.indices(gx.shape)[k]
        on_surface |= (idx == 0) | (idx == n[k] - 1)
    offsets = np.stack([gx[on_surface], gy[on_surface], gz[on_surface]], axis=1)

    volume = float(np.prod(size))
    mass = rho * volume
    lx, ly, lz = size
    inertia = mass / 12.0 * np.array([ly**2 + lz**2, lx**2 + lz**2, lx**2 + ly**2])

    ns = max(1, int(samples_per_edge))
    cell = size / ns
    c = [(-size[k] / 2 + cell[k] * (np.arange(ns) + 0.5)) for k in range(3)]
    sx, sy, sz = np.meshgrid(*c, indexing="ij")
    samples = np.stack([sx.ravel(), sy.ravel(), sz.ravel()], axis=1)
    sample_vol = np.full(len(samples), volume / len(samples))
    ns_sorted = np.sort(n)
    return RigidShape(name=name, mass_kg=mass, volume_m3=volume, inertia_kg_m2=inertia,
                      sphere_offsets_m=offsets, sphere_radius_m=radius, sample_offsets_m=samples,
                      sample_volumes_m3=sample_vol, sample_half_extent_m=cell / 2,
                      face_pairs=int(ns_sorted[1] * ns_sorted[2]))


def sphere(radius_m: float, density_kg_m3: float, name: str = "sphere") -> RigidShape:
    """A solid sphere represented by one DEM sphere of the same radius (I = 2/5 m r^2)."""
    r = _check_positive("radius_m", radius_m)
    rho = _check_positive("density_kg_m3", density_kg_m3)
    volume = 4.0 / 3.0 * np.pi * r**3
    mass = rho * volume
    inertia = np.full(3, 0.4 * mass * r**2)
    half = np.full(3, 0.5 * volume ** (1 / 3))
    return RigidShape(name=name, mass_kg=mass, volume_m3=volume, inertia_kg_m2=inertia,
                      sphere_offsets_m=np.zeros((1, 3)), sphere_radius_m=r, sample_offsets_m=np.zeros((1, 3)),
                      sample_volumes_m3=np.array([volume]), sample_half_extent_m=half)


def _tetra_mass_properties(vertices: np.ndarray, triangles: np.ndarray, apex: np.ndarray):
    """Volume, centroid and second moment ``int x x^T dV`` of a convex solid split into tetrahedra (apex, tri).

    For a tetrahedron with vertices v_k: int x_i x_j dV = V/20 (sum_k v_ki v_kj + s_i s_j), s = sum_k v_k
    (Tonon 2004, J. Math. Stat. 1, 8-11).
    """
    a = np.broadcast_to(apex, (len(triangles), 3))
    b, c, d = (vertices[triangles[:, k]] for k in range(3))
    vols = np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))) / 6.0
    volume = vols.sum()
    centroid = (vols[:, None] * (a + b + c + d) / 4.0).sum(axis=0) / volume
    second = np.zeros((3, 3))
    for v, pts in zip(vols, np.stack([a, b, c, d], axis=1)):
        s = pts.sum(axis=0)
        second += v / 20.0 * (pts.T @ pts + np.outer(s, s))
    return volume, centroid, second


def _sample_triangle(p0, p1, p2, spacing):
    """Points on a triangle: its vertices, edge points and an interior lattice, all about ``spacing`` apart."""
    pts = [p0, p1, p2]
    for a, b in ((p0, p1), (p1, p2), (p2, p0)):
        m = int(np.ceil(np.linalg.norm(b - a) / spacing))
        for t in np.arange(1, m) / m:
            pts.append(a + t * (b - a))
    e1 = p1 - p0
    u = e1 / np.linalg.norm(e1)
    nrm = np.cross(e1, p2 - p0)
    nrm /= np.linalg.norm(nrm)
    v = np.cross(nrm, u)
    loc = np.array([[(q - p0) @ u, (q - p0) @ v] for q in (p0, p1, p2)])
    lo, hi = loc.min(axis=0), loc.max(axis=0)
    gu = np.arange(lo[0] + spacing, hi[0], spacing)
    gv = np.arange(lo[1] + spacing, hi[1], spacing)
    if len(gu) and len(gv):
        UU, VV = np.meshgrid(gu, gv, indexing="ij")
        q = np.stack([UU.ravel(), VV.ravel()], axis=1)
        # inside test with a margin of half a spacing from every edge
        inside = np.ones(len(q), dtype=bool)
        for k in range(3):
            a, b = loc[k], loc[(k + 1) % 3]
            c = loc[(k + 2) % 3]
            t = b - a
            en = np.array([-t[1], t[0]]) / np.linalg.norm(t)
            if (c - a) @ en < 0:
                en = -en
            inside &= (q - a) @ en >= 0.5 * spacing
        for qq in q[inside]:
            pts.append(p0 + qq[0] * u + qq[1] * v)
    return pts


def _volume_samples(verts: np.ndarray, com: np.ndarray, spacing: float, inside) -> np.ndarray:
    """Volume samples: the centres of a cubic lattice of ``spacing`` over the vertices' box that ``inside`` keeps
    (the centre of mass alone where none is)."""
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    grids = [np.arange(lo[k] + spacing / 2, hi[k], spacing) for k in range(3)]
    gx, gy, gz = np.meshgrid(*grids, indexing="ij")
    cand = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    samples = cand[inside(cand)]
    return samples if len(samples) else com[None, :]


def _dedupe(points: np.ndarray, tol: float) -> np.ndarray:
    from scipy.spatial import cKDTree

    keep = np.ones(len(points), dtype=bool)
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")     # i < j in each row
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]               # in (i, j) order: the earlier point stays
    for i, j in pairs.tolist():
        if keep[i] and keep[j]:
            keep[j] = False
    return points[keep]


def convex_polyhedron(vertices_m, density_kg_m3: float, spacing_m: float, sample_spacing_m: float | None = None,
                      name: str = "hull") -> RigidShape:
    """A convex solid given by its vertices (scipy ConvexHull), e.g. a ship hull in ship coordinates.

    Mass properties by tetrahedral decomposition from an interior point. Spheres of radius ``spacing/2`` are
    placed on the faces of the solid shrunk inward by one radius (half-space intersection), so their envelope
    is the given hull. Volume samples: a cubic lattice of ``sample_spacing_m`` inside the hull.
    """
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    verts = np.asarray(vertices_m, dtype=float)
    if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 4:
        raise InputError("hull vertices must be an (n >= 4, 3) array of points in metres")
    rho = _check_positive("density_kg_m3", density_kg_m3)
    spacing = _check_positive("spacing_m", spacing_m)
    radius = spacing / 2
    hull = ConvexHull(verts)
    inner_pt = verts[hull.vertices].mean(axis=0)
    volume, com, second = _tetra_mass_properties(verts, hull.simplices, inner_pt)
    mass = rho * volume
    # second moment about the centre of mass -> inertia tensor of the solid
    c_com = rho * (second - volume * np.outer(com, com))
    inertia_model = np.trace(c_com) * np.eye(3) - c_com
    moments, axes = _principal_frame(inertia_model)

    eq = hull.equations.copy()  # n.x + d <= 0 inside, |n| = 1
    if (eq[:, :3] @ com + eq[:, 3]).max() > -radius:
        raise InputError(f"sphere spacing {spacing} m is too coarse for this hull: use a spacing below "
                         f"the hull's smallest thickness")
    shrunk = eq.copy()
    shrunk[:, 3] += radius
    inner = HalfspaceIntersection(shrunk, com).intersections
    inner_hull = ConvexHull(inner)
    pts = []
    for tri in inner_hull.simplices:
        pts.extend(_sample_triangle(*(inner[k] for k in tri), spacing))
    centres = _dedupe(np.array(pts), 0.5 * spacing)
    offsets = (centres - com) @ axes
    on_face = np.abs(centres @ shrunk[:, :3].T + shrunk[:, 3]) < 0.25 * spacing
    face_pairs = int(max(1, on_face.sum(axis=0).max()))

    ss = sample_spacing_m or max(spacing, volume ** (1 / 3) / 8)
    samples = _volume_samples(verts, com, ss, lambda p: (p @ eq[:, :3].T + eq[:, 3]).max(axis=1) <= 0)
    sample_vol = np.full(len(samples), volume / len(samples))
    log.debug("convex polyhedron %s: %d spheres, %d volume samples", name, len(offsets), len(samples))
    return RigidShape(name=name, mass_kg=mass, volume_m3=volume, inertia_kg_m2=moments,
                      sphere_offsets_m=offsets, sphere_radius_m=radius, sample_offsets_m=(samples - com) @ axes,
                      sample_volumes_m3=sample_vol, sample_half_extent_m=np.full(3, ss / 2),
                      model_com_m=com, model_to_body=axes, face_pairs=face_pairs)


def _mesh_mass_properties(vertices: np.ndarray, faces: np.ndarray):
    """Volume, centroid and second moment ``int x x^T dV`` of a closed, outward triangle mesh: signed tetrahedra
    from the origin (so a solid of any shape sums right; Tonon 2004 for each tetrahedron)."""
    b, c, d = (vertices[faces[:, k]] for k in range(3))
    vols = np.einsum("ij,ij->i", b, np.cross(c, d)) / 6.0
    volume = vols.sum()
    s = b + c + d  # the apex (origin) adds nothing
    centroid = (vols[:, None] * s / 4.0).sum(axis=0) / volume
    second = np.einsum("t,tki,tkj->ij", vols / 20.0, np.stack([b, c, d], axis=1), np.stack([b, c, d], axis=1))
    second += np.einsum("t,ti,tj->ij", vols / 20.0, s, s)
    return volume, centroid, second


#: Shears (dx/dz, dy/dz) of the three rays of :func:`inside_mesh`: none lies along a lattice or a mesh edge.
_RAY_TILTS = ((0.0, 0.0), (0.1234567, 0.0654321), (-0.0712345, 0.1123456))


def inside_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Which points lie inside a closed triangle mesh: the parity of the faces a ray crosses, the majority of
    three rays (one along +z, two tilted), so a ray that grazes an edge or a vertex is outvoted."""
    votes = np.zeros(len(points), dtype=np.int64)
    for a, b in _RAY_TILTS:
        shear = np.array([[1.0, 0.0, -a], [0.0, 1.0, -b], [0.0, 0.0, 1.0]])  # the tilted ray becomes vertical
        votes += _inside_along_z(np.asarray(points, float) @ shear.T, vertices @ shear.T, faces, chunk)
    return votes >= 2


def _inside_along_z(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, chunk: int) -> np.ndarray:
    """The parity of the faces a ray from each point along +z crosses. Each point is tested against the faces
    whose (slightly padded) xy bounding box holds it, found through a grid of square bins in xy, so the work
    grows with the points times the faces above and below each, not with all faces (a 375 000-face hull took
    minutes and gigabytes when every point met every face). ``chunk``: points per batch of pairs."""
    t = vertices[faces]
    (x0, y0), (x1, y1), (x2, y2) = (t[:, k, :2].T for k in range(3))
    det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
    ok = np.abs(det) > 1e-300  # faces seen edge-on from below are never crossed
    t, det = t[ok], det[ok]
    out = np.zeros(len(points), dtype=bool)
    if not len(t) or not len(points):
        return out
    lo, hi = t[:, :, :2].min(axis=1), t[:, :, :2].max(axis=1)
    g_lo = np.minimum(lo.min(axis=0), points[:, :2].min(axis=0))
    span = float((np.maximum(hi.max(axis=0), points[:, :2].max(axis=0)) - g_lo).max()) or 1.0
    pad = 1e-9 * span      # a point on a box's edge by round-off still meets the face
    size = max(float(np.median((hi - lo).max(axis=1))), span / 2048.0)
    nbins = int(span / size) + 2
    b_lo = np.floor((lo - pad - g_lo) / size).astype(np.int64).clip(0, nbins - 1)
    b_hi = np.floor((hi + pad - g_lo) / size).astype(np.int64).clip(0, nbins - 1)
    wide = b_hi - b_lo + 1
    per_face = wide[:, 0] * wide[:, 1]
    face_of = np.repeat(np.arange(len(t)), per_face)
    k = np.arange(len(face_of)) - np.repeat(np.cumsum(per_face) - per_face, per_face)
    bins = (b_lo[face_of, 0] + k % wide[face_of, 0]) * nbins + b_lo[face_of, 1] + k // wide[face_of, 0]
    order = np.argsort(bins, kind="stable")
    by_bin, start = face_of[order], np.searchsorted(bins[order], np.arange(nbins * nbins + 1))
    pb = np.floor((points[:, :2] - g_lo) / size).astype(np.int64).clip(0, nbins - 1)
    pbin = pb[:, 0] * nbins + pb[:, 1]
    first, count = start[pbin], start[pbin + 1] - start[pbin]
    (x0, y0), (x1, y1), (x2, y2) = (t[:, k3, :2].T for k3 in range(3))
    for lo_p in range(0, len(points), chunk):
        sel = slice(lo_p, lo_p + chunk)
        n_pairs = count[sel]
        i = np.repeat(np.arange(lo_p, lo_p + len(n_pairs)), n_pairs)
        if not len(i):
            continue
        offs = np.arange(len(i)) - np.repeat(np.cumsum(n_pairs) - n_pairs, n_pairs)
        j = by_bin[first[i] + offs]
        px, py = points[i, 0], points[i, 1]
        d = det[j]
        l0 = ((y1[j] - y2[j]) * (px - x2[j]) + (x2[j] - x1[j]) * (py - y2[j])) / d
        l1 = ((y2[j] - y0[j]) * (px - x2[j]) + (x0[j] - x2[j]) * (py - y2[j])) / d
        l2 = 1.0 - l0 - l1
        # half-open barycentric test, so a ray through a shared edge counts one of its two faces
        hit = (l0 >= 0) & (l1 >= 0) & (l2 > 0)
        z = l0 * t[j, 0, 2] + l1 * t[j, 1, 2] + l2 * t[j, 2, 2]
        crossed = np.bincount(i[hit & (z > points[i, 2])] - lo_p, minlength=len(n_pairs))
        out[sel] = (crossed % 2) == 1
    return out


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from each point p[k] to the triangle (a[k], b[k], c[k]) (Ericson 2005, section 5.1.5, by
    Voronoi regions, vectorised)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    safe = np.where(denom != 0, denom, 1.0)
    v, w = vb / safe, vc / safe
    q = a + v[:, None] * ab + w[:, None] * ac  # inside the face
    with np.errstate(divide="ignore", invalid="ignore"):
        regions = [
            ((d1 <= 0) & (d2 <= 0), a),
            ((d3 >= 0) & (d4 <= d3), b),
            ((d6 >= 0) & (d5 <= d6), c),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + np.nan_to_num(d1 / (d1 - d3))[:, None] * ab),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + np.nan_to_num(d2 / (d2 - d6))[:, None] * ac),
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
             b + np.nan_to_num((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None] * (c - b)),
        ]
    for cond, point in reversed(regions):  # the first region that applies wins
        q = np.where(cond[:, None], point, q)
    return np.linalg.norm(p - q, axis=1)


def distance_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, within: float) -> np.ndarray:
    """Unsigned distance from each point to a triangle mesh, exact up to ``within`` (farther points: at least
    ``within``); the points near each triangle found with a k-d tree of the points, within the triangle's own
    reach (its centre's farthest corner) plus ``within``."""
    from scipy.spatial import cKDTree

    t = vertices[faces]
    centroid = t.mean(axis=1)
    reach = np.linalg.norm(t - centroid[:, None, :], axis=2).max(axis=1)     # each face's own
    # the points near each face, within its own reach: one long face (a deck strip) no longer widens every
    # point's search to its size
    near = cKDTree(points).query_ball_point(centroid, within + reach)
    j = np.repeat(np.arange(len(faces)), [len(ps) for ps in near])
    i = np.fromiter((ii for ps in near for ii in ps), dtype=np.int64, count=len(j))
    out = np.full(len(points), np.inf)
    step = 1 << 21          # pairs at a time: the temporaries of a fine mesh's tens of millions of pairs stay ~1 GB
    for lo in range(0, len(i), step):
        ii, jj = i[lo:lo + step], j[lo:lo + step]
        np.minimum.at(out, ii, _closest_on_triangles(points[ii], t[jj, 0], t[jj, 1], t[jj, 2]))
    return np.minimum(out, max(within, 0.0) if np.isinf(out).any() else np.inf)


#: An edge or corner of a mesh is a feature (it gets its own spheres) where its faces' normals turn by more than this
#: (deg). Face spheres set back one radius from faces that turn by theta leave the envelope r (1/cos(theta/2) - 1)
#: inside the corner: 1.5 % of a radius at 20 deg, so a finely meshed curved surface needs none of its own.
FEATURE_ANGLE_DEG = 20.0


def _face_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    normals = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    lengths = np.linalg.norm(normals, axis=1)
    return normals / np.where(lengths > 0, lengths, 1.0)[:, None]


def _convex_edge_points(verts: np.ndarray, faces: np.ndarray, spacing: float, radius: float) -> np.ndarray:
    """Sphere centres at each corner and along each convex feature edge of a mesh (its faces turning by more than
    :data:`FEATURE_ANGLE_DEG`), one radius from every face that meets there (the corners and edges of the solid
    shrunk by one radius, as :func:`convex_polyhedron` samples them): the stem keeps its sharpness."""
    normals = _face_normals(verts, faces)
    cos_feature = np.cos(np.radians(FEATURE_ANGLE_DEG))
    # corners: vertices whose faces' normals spread by more than the feature angle about their mean
    fv, ff = faces.ravel(), np.repeat(np.arange(len(faces)), 3)
    mean = np.zeros_like(verts)
    np.add.at(mean, fv, normals[ff])
    mean /= np.maximum(np.linalg.norm(mean, axis=1), 1e-300)[:, None]
    spread = np.ones(len(verts))
    np.minimum.at(spread, fv, np.einsum("ij,ij->i", normals[ff], mean[fv]))
    corners = np.flatnonzero(spread < np.cos(np.radians(0.5 * FEATURE_ANGLE_DEG)))
    out = []
    if len(corners):
        order = np.argsort(fv, kind="stable")
        starts = np.searchsorted(fv[order], corners)
        ends = np.searchsorted(fv[order], corners, side="right")
        for vtx, a, b in zip(corners, starts, ends):
            ns = np.unique(np.round(normals[ff[order[a:b]]], 9), axis=0)
            d = np.linalg.lstsq(ns, np.full(len(ns), -radius), rcond=None)[0]
            if np.linalg.norm(d) < 4.0 * radius:
                out.append(verts[vtx] + d)
    # edges shared by two faces that turn convexly by more than the feature angle
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(faces)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    k = np.flatnonzero((edges[1:] == edges[:-1]).all(axis=1))
    a, b, f1, f2 = edges[k, 0], edges[k, 1], owner[k], owner[k + 1]
    n1, n2 = normals[f1], normals[f2]
    cos = np.einsum("ij,ij->i", n1, n2)
    convex = np.einsum("ij,ij->i", verts[faces[f2]].mean(axis=1) - verts[a], n1) <= 1e-12 * spacing
    sharp = (cos < cos_feature) & (cos >= -0.9) & convex  # not a knife edge, whose inward offset runs off
    a, b, n1, n2, cos = a[sharp], b[sharp], n1[sharp], n2[sharp], cos[sharp]
    d = -radius * (n1 + n2) / (1.0 + cos)[:, None]
    m = np.maximum(1, np.ceil(np.linalg.norm(verts[b] - verts[a], axis=1) / spacing).astype(np.int64))
    e = np.repeat(np.arange(len(m)), m + 1)
    t = (np.arange(len(e)) - np.repeat(np.cumsum(m + 1) - (m + 1), m + 1)) / m[e]
    along = verts[a][e] + t[:, None] * (verts[b] - verts[a])[e] + d[e]
    return np.concatenate([np.asarray(out, dtype=float).reshape(-1, 3), along])


def _face_points(verts: np.ndarray, faces: np.ndarray, spacing: float, radius: float) -> np.ndarray:
    """Sphere places on the faces, each set back one radius along its face's inward normal, thinned to one per cube of
    half a spacing (:func:`_one_per_cube`), so the count goes with the surface's area, not with the faces: a face of
    two spacings or more sampled by :func:`_sample_triangle`, a face of half a spacing to two by its corners, edge
    midpoints and centroid, a smaller one (a fine mesh's) by its centroid."""
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 0
    inward = -radius * n / np.where(ok, norm, 1.0)[:, None]
    size = np.linalg.norm(tri - tri[:, [1, 2, 0]], axis=2).max(axis=1)
    pts = [np.asarray(_sample_triangle(*tri[k], spacing)) + inward[k] for k in np.flatnonzero(ok & (size >= 2 * spacing))]
    mid = ok & (size < 2.0 * spacing) & (size >= 0.5 * spacing)
    if mid.any():
        t = tri[mid]
        seven = np.concatenate([t, 0.5 * (t + t[:, [1, 2, 0]]), t.mean(axis=1)[:, None, :]], axis=1)
        pts.append((seven + inward[mid][:, None, :]).reshape(-1, 3))
    fine = ok & (size < 0.5 * spacing)
    pts.append(tri[fine].mean(axis=1) + inward[fine])
    return _one_per_cube(np.concatenate(pts), 0.5 * spacing)


def _one_per_cube(points: np.ndarray, edge: float) -> np.ndarray:
    """The first of ``points`` in each cube of a lattice of ``edge``, in their order."""
    if not len(points):
        return points
    cell = np.floor((points - points.min(axis=0)) / edge).astype(np.int64)
    dims = cell.max(axis=0) + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    _, first = np.unique(key, return_index=True)
    return points[np.sort(first)]


def mesh_solid(vertices_m, faces, density_kg_m3: float, spacing_m: float, sample_spacing_m: float | None = None,
               name: str = "hull", z_max_m: float = np.inf) -> RigidShape:
    """A solid of any shape given as a closed, outward triangle mesh (e.g. a ship hull in ship coordinates).

    Mass properties from signed tetrahedra. Spheres of radius ``spacing/2`` are placed on every face, about
    ``spacing`` apart, and set back along the face's inward normal by one radius, so their envelope is the
    surface with rounded edges (as :func:`convex_polyhedron` does for a convex solid). Volume samples: a cubic
    lattice of ``sample_spacing_m`` inside the mesh. ``z_max_m``: spheres are only wanted up to this height (a hull's
    band above its waterline), so no place higher than it plus a spacing is made or tested; mass properties are the
    whole solid's.
    """
    verts = np.asarray(vertices_m, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 4:
        raise InputError("hull mesh: vertices must be (n, 3) in metres and faces (m >= 4, 3) vertex indices")
    rho = _check_positive("density_kg_m3", density_kg_m3)
    spacing = _check_positive("spacing_m", spacing_m)
    radius = spacing / 2
    volume, com, second = _mesh_mass_properties(verts, faces)
    if not volume > 0:
        raise InputError(f"hull mesh {name}: volume {volume:.4g} m^3; the faces must point outward")
    mass = rho * volume
    c_com = rho * (second - volume * np.outer(com, com))
    inertia_model = np.trace(c_com) * np.eye(3) - c_com
    moments, axes = _principal_frame(inertia_model)

    # the edges' first: the de-duplication keeps them
    low = faces[verts[faces][:, :, 2].min(axis=1) <= z_max_m + spacing]   # the faces the wanted spheres lie on
    cand = np.concatenate([_convex_edge_points(verts, low, spacing, radius), _face_points(verts, low, spacing, radius)])
    cand = cand[cand[:, 2] <= z_max_m + spacing]
    # set back from every face, not only their own: near an edge a point moved in from one face lies outside or
    # too near the other, and goes (before the de-duplication, so it cannot push out a good neighbour)
    near = faces[verts[faces][:, :, 2].min(axis=1) <= z_max_m + 2.0 * spacing]  # all within a radius of a place
    keep = inside_mesh(cand, verts, faces) & (distance_to_mesh(cand, verts, near, radius) >= 0.98 * radius)
    if keep.mean() < 0.25:
        raise InputError(f"sphere spacing {spacing} m is too coarse for hull mesh {name}: {np.sum(~keep)} of "
                         f"{len(cand)} sphere places fall outside it or too near another face; use a spacing below "
                         f"its thinnest part")
    centres = _dedupe(cand[keep], 0.5 * spacing)
    offsets = (centres - com) @ axes

    ss = sample_spacing_m or max(spacing, volume ** (1 / 3) / 8)
    samples = _volume_samples(verts, com, ss, lambda p: inside_mesh(p, verts, faces))
    sample_vol = np.full(len(samples), volume / len(samples))
    log.debug("mesh solid %s: %d faces, %d spheres, %d volume samples", name, len(faces), len(offsets), len(samples))
    return RigidShape(name=name, mass_kg=mass, volume_m3=volume, inertia_kg_m2=moments,
                      sphere_offsets_m=offsets, sphere_radius_m=radius, sample_offsets_m=(samples - com) @ axes,
                      sample_volumes_m3=sample_vol, sample_half_extent_m=np.full(3, ss / 2),
                      model_com_m=com, model_to_body=axes)


def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        k = int(np.argmax(np.diag(R)))
        i, j = (k + 1) % 3, (k + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[k, k] - R[i, i] - R[j, j])
        q = np.empty(4)
        q[0] = (R[j, i] - R[i, j]) / s
        q[1 + k] = 0.25 * s
        q[1 + i] = (R[i, k] + R[k, i]) / s
        q[1 + j] = (R[j, k] + R[k, j]) / s
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def matrix_from_quaternion(q) -> np.ndarray:
    """Rotation matrix (body -> world) of a unit quaternion (w, x, y, z); of quaternions (..., 4) the matrices
    (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)
