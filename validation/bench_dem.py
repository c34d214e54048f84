"""DEM benchmark: sphere-steps and contacts per second for the paper's 88 % brash-ice channel with a hull in it.

4096 cubes of 41 mm (32 x 128 over 1.39 m x 5.56 m, 950 kg/m^3, 2 x 2 x 2 or 3 x 3 x 3 surface spheres) float
at their draft in tier-1 water; a box-like convex hull with a wedge bow (3.5 m x 0.7 m) moves at 1 knot as a
kinematic body with its stem ``--bow-in`` metres (default 0.5) into the channel, the cubes it would overlap left
out, so the bow's faces meet the ice from the first steps: the timed steps hold contacts (ice on the hull and ice
on ice), whose count per second stands beside the sphere-steps per second. Timed after a warm-up step, compile
time apart.

    python -m validation.bench_dem [--backend cpu|cuda] [--precision float64] [--n 4096] [--steps 20]
                                   [--bow-in 0.5] [--json]
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time

import numpy as np

KNOT_M_S = 0.514


def add_arguments(parser: argparse.ArgumentParser):
    parser.add_argument("--spheres-per-edge", type=int, default=3, help="spheres per cube edge (2: 8, 3: 26)")
    parser.add_argument("--dt", type=float, default=2e-3, help="step passed to DEMSystem.step (s)")
    parser.add_argument("--bow-in", type=float, default=0.5, metavar="M",
                        help="how far the stem starts inside the channel (m; default 0.5)")


def hull_vertices(length=3.5, beam=0.7, depth=0.3, bow_length=0.7, x_stern=0.0, z_keel=-0.2):
    """A convex box-like hull with a wedge bow, ship coordinates (x forward, keel at z_keel)."""
    b2 = beam / 2
    xs_bow = x_stern + length - bow_length
    pts = []
    for z in (z_keel, z_keel + depth):
        pts += [(x_stern, -b2, z), (x_stern, b2, z), (xs_bow, -b2, z), (xs_bow, b2, z),
                (x_stern + length, -0.05, z), (x_stern + length, 0.05, z)]
    return np.array(pts)


def _world_spheres(shape, position_m) -> np.ndarray:
    """Sphere centres (n, 3) of ``shape`` placed at ``position_m`` without rotation (DEMSystem.add_body)."""
    return (np.asarray(position_m, float) + shape.model_com_m
            + shape.sphere_offsets_m @ shape.model_to_body.T)


def build_scene(n_cubes=4096, spheres_per_edge=3, backend="cpu", precision="float64", bow_in_m=0.5):
    """The channel of ``n_cubes`` cubes and the hull with its stem ``bow_in_m`` into it; the cubes whose spheres the
    hull's would touch at the start are left out. Returns (system, hull body, cubes placed)."""
    from scipy.spatial import cKDTree

    from iceresist.dem import ContactParameters, DEMSystem, Water, box, convex_polyhedron

    a, rho = 0.041, 950.0
    width, length = 1.39, 5.56
    ny = max(1, int(round(math.sqrt(n_cubes / 4))))
    nx = int(math.ceil(n_cubes / ny))
    s = DEMSystem(backend=backend, precision=precision,
                  ice_ice=ContactParameters(normal_stiffness_N_m=2e4, restitution=0.3, friction=0.35),
                  ice_ship=ContactParameters(normal_stiffness_N_m=2e4, restitution=0.3, friction=0.05))
    cube = box((a, a, a), rho, spheres_per_edge=spheres_per_edge)
    hull = convex_polyhedron(hull_vertices(), 500.0, spacing_m=0.03, sample_spacing_m=0.1)
    hull_at = (-3.5 + bow_in_m, 0.0, 0.0)      # the stem (x = 3.5 in the hull's frame) bow_in_m past x = 0
    near = cKDTree(_world_spheres(hull, hull_at))
    reach = cube.sphere_radius_m + hull.sphere_radius_m
    z_eq = a / 2 - rho / 1000.0 * a
    k = placed = 0
    for i in range(nx):
        for j in range(ny):
            if k == n_cubes:
                break
            k += 1
            at = ((i + 0.5) * length / nx, (j + 0.5) * width / ny - width / 2, z_eq)
            if np.isfinite(near.query(_world_spheres(cube, at), distance_upper_bound=reach)[0]).any():
                continue                        # the hull stands where this cube would float
            s.add_body(cube, at)
            placed += 1
    ship = s.add_body(hull, hull_at, (KNOT_M_S, 0, 0), kinematic=True, material="ship")
    s.set_water(Water())
    return s, ship, placed


def run(args) -> list[dict]:
    """One measurement per precision (``args.precision``: one name, or the dispatcher's list of them)."""
    precisions = [args.precision] if isinstance(args.precision, str) else list(args.precision)
    return [measure(args, p) for p in precisions]


def measure(args, precision: str) -> dict:
    s, ship, placed = build_scene(args.n, getattr(args, "spheres_per_edge", 3), args.backend, precision,
                                  getattr(args, "bow_in", 0.5))
    dt = getattr(args, "dt", 2e-3)
    t0 = time.perf_counter()
    s.step(dt)  # warm-up: compiles the kernels
    compile_s = time.perf_counter() - t0
    sub0 = s.substeps_taken
    contacts = 0
    force = np.zeros(3)
    t0 = time.perf_counter()
    for _ in range(args.steps):
        s.step(dt)
        contacts += s.contact_count() * s.last_substeps
        force += s.ice_force_on(ship)
    seconds = time.perf_counter() - t0
    substeps = s.substeps_taken - sub0
    ns = s.n_spheres
    return {
        "name": "dem", "backend": s.describe()["backend"], "precision": precision, "bodies": s.n_bodies,
        "cubes": placed, "bow_in_m": getattr(args, "bow_in", 0.5),
        "spheres": ns, "steps": args.steps, "substeps": substeps, "substep_s": s.substep_s(),
        "seconds": seconds, "compile_seconds": compile_s,
        "sphere_steps_per_s": ns * substeps / seconds,
        "contacts_per_s": contacts / seconds,
        "contacts_per_substep": contacts / max(substeps, 1), "contacts_last": s.contact_count(),
        "ice_force_N": s.ice_force_on(ship).tolist(), "ice_force_mean_N": (force / max(args.steps, 1)).tolist(),
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="cpu", choices=["auto", "cpu", "cuda"])
    p.add_argument("--precision", default="float64", choices=["float32", "float64"])
    p.add_argument("--n", type=int, default=4096, help="number of ice cubes")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--json", action="store_true")
    add_arguments(p)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    for r in run(args):
        if args.json:
            print(json.dumps(r))
        else:
            print(f"{r['name']} {r['backend']} {r['precision']}: {r['bodies']} bodies, {r['spheres']} spheres, "
                  f"{r['substeps']} sub-steps in {r['seconds']:.2f} s: {r['sphere_steps_per_s']:.3e} sphere-steps/s, "
                  f"{r['contacts_per_s']:.3e} contacts/s ({r['contacts_per_substep']:.0f} contacts per sub-step, "
                  f"mean ice force on the hull {r['ice_force_mean_N'][0]:+.3g} N along x; compile "
                  f"{r['compile_seconds']:.1f} s)")


if __name__ == "__main__":
    main()
