"""Analytic hull forms as closed meshes: the hulls of the "your own hull" trials (docs/SHIP.md) and of the tests.

``python -m validation.hull_forms DIR`` writes ``slender.stl`` (a 3 m raked Wigley hull, 0.19 m draught) and
``full.stl`` (a 2.4 m hull with a parallel middle body and full sections, 0.25 m draught) into DIR.

The form: half breadth y = (B/2) f(x) g(z) below the waterline z = T (keel at z = 0), wall-sided above it to the
deck at D, every section moved forward by (z - T) cot(rake), with f = 1 along the parallel middle body (a fraction
``parallel`` of L) and 1 - u^2 beyond it (u from 0 at its end to 1 at the stem), g = 1 - |z/T - 1|^p. With no
parallel body and p = 2 it is the Wigley hull (Journee, "Experiments and calculations on four Wigley hullforms",
Delft University of Technology, report 909, 1992): exact FSICR inputs at T are L, B, LPAR = 0, LBOW = L/2,
Awf = B L / 3, alpha = atan(sqrt(2) B / L), phi1 = phi2 = rake.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

#: The trial hulls: (length, beam, draught, depth, rake deg, parallel fraction, section power).
FORMS = {"slender": (3.0, 0.3, 0.19, 0.3, 30.0, 0.0, 2), "full": (2.4, 0.42, 0.25, 0.36, 30.0, 0.4, 4)}


def raked_form(nx: int, nz: int, *, length=3.0, beam=0.3, draught=0.19, depth=0.3, rake_deg=30.0, parallel=0.0,
               power=2):
    """The form of the module docstring as a watertight trimesh: ``nx`` stations, ``nz`` rows below the waterline."""
    import trimesh

    x = np.linspace(-0.5 * length, 0.5 * length, nx)
    z = np.concatenate([np.linspace(0.0, draught, nz + 1), np.linspace(draught, depth, 4)[1:]])
    X, Z = np.meshgrid(x, z, indexing="ij")
    s = np.minimum(Z - draught, 0.0) / draught
    half_par = 0.5 * parallel * length
    u = np.clip((np.abs(X) - half_par) / (0.5 * length - half_par), 0.0, 1.0)
    Y = 0.5 * beam * (1.0 - u * u) * (1.0 - np.abs(s) ** power)
    port = np.stack([X + (Z - draught) / math.tan(math.radians(rake_deg)), Y, Z], -1).reshape(-1, 3)
    n, nzt = len(port), len(z)
    i, k = np.meshgrid(np.arange(nx - 1), np.arange(nzt - 1), indexing="ij")
    a, b = (i * nzt + k).ravel(), ((i + 1) * nzt + k).ravel()
    side = np.concatenate([np.stack([a, b + 1, b], 1), np.stack([a, a + 1, b + 1], 1)])
    top = np.arange(nx) * nzt + nzt - 1
    deck = np.concatenate([np.stack([top[:-1], top[1:] + n, top[1:]], 1),
                           np.stack([top[:-1], top[:-1] + n, top[1:] + n], 1)])
    faces = np.concatenate([side, side[:, ::-1] + n, deck])
    v = np.vstack([port, port * np.array([1.0, -1.0, 1.0])])
    keep = np.abs(v[faces, 1]).max(axis=1) > 0          # the centre plane's slivers belong to neither side
    mesh = trimesh.Trimesh(v, faces[keep], process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    if mesh.volume < 0:
        mesh.invert()
    assert mesh.is_watertight
    return mesh


def form(name: str, nx: int = 121, nz: int = 24):
    """One of :data:`FORMS` as a mesh."""
    L, B, T, D, rake, par, p = FORMS[name]
    return raked_form(nx, nz, length=L, beam=B, draught=T, depth=D, rake_deg=rake, parallel=par, power=p)


def main(argv=None) -> int:
    out = Path((argv or sys.argv[1:] or ["."])[0])
    out.mkdir(parents=True, exist_ok=True)
    for name in FORMS:
        path = out / f"{name}.stl"
        form(name).export(path)
        print(f"{path}: draught {FORMS[name][2]} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
