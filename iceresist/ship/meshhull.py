"""A hull given as a closed surface mesh (STL or OBJ): ``ship.hull = "mesh"``.

The mesh is read and checked by :mod:`fsicr.hullmesh` (trimesh; watertight, outward, a plausible length in its
unit, turned by ``ship.mesh_bow`` and ``ship.mesh_up``) and moved into the ship frame of
:mod:`iceresist.ship.hull`: x forward, y to port, z up, origin on the centreline at the keel below the stem at
the waterline. :class:`MeshHull` answers what the models ask of a hull (draught, beam, waterline length, bow
length, midship area, displacement, the waterline polygon, the FSICR inputs), so a mesh hull runs wherever the
parametric B-063 runs: the DEM sees spheres on its faces (:func:`iceresist.dem.mesh_solid`; a convex mesh takes
:func:`iceresist.dem.convex_polyhedron`, the B-063 path), and tier 2's fluid sees a convex mesh as one convex
polyhedron and any other as a union of convex slabs along its length (:meth:`MeshHull.fluid_pieces`,
:class:`iceresist.coupling.ConvexUnion`).
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import fsicr
from fsicr import hullmesh
from fsicr.errors import FsicrInputError
from iceresist.dem.bodies import inside_mesh
from iceresist.errors import InputError

#: The scene keys of the mesh options, for messages.
SCENE_KEYS = hullmesh.MeshKeys(file="ship.mesh_file", unit="ship.mesh_unit", bow="ship.mesh_bow", up="ship.mesh_up",
                               draught="ship.draught_m")
#: Heights at which the immersed sections are integrated (midpoint rule) for the midship area.
SECTION_LEVELS = 64


def resolve_mesh_path(text: str, scene_source: str | None = None) -> str:
    """A mesh path as given, else relative to the scene file's folder, else a built-in mesh name."""
    p = Path(text)
    try:
        if p.is_file() or p.is_absolute():
            return str(p)
        if scene_source:
            beside = Path(scene_source).parent / p
            if beside.is_file():
                return str(beside)
    except (OSError, ValueError):  # a name the file system refuses (too long, ...): the reader names it
        pass
    return text  # a built-in name (b063), or a missing file that the reader names


def scaled_inputs(inputs: dict, scale: float) -> dict:
    """FSICR inputs at model scale to ``scale`` x: lengths x scale, the area x scale^2, angles as they are."""
    s = float(scale)
    return {k: v * (s * s if k == "Awf_m2" else 1.0 if k.endswith("_deg") else s) for k, v in inputs.items()}


def _volume_below(tris: np.ndarray, z_m: float) -> float:
    """Volume of a closed outward mesh below the plane z = ``z_m``, by the divergence theorem with the field
    (0, 0, min(z, z_m)), whose divergence is 1 below the plane and 0 above: no cap is needed."""
    total = 0.0
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])  # 2 A n_unit
    zmin, zmax = tris[:, :, 2].min(axis=1), tris[:, :, 2].max(axis=1)
    below, above = zmax <= z_m, zmin >= z_m
    # whole faces: int min(z, z_m) n_z dA = n_z (A z_centroid) or n_z A z_m
    total += (0.5 * n[below, 2] * tris[below, :, 2].mean(axis=1)).sum()
    total += (0.5 * n[above, 2] * z_m).sum()
    for k in np.flatnonzero(~below & ~above):
        t = tris[k]
        poly_lo, poly_hi = _clip(t, z_m)
        for poly, f in ((poly_lo, None), (poly_hi, z_m)):
            for i in range(1, len(poly) - 1):
                a, b, c = poly[0], poly[i], poly[i + 1]
                area_nz = 0.5 * np.cross(b - a, c - a)[2]
                total += area_nz * ((a[2] + b[2] + c[2]) / 3.0 if f is None else f)
    return float(total)


def _clip(t: np.ndarray, z_m: float) -> tuple[list, list]:
    """A triangle split by the plane z = ``z_m`` into the polygons below and above (vertex order kept)."""
    lo, hi = [], []
    for i in range(3):
        p, q = t[i], t[(i + 1) % 3]
        (lo if p[2] <= z_m else hi).append(p)
        if (p[2] - z_m) * (q[2] - z_m) < 0:
            x = p + (z_m - p[2]) / (q[2] - p[2]) * (q - p)
            lo.append(x)
            hi.append(x)
    return lo, hi


def _chain(segs: np.ndarray) -> np.ndarray:
    """The longest closed loop of a waterline's segments, in order (n, 2)."""
    key = lambda p: (round(float(p[0]), 9), round(float(p[1]), 9))  # noqa: E731
    nbrs: dict = {}
    for a, b in segs:
        ka, kb = key(a), key(b)
        if ka == kb:
            continue
        nbrs.setdefault(ka, []).append(kb)
        nbrs.setdefault(kb, []).append(ka)
    seen, best = set(), []
    for start in nbrs:
        if start in seen:
            continue
        loop, prev, cur = [start], None, start
        seen.add(start)
        while True:
            nxt = next((k for k in nbrs[cur] if k != prev and k not in seen), None)
            if nxt is None:
                break
            loop.append(nxt)
            seen.add(nxt)
            prev, cur = cur, nxt
        if len(loop) > len(best):
            best = loop
    return np.array(best, dtype=float)


@dataclass
class MeshHull:
    """A hull mesh in the ship frame at its draught (metres); the interface of
    :class:`iceresist.ship.hull.HullGeometry` that the models and post-processing use."""

    mesh: hullmesh.HullMesh
    draught_m: float
    name: str = "mesh hull"
    inputs: dict = field(init=False)
    #: the mesh's edges and the excess test's lattice, found once (a fine mesh's take seconds)
    _edges: tuple | None = field(default=None, init=False, repr=False)
    _lattice: tuple | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        self.inputs = hullmesh.measure(self.mesh, self.draught_m, keys=SCENE_KEYS)
        t = self.mesh.triangles
        self._volume = _volume_below(t, self.draught_m)
        segs = [hullmesh.waterline_segments(self.mesh, (k + 0.5) * self.draught_m / SECTION_LEVELS)
                for k in range(SECTION_LEVELS)]
        xs = np.linspace(self.mesh.vertices[:, 0].min(), self.mesh.vertices[:, 0].max(), 201)
        areas = sum(hullmesh.breadth_at(s, xs) for s in segs) * self.draught_m / SECTION_LEVELS
        self._midship_area = float(areas.max())
        self._waterline = _chain(hullmesh.waterline_segments(self.mesh, self.draught_m))
        self.convex_fraction = float(self.mesh.convex_fill)

    @classmethod
    def from_file(cls, path: str, draught_m: float, *, unit: str = "m", bow: str = "+x", up: str = "+z",
                  scale: float = 1.0, scene_source: str | None = None,
                  keys: hullmesh.MeshKeys = SCENE_KEYS, name: str | None = None) -> "MeshHull":
        """Read, check and place a hull mesh, its lengths divided by ``scale`` (a full-scale mesh run as a 1:25
        model: 25) and ``draught_m`` the model's; one-line :class:`InputError` naming the key, by default the
        scene's, on bad input. The same file read with the same options again (a sweep's cases, a scene and its
        model) is read once."""
        resolved = resolve_mesh_path(path, scene_source)
        try:
            st = Path(resolved).stat()
            stamp = (st.st_mtime_ns, st.st_size)
        except (OSError, ValueError):
            stamp = None  # a built-in name, or a path the reader refuses in one line
        return _read_placed(cls, resolved, stamp, float(draught_m), unit, bow, up, float(scale), keys,
                            name or Path(path).stem)

    # -- convex pieces for the fluid (tier 2) -----------------------------------------------------------
    def convex_pieces(self, slabs: int) -> list[np.ndarray]:
        """The hull cut into ``slabs`` equal slabs along x, each slab's part as the vertices of its convex hull
        (the mesh's vertices in the slab and its edges' crossings of the two cut planes)."""
        from scipy.spatial import ConvexHull

        v = self.mesh.vertices
        a, b = self._edge_ends()
        lo, hi = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
        cuts = np.linspace(v[:, 0].min(), v[:, 0].max(), slabs + 1)
        crossings = []
        for xc in cuts:
            on = (lo <= xc) & (xc <= hi) & (lo < hi)     # only the edges across the plane
            aa, bb = a[on], b[on]
            pts = aa + ((xc - aa[:, 0]) / (bb[:, 0] - aa[:, 0]))[:, None] * (bb - aa)
            pts[:, 0] = xc
            crossings.append(pts)
        pieces = []
        for k in range(slabs):
            pts = np.vstack([v[(v[:, 0] >= cuts[k]) & (v[:, 0] <= cuts[k + 1])], crossings[k], crossings[k + 1]])
            pieces.append(pts[ConvexHull(pts).vertices] if len(pts) > 64 else pts)
        return pieces

    def _edge_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """The ends of every edge of the mesh, once (a fine mesh's 1.5 M edges take seconds to find)."""
        if self._edges is None:
            f = self.mesh.faces
            e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
            key = np.unique(e[:, 0] * np.int64(len(self.mesh.vertices)) + e[:, 1])
            n = np.int64(len(self.mesh.vertices))
            v = self.mesh.vertices
            self._edges = (v[key // n], v[key % n])
        return self._edges

    def union_excess(self, pieces: list[np.ndarray], samples: int = 40) -> float:
        """How much more the union of the pieces' convex hulls holds than the mesh, as a fraction of the mesh's
        volume (points of a lattice of ``samples`` along the longest side)."""
        from scipy.spatial import ConvexHull

        cached = self._lattice
        if cached is None or cached[0] != samples:  # the lattice and what of it the mesh holds, once per hull
            v = self.mesh.vertices
            lo, hi = v.min(axis=0), v.max(axis=0)
            h = float(np.max(hi - lo)) / samples
            g = np.stack(np.meshgrid(*[np.arange(lo[k] + h / 2, hi[k], h) for k in range(3)], indexing="ij"), -1)
            p = g.reshape(-1, 3)
            self._lattice = cached = (samples, p, inside_mesh(p, v, self.mesh.faces))
        _, p, in_mesh = cached
        in_union = np.zeros(len(p), dtype=bool)
        for piece in pieces:
            eq = ConvexHull(piece).equations
            near = np.flatnonzero((p[:, 0] >= piece[:, 0].min()) & (p[:, 0] <= piece[:, 0].max()))  # its slab's
            in_union[near] |= (p[near] @ eq[:, :3].T + eq[:, 3]).max(axis=1) <= 1e-12
        return float((in_union & ~in_mesh).sum() / max(in_mesh.sum(), 1))

    def fluid_pieces(self, tolerance: float = 0.01, most: int = 256) -> tuple[list[np.ndarray], float]:
        """Convex pieces for the fluid: one (the mesh) if it is convex, else slabs doubled from 8 until their union
        holds at most ``tolerance`` more than the mesh; (pieces, excess). A mesh whose sections are not convex
        keeps an excess however thin the slabs: refused naming ``ship.tier``."""
        if self.is_convex:
            return [self.mesh.vertices], 0.0
        slabs = 8
        while True:
            pieces = self.convex_pieces(slabs)
            excess = self.union_excess(pieces)
            if excess <= tolerance:
                return pieces, excess
            if slabs >= most:
                raise InputError(f"ship.tier: tier 2 sees a hull as convex slabs along its length, and the "
                                 f"{most} slabs of {self.name!r} still hold {100 * excess:.1f} % more than it (its "
                                 f"cross-sections are not convex); run it at tier = 1")
            slabs *= 2

    # -- what the models ask of a hull ---------------------------------------------------------------
    @property
    def is_convex(self) -> bool:
        """The mesh fills its convex hull (to 1e-6): tier 2 sees it as a convex polyhedron."""
        return self.convex_fraction > 1.0 - 1e-6

    @property
    def beam_m(self) -> float:
        return self.inputs["B_m"]

    @property
    def waterline_length_m(self) -> float:
        return self.inputs["L_m"]

    @property
    def end_length_m(self) -> float:
        """LBOW: from the end of the parallel body to the stem."""
        return self.inputs["LBOW_m"]

    @property
    def parallel_length_m(self) -> float:
        return self.inputs["LPAR_m"]

    @property
    def length_overall_m(self) -> float:
        return self.mesh.length_m

    @property
    def depth_m(self) -> float:
        return self.mesh.depth_m

    @property
    def freeboard_m(self) -> float:
        return self.depth_m - self.draught_m

    @property
    def midship_area_m2(self) -> float:
        """The largest immersed cross-section (m^2), integrated over 64 heights at 201 stations."""
        return self._midship_area

    @property
    def prismatic_length_m(self) -> float:
        """V / A_s (m): the spacing of the hull's long-wave source and sink (:mod:`iceresist.ship.tank`)."""
        return self._volume / self._midship_area

    def volume_m3(self) -> float:
        """Displacement volume below the waterline (m^3), exact for the mesh."""
        return self._volume

    def vertices(self) -> np.ndarray:
        return self.mesh.vertices

    @property
    def faces(self) -> np.ndarray:
        return self.mesh.faces

    def waterline_polygon(self) -> np.ndarray:
        """The waterline at the draught (x, y), in order."""
        return self._waterline

    def fsicr_inputs(self, scale: float = 25.0) -> dict:
        """The FSICR R_CH inputs measured on the mesh (:mod:`fsicr.hullmesh`), at full scale."""
        return scaled_inputs(self.inputs, scale)

    def fsicr_ship(self, scale: float = 25.0, name: str | None = None):
        return fsicr.Ship(name=name or self.name, **self.fsicr_inputs(scale))

    def sha256(self) -> str:
        """Fingerprint of the placed mesh (vertices and faces), for the result file."""
        h = hashlib.sha256(np.ascontiguousarray(self.mesh.vertices).tobytes())
        h.update(np.ascontiguousarray(self.mesh.faces).tobytes())
        return h.hexdigest()

    def describe(self) -> dict:
        """The hull's entry in a run's metadata."""
        return {"kind": "mesh", "mesh_file": self.mesh.meta.get("file", ""), "mesh_sha256": self.sha256(),
                "mesh_unit": self.mesh.meta.get("unit", "m"), "mesh_bow": self.mesh.meta.get("bow", "+x"),
                "mesh_up": self.mesh.meta.get("up", "+z"),
                "mesh_scale": float(self.mesh.meta.get("scale", 1.0)), "triangles": int(len(self.mesh.faces)),
                "length_overall_m": self.length_overall_m, "beam_m": self.beam_m, "draught_m": self.draught_m,
                "parallel_length_m": self.parallel_length_m, "end_length_m": self.end_length_m,
                "waterline_length_m": self.waterline_length_m, "freeboard_m": self.freeboard_m,
                "midship_area_m2": self.midship_area_m2, "volume_m3": self.volume_m3(),
                "convex_fraction": self.convex_fraction, "fsicr_inputs_model_scale": dict(self.inputs),
                "waterline_polygon_m": self._waterline.tolist()}


@dataclass(frozen=True)
class HullRecord:
    """A mesh hull as a run's metadata describes it (:meth:`MeshHull.describe`): what post-processing and
    reports ask of a hull, without the mesh file."""

    data: dict

    def __getattr__(self, name):
        try:
            return self.data[name]
        except KeyError:
            raise AttributeError(name) from None

    @property
    def prismatic_length_m(self) -> float:
        return self.data["volume_m3"] / self.data["midship_area_m2"]

    def waterline_polygon(self) -> np.ndarray:
        return np.asarray(self.data["waterline_polygon_m"], dtype=float)

    def fsicr_inputs(self, scale: float = 25.0) -> dict:
        return scaled_inputs(self.data["fsicr_inputs_model_scale"], scale)


@functools.lru_cache(maxsize=4)
def _read_placed(cls, resolved: str, stamp, draught_m: float, unit: str, bow: str, up: str, scale: float,
                 keys: hullmesh.MeshKeys, name: str) -> MeshHull:
    """:meth:`MeshHull.from_file`, remembered for the last few (file, modification time, options)."""
    try:
        mesh = hullmesh.read_hull_mesh(resolved, unit=unit, bow=bow, up=up, keys=keys)
        if scale != 1.0:
            mesh.vertices = mesh.vertices / scale
            mesh.meta["scale"] = scale
        mesh = hullmesh.to_stem_frame(mesh, draught_m, keys=keys)
        return cls(mesh, draught_m, name=name)
    except FsicrInputError as exc:
        raise InputError(str(exc)) from None
