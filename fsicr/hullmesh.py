"""FSICR inputs measured on a hull mesh (STL or OBJ) at a draught.

The mesh is read with trimesh, checked (not empty, watertight, normals outward, a plausible length in its unit),
turned into the ship frame (x forward, y to port, z up; keel at z = 0, centreline at y = 0, the stem at the
waterline at x = 0) and cut by horizontal planes. Every quantity comes from waterlines, the sections z = const,
so no cut runs along a face of the centreline plane. Definitions (FSICR 2017, Traficom guidelines on the
application of the ice class rules, section 3.2.2, "Ship parameters"), measured at the draught T:

* **L**: the length of the waterline at T (foremost to aftmost point). The rules ask for the length between
  perpendiculars; for a hull whose rudder post ends the waterline the two agree; otherwise state ``L``.
* **B**: the largest breadth of the waterline at T.
* **LPAR**: the length of the parallel midship body, where the waterline's breadth is B to within ``tolerance``
  (default :data:`PARALLEL_TOLERANCE`, 1e-6 of B: the rounding of a float32 STL, so that a body whose sides are
  drawn parallel counts whole and a curved waterline has none, LPAR = 0, at any spacing of its stations): from its
  aftmost to its foremost vertex.
* **LBOW**: the length of the bow, from the foremost point of the waterline to the forward end of the parallel
  body.
* **Awf**: the area of the waterline of the bow, forward of the parallel body (the breadth integrated over LBOW;
  exact for a mesh, whose waterline is a polygon).
* **alpha**: the angle between the waterline and the centreline at B/4 off the centreline, on the bow (the mean
  of port and starboard).
* **phi1**: the rake of the stem at the centreline: the angle between the stem and the horizontal at T, from the
  foremost points of the centreline at T - dz and T + dz (dz = 1 % of T, less where the hull is shallower).
* **phi2**: the rake of the bow at B/4 off the centreline, the same way (the mean of port and starboard).

Lengths are multiplied by ``scale`` and the area by ``scale**2`` (model to full scale). Imports nothing from the
engine; needs trimesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import FsicrInputError, short_text, unusable_name

#: Metres per unit of the mesh's coordinates.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "ft": 0.3048, "in": 0.0254}
#: Axis names of the orientation options.
AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}
#: Plausible hull lengths (m): a towing-tank model to the largest ships.
LENGTH_RANGE_M = (0.2, 500.0)

#: How close to B (relative) the waterline's breadth must be along the parallel midship body: a few float32 ulps.
#: A looser bound (the 1e-3 of earlier versions) let a curved waterline's flat middle count as parallel, over a
#: length that grew as the mesh was refined (0.05 / 0.075 / 0.09 m at 121 / 241 / 601 stations of a 3 m
#: parabolic waterline, whose LPAR is 0).
PARALLEL_TOLERANCE = 1e-6

#: How each input is measured, for reports.
HOW = {
    "L_m": "waterline length at T",
    "B_m": "largest waterline breadth at T",
    "LPAR_m": "waterline breadth B (to 1e-6) along it",
    "LBOW_m": "forward end of the parallel body to the stem",
    "Awf_m2": "waterline area forward of the parallel body",
    "alpha_deg": "waterline to centreline at B/4",
    "phi1_deg": "stem to horizontal at T, centreline",
    "phi2_deg": "bow to horizontal at T, B/4 off the centreline",
}


@dataclass(frozen=True)
class MeshKeys:
    """What the user calls each option, for messages (command-line flags or scene keys)."""

    file: str = "--mesh"
    unit: str = "--mesh-unit"
    bow: str = "--mesh-bow"
    up: str = "--mesh-up"
    draught: str = "--draught"


@dataclass
class HullMesh:
    """A checked hull mesh in the ship frame, metres: ``vertices`` (n, 3) and ``faces`` (m, 3)."""

    vertices: np.ndarray
    faces: np.ndarray
    source: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def triangles(self) -> np.ndarray:
        return self.vertices[self.faces]

    @property
    def length_m(self) -> float:
        return float(np.ptp(self.vertices[:, 0]))

    @property
    def depth_m(self) -> float:
        return float(self.vertices[:, 2].max())

    @property
    def volume_m3(self) -> float:
        t = self.triangles
        return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)

    @property
    def convex_fill(self) -> float:
        """The mesh's volume over its convex hull's: 1 for a convex solid."""
        from scipy.spatial import ConvexHull

        return self.volume_m3 / float(ConvexHull(self.vertices).volume)

    def trimesh(self):
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def builtin_meshes() -> dict[str, Path]:
    """Hull meshes shipped with the package, by name without the suffix: ``b063`` is the paper's B-063 model
    (1:25, draught 0.44 m) going ahead with Bow A at +x; ``--mesh-bow -x`` turns it to go ahead with Bow B."""
    import importlib.resources

    folder = importlib.resources.files("fsicr") / "ships"
    return {Path(p.name).stem: Path(str(p)) for p in folder.iterdir() if p.name.endswith((".stl", ".obj"))}


def _rotation(bow: str, up: str, keys: MeshKeys) -> np.ndarray:
    """The rotation taking the mesh's bow axis to +x and its up axis to +z."""
    for key, value in ((keys.bow, bow), (keys.up, up)):
        if value not in AXES:
            raise FsicrInputError(f"{key}: {value!r} is not an axis; use one of {', '.join(AXES)}")
    (ib, sb), (iu, su) = AXES[bow], AXES[up]
    if ib == iu:
        raise FsicrInputError(f"{keys.up}: {up!r} is parallel to {keys.bow} {bow!r}; give an up axis at right angles "
                              f"to the bow (e.g. {keys.bow} '+x' with {keys.up} '+z')")
    fwd = np.zeros(3)
    fwd[ib] = sb
    upv = np.zeros(3)
    upv[iu] = su
    port = np.cross(upv, fwd)  # y = z x x
    return np.stack([fwd, port, upv])  # rows: ship axes in mesh coordinates


def stl_problem(p: Path) -> str | None:
    """What makes the file ``p`` no STL, in words, or None where it may be one: an ASCII STL starts with
    ``solid`` and holds ``facet``; a binary STL is 84 bytes of header and count and 50 bytes per triangle (bytes
    beyond them, which some exporters write, are let be)."""
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(1 << 16)
    if head[:5].lower() == b"solid":
        if b"facet" in head:
            return None
        if size < 84:
            return "holds no triangles (a text STL without a facet)"
    if size < 84:
        return f"is not an STL: {size} bytes, and a binary STL has at least 84 (header and triangle count)"
    count = int.from_bytes(head[80:84], "little")
    if count == 0:
        return "holds no triangles (a binary STL whose triangle count is 0)"
    if size < 84 + 50 * count:
        return (f"is not a whole binary STL: its header announces {count} triangles ({84 + 50 * count} bytes) but "
                f"the file holds {size} bytes (cut short, or not an STL)")
    return None


def read_mesh(path, *, unit: str = "m", keys: MeshKeys = MeshKeys(), what: str = "hull") -> HullMesh:
    """Read and check a closed surface mesh (STL or OBJ; a built-in name), in metres, as the file places it:
    not empty, watertight, faces outward."""
    try:
        import trimesh
    except ImportError:  # pragma: no cover - a dependency
        raise FsicrInputError(f"{keys.file}: reading a mesh needs trimesh: pip install trimesh") from None
    p = Path(path)
    builtin = builtin_meshes()
    try:  # a name the file system refuses (too long, a NUL byte) is the user's input, not a crash
        if not p.exists() and p.parent == Path(".") and p.stem in builtin:
            p = builtin[p.stem]
        is_file = p.is_file()
    except (OSError, ValueError) as exc:
        raise FsicrInputError(f"{keys.file}: {unusable_name(str(path), exc, 'file')}; give the path of an STL or "
                              f"OBJ {what}") from None
    if not is_file:
        raise FsicrInputError(f"{keys.file}: no file {short_text(str(path))}; give the path of an STL or OBJ {what} "
                              f"or a built-in one ({', '.join(sorted(builtin))})")
    if p.suffix.lower() not in (".stl", ".obj"):
        raise FsicrInputError(f"{keys.file}: {short_text(p.name)} is not .stl or .obj; export the {what} as STL or "
                              f"OBJ")
    if unit not in UNITS:
        raise FsicrInputError(f"{keys.unit}: {unit!r} is not a length unit; use one of {', '.join(UNITS)}")
    wrong = stl_problem(p) if p.suffix.lower() == ".stl" else None
    if wrong:
        raise FsicrInputError(f"{keys.file}: {short_text(str(p))} {wrong}; export the {what} again as STL or OBJ")
    try:
        mesh = trimesh.load(p, force="mesh", process=True)
    except Exception as exc:  # noqa: BLE001 - any parse failure is the user's file
        raise FsicrInputError(f"{keys.file}: {short_text(str(p))} could not be read as a mesh ({type(exc).__name__}: "
                              f"{str(exc)[:80]}); export the {what} again as STL or OBJ") from None
    if len(getattr(mesh, "faces", ())) == 0:
        raise FsicrInputError(f"{keys.file}: {short_text(str(p))} holds no triangles; export the {what} surface as "
                              f"STL or OBJ")
    if not mesh.is_watertight:
        raise FsicrInputError(f"{keys.file}: {p.name!r} is not watertight ({len(mesh.faces)} triangles, open edges "
                              f"or holes); close the {what} (deck included) before exporting")
    bodies = int(mesh.body_count)
    if bodies > 1:
        raise FsicrInputError(f"{keys.file}: {p.name!r} holds {bodies} separate closed surfaces; a {what} is one "
                              f"body: export it alone, or join the parts into one closed surface")
    out = HullMesh(np.asarray(mesh.vertices, float) * UNITS[unit], np.asarray(mesh.faces, np.int64), source=str(p),
                   meta={"file": str(p), "unit": unit, "triangles": int(len(mesh.faces))})
    if out.volume_m3 <= 0:
        raise FsicrInputError(f"{keys.file}: {p.name!r} is inside out (its faces point inward, volume "
                              f"{out.volume_m3:.4g} m^3); flip the normals before exporting")
    return out


def read_hull_mesh(path, *, unit: str = "m", bow: str = "+x", up: str = "+z", keys: MeshKeys = MeshKeys()) -> HullMesh:
    """Read, check and orient a hull mesh; the stem is put at x = 0 later by :func:`to_stem_frame`."""
    R = _rotation(bow, up, keys)
    hull = read_mesh(path, unit=unit, keys=keys)
    hull.vertices = hull.vertices @ R.T
    hull.meta.update(bow=bow, up=up)
    length = hull.length_m
    lo, hi = LENGTH_RANGE_M
    if not lo <= length <= hi:
        fits = [f"{u!r} ({length / UNITS[unit] * f:.4g} m long)" for u, f in sorted(UNITS.items(), key=lambda i: i[1])
                if lo <= length / UNITS[unit] * f <= hi and u != unit]
        raise FsicrInputError(f"{keys.unit}: the hull is {length:.4g} m long in {unit!r}, outside {lo:g}-{hi:g} m; "
                              f"set {keys.unit} to the mesh's unit: {' or '.join(fits) or 'm'}")
    v = hull.vertices.copy()
    v[:, 2] -= v[:, 2].min()  # keel at z = 0
    v[:, 1] -= 0.5 * (v[:, 1].min() + v[:, 1].max())  # centreline at y = 0
    hull.vertices = v
    return hull


# ---------------------------------------------------------------------------------------------- sections
def waterline_segments(hull: HullMesh, z_m: float) -> np.ndarray:
    """The section of the hull by the plane z = ``z_m``: (n, 2, 2) segments in (x, y). Only the triangles whose
    height range holds ``z_m`` are cut (a few per cent of a fine mesh)."""
    z = hull.vertices[:, 2][hull.faces]
    t = hull.vertices[hull.faces[(z.min(axis=1) <= z_m) & (z.max(axis=1) >= z_m)]]
    d = t[:, :, 2] - z_m
    d = np.where(d == 0.0, 1e-300, d)  # a vertex on the plane counts as just above it: no edge lies in it
    segs = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        cut = (d[:, a] > 0) != (d[:, b] > 0)
        w = d[:, a] / np.where(cut, d[:, a] - d[:, b], 1.0)
        p = t[:, a, :2] + w[:, None] * (t[:, b, :2] - t[:, a, :2])
        segs.append(np.where(cut[:, None], p, np.nan))
    pts = np.stack(segs, axis=1)  # (m, 3 edges, 2): a triangle crossing the plane cuts exactly two edges
    keep = np.isfinite(pts[:, :, 0]).sum(axis=1) == 2
    pts = pts[keep]
    ok = np.isfinite(pts[:, :, 0])
    return pts[ok].reshape(-1, 2, 2)


def breadth_at(segs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The waterline's breadth (largest minus smallest y) at each x."""
    x0, x1 = segs[:, 0, 0], segs[:, 1, 0]
    y0, y1 = segs[:, 0, 1], segs[:, 1, 1]
    lo, hi = np.minimum(x0, x1), np.maximum(x0, x1)
    out = np.zeros(len(x))
    for i, xi in enumerate(x):
        on = (lo <= xi) & (xi <= hi)
        if not on.any():
            continue
        dx = x1[on] - x0[on]
        w = np.where(dx != 0, (xi - x0[on]) / np.where(dx != 0, dx, 1.0), 0.0)
        y = np.concatenate([y0[on] + w * (y1[on] - y0[on]), y1[on][dx == 0]])  # a segment along y: both ends
        out[i] = y.max() - y.min()
    return out


def foremost_x(segs: np.ndarray, y_m: float) -> float:
    """The largest x at which the waterline crosses the line y = ``y_m``."""
    y0, y1 = segs[:, 0, 1], segs[:, 1, 1]
    on = (np.minimum(y0, y1) <= y_m) & (y_m <= np.maximum(y0, y1))
    if not on.any():
        return math.nan
    s = segs[on]
    dy = s[:, 1, 1] - s[:, 0, 1]
    w = np.where(dy != 0, (y_m - s[:, 0, 1]) / np.where(dy != 0, dy, 1.0), 1.0)
    x = s[:, 0, 0] + w * (s[:, 1, 0] - s[:, 0, 0])
    return float(np.max(np.concatenate([x, np.where(dy == 0, np.maximum(s[:, 0, 0], s[:, 1, 0]), -np.inf)])))


def _rake_deg(hull: HullMesh, T: float, y_m: float, dz: float) -> float:
    """Angle between the bow line at offset y and the horizontal at T (deg; 90 = a vertical stem)."""
    lo, hi = foremost_x(waterline_segments(hull, T - dz), y_m), foremost_x(waterline_segments(hull, T + dz), y_m)
    return math.degrees(math.atan2(2.0 * dz, hi - lo))


def to_stem_frame(hull: HullMesh, draught_m: float, keys: MeshKeys = MeshKeys()) -> HullMesh:
    """The hull moved along x so the stem at the waterline (the waterline's foremost point) is at x = 0."""
    check_draught(hull, draught_m, keys)
    x_fp = waterline_segments(hull, draught_m)[:, :, 0].max()
    v = hull.vertices.copy()
    v[:, 0] -= x_fp
    return HullMesh(v, hull.faces, hull.source, {**hull.meta, "draught_m": float(draught_m)})


def check_draught(hull: HullMesh, draught_m: float, keys: MeshKeys = MeshKeys()) -> None:
    if not 0 < draught_m < hull.depth_m:
        raise FsicrInputError(f"{keys.draught}: {draught_m:g} m is not within the hull's depth (0, "
                              f"{hull.depth_m:.4g}) m; give the draught in metres at the mesh's scale")


def measure(hull: HullMesh, draught_m: float, *, scale: float = 1.0, tolerance: float = PARALLEL_TOLERANCE,
            keys: MeshKeys = MeshKeys()) -> dict:
    """The FSICR waterline inputs of the hull at ``draught_m`` (module docstring), times ``scale``."""
    check_draught(hull, draught_m, keys)
    if not scale > 0:
        raise FsicrInputError(f"--scale: must be > 0 (got {scale}); e.g. 25 for a 1:25 model")
    T = float(draught_m)
    segs = waterline_segments(hull, T)
    xs = np.unique(segs[:, :, 0])
    b = breadth_at(segs, xs)
    B = float(b.max())
    full = xs[b >= (1.0 - tolerance) * B]
    x_fp, x_ap = float(xs.max()), float(xs.min())
    x_fs, x_as = float(full.max()), float(full.min())
    if x_fs - x_as <= tolerance * (x_fp - x_ap):     # the one widest station, seen twice by the plane's round-off
        x_fs = x_as = 0.5 * (x_fs + x_as)
    bow = xs >= x_fs
    awf = float(np.trapezoid(b[bow], xs[bow])) if hasattr(np, "trapezoid") else float(np.trapz(b[bow], xs[bow]))
    q, eps = 0.25 * B, 1e-3 * B
    alphas = []
    for side in (1.0, -1.0):
        x_in, x_out = foremost_x(segs, side * (q - eps)), foremost_x(segs, side * (q + eps))
        alphas.append(math.degrees(math.atan2(2.0 * eps, x_in - x_out)))
    dz = min(0.01 * T, 0.5 * (hull.depth_m - T))
    phi1 = _rake_deg(hull, T, 0.0, dz)
    phi2 = 0.5 * (_rake_deg(hull, T, q, dz) + _rake_deg(hull, T, -q, dz))
    s = float(scale)
    return {"L_m": (x_fp - x_ap) * s, "B_m": B * s, "T_m": T * s, "LPAR_m": (x_fs - x_as) * s,
            "LBOW_m": (x_fp - x_fs) * s, "Awf_m2": awf * s * s, "alpha_deg": float(np.mean(alphas)),
            "phi1_deg": phi1, "phi2_deg": phi2}


def write_stl(path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A binary STL of a triangle mesh (trimesh's exporter)."""
    import trimesh

    trimesh.Trimesh(vertices, faces, process=False).export(str(path))
