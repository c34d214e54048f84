"""What a scene must hold before a model is built on it, beyond what its schema checks one key at a time: the
bodies inside the box and clear of one another (:func:`check_bodies`), the closed tank of floating bodies on one level
(:func:`check_tank`), gravity alone driving a free surface (:func:`check_free_surface_forces`). Each refusal is one
line naming the key and a value that works.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.errors import InputError
from iceresist.scene.blocks import half_extent
from iceresist.scene.schema import Scene


def fmt_g(v) -> str:
    """A number in six significant digits, for the messages of the bodies' checks."""
    return f"{float(v):.6g}"


def overlap_at_start(a, b, ma=None, mb=None) -> bool:
    """Whether bodies ``a`` and ``b`` of the scene share volume at t = 0 (a mesh body counts as its bounding box:
    the check errs on the side of refusing)."""
    ca, cb = np.asarray(a.position_m, dtype=float), np.asarray(b.position_m, dtype=float)
    ha, hb = half_extent(a, ma), half_extent(b, mb)
    if a.shape == "sphere" and b.shape == "sphere":
        return float(np.linalg.norm(ca - cb)) < a.radius_m + b.radius_m
    if a.shape != "sphere" and b.shape != "sphere":
        return bool((np.abs(ca - cb) < ha + hb).all())
    s, c, h = (a, cb, hb) if a.shape == "sphere" else (b, ca, ha)
    centre = np.asarray(s.position_m, dtype=float)
    nearest = np.clip(centre, c - h, c + h)
    return float(np.linalg.norm(centre - nearest)) < s.radius_m


def check_bodies(scene: Scene, box_m, meshes: dict | None = None) -> None:
    """Refuse bodies that reach outside the box ``box_m`` (m), overlap at t = 0, or give a velocity to a fixed
    body: an :class:`InputError` naming the key and a value that works. ``meshes``: body index -> its
    :func:`body_mesh`."""
    box_m = np.asarray(box_m, dtype=float)
    meshes = meshes or {}
    for i, b in enumerate(scene.bodies):
        c, h = np.asarray(b.position_m, dtype=float), half_extent(b, meshes.get(i))
        key = {"sphere": "radius_m", "box": "size_m", "mesh": "mesh_unit"}[b.shape]
        if b.motion == "fixed" and any(b.velocity_m_s):
            raise InputError(f"bodies[{i}].velocity_m_s: body {b.name!r} is fixed (at rest): leave velocity_m_s "
                             f"out, or set motion = \"prescribed\" to move it at {list(b.velocity_m_s)} m/s")
        for a, axis in enumerate("xyz"):
            if 2 * h[a] >= box_m[a]:
                raise InputError(f"bodies[{i}].{key}: body {b.name!r} is {fmt_g(2 * h[a])} m across along {axis}, "
                                 f"not less than the domain's {fmt_g(box_m[a])} m: make it smaller than that")
            if c[a] - h[a] < 0.0 or c[a] + h[a] > box_m[a]:
                fix = c.copy()
                fix[a] = min(max(c[a], h[a]), box_m[a] - h[a])
                raise InputError(f"bodies[{i}].position_m: body {b.name!r} reaches {axis} = {fmt_g(c[a] - h[a])} .. "
                                 f"{fmt_g(c[a] + h[a])} m, outside the domain 0 .. {fmt_g(box_m[a])} m: use e.g. "
                                 f"position_m = [{', '.join(fmt_g(v) for v in fix)}]")
    for j, b in enumerate(scene.bodies):
        for i in range(j):
            a = scene.bodies[i]
            if not overlap_at_start(a, b, meshes.get(i), meshes.get(j)):
                continue
            ca, ha, hb = (np.asarray(a.position_m, dtype=float), half_extent(a, meshes.get(i)),
                          half_extent(b, meshes.get(j)))
            fix = np.asarray(b.position_m, dtype=float).copy()
            gap = 0.05 * float(min(ha.min(), hb.min()))
            ahead, behind = ca[0] + ha[0] + hb[0] + gap, ca[0] - ha[0] - hb[0] - gap
            fix[0] = ahead if ahead + hb[0] <= box_m[0] else behind
            raise InputError(f"bodies[{j}].position_m: body {b.name!r} overlaps body {a.name!r} at t = 0: move it "
                             f"clear, e.g. position_m = [{', '.join(fmt_g(v) for v in fix)}]")


def check_tank(scene, u) -> None:
    """What a free surface with bodies on one level takes: a closed tank of walls, water over the whole floor,
    still at the start, gravity at most 0.01 in lattice units."""
    fl, fs = scene.fluid, scene.free_surface
    for name, face in scene.domain.faces.items():
        if face.kind != "wall":
            raise InputError(f"domain.faces.{name}: a free-surface scene with [[bodies]] is a closed tank: set "
                             f"{name} = \"wall\" (not {face.kind!r})")
    if fs.column_length_m is not None:
        raise InputError("free_surface.column_length_m: a scene with [[bodies]] starts with water over the whole "
                         "floor: leave column_length_m out")
    if any(fl.initial_velocity_m_s):
        raise InputError("fluid.initial_velocity_m_s: a free-surface scene with [[bodies]] starts from still "
                         "water: leave initial_velocity_m_s out")
    g = -float(fl.gravity_m_s2[2])
    g_lattice = float(u.acceleration_to_lattice(g))
    if g_lattice > 0.01:
        raise InputError(f"numerics.dt_s: gravity is {g_lattice:.4g} in lattice units (g dt^2 / dx), above "
                         f"0.01: use a smaller time step, numerics.dt_s <= {fmt_g(math.sqrt(0.01 * u.dx_m / g))} s")


def check_free_surface_forces(scene: Scene) -> None:
    """A free surface is driven by gravity alone, along -z: name the key otherwise."""
    fl = scene.fluid
    gx, gy, gz = fl.gravity_m_s2
    if gx != 0.0 or gy != 0.0 or not gz < 0.0:
        raise InputError(f"fluid.gravity_m_s2: the free surface needs gravity along -z, e.g. [0, 0, -9.81], "
                         f"not {list(fl.gravity_m_s2)}")
    if any(fl.body_force_N_m3):
        raise InputError("fluid.body_force_N_m3: a free-surface scene is driven by gravity alone; "
                         "leave the body force out")
