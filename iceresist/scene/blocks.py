"""The blocks a scene asks for: its level-0 grid, the regions of its ``[refinement]`` and the octree they give (paper
section 2.5); a scene without ``[refinement]`` is the octree of one level (:func:`scene_octree`). Also its faces as
the block forest takes them (:func:`forest_faces`), the whole blocks it must fill (:func:`check_block_shape`) and the
padding of ``domain.pad_to_blocks`` (:func:`padding_solid`).

Also the bodies' sizes the finest level must hold (:func:`body_mesh`, :func:`half_extent`) and the memory check of
the levels (:func:`check_level_memory`).
"""

from __future__ import annotations

import numpy as np

from fsicr.errors import FsicrInputError
from fsicr.hullmesh import MeshKeys, read_mesh
from iceresist.errors import InputError
from iceresist.grid.forest import BLOCK, Face
from iceresist.grid.octree import BlockOctree
from iceresist.grid.regrid import any_in_boxes
from iceresist.limits import available_memory_bytes as mem_available
from iceresist.scene.schema import Scene
from iceresist.ship.meshhull import resolve_mesh_path
from iceresist.units import Units

#: Scene face name -> block-forest face name.
FOREST_FACE = {"x_min": "x-", "x_max": "x+", "y_min": "y-", "y_max": "y+", "z_min": "z-", "z_max": "z+"}


def forest_faces(scene: Scene, units: Units) -> dict:
    """The scene's faces as block-forest :class:`Face` values in lattice units."""
    faces = {}
    for name, face in scene.domain.faces.items():
        rho = face.density_kg_m3 if face.density_kg_m3 is not None else scene.rho_kg_m3
        faces[FOREST_FACE[name]] = Face(face.kind, tuple(float(units.velocity_to_lattice(v)) for v in face.velocity_m_s),
                                        float(units.density_to_lattice(rho)))
    return faces


def check_block_shape(shape_cells) -> None:
    """The uniform forest needs whole 8x8x8 blocks: name the key and the nearest valid counts."""
    for axis, n in zip("xyz", shape_cells):
        if n % BLOCK:
            lo, hi = max(BLOCK, n // BLOCK * BLOCK), (n // BLOCK + 1) * BLOCK
            use = f"{lo}" if lo == hi else f"{lo} or {hi}"
            raise InputError(f"domain: {n} cells along {axis} is not a multiple of {BLOCK} (blocks of 8x8x8 cells): "
                             f"use {use} cells (change domain.cells, or domain.size_m / domain.dx_m)")


def padding_solid(scene: Scene):
    """``solid(x, y, z)`` of the cells beyond the box that ``domain.pad_to_blocks`` adds (None where there are
    none): the grid is :meth:`~iceresist.scene.schema.Domain.padded_cells`, the box its first
    :meth:`~iceresist.scene.schema.Domain.shape_cells`."""
    n = scene.domain.shape_cells()
    if tuple(scene.domain.padded_cells()) == tuple(n):
        return None

    def outside_box(x, y, z):
        return (x >= n[0]) | (y >= n[1]) | (z >= n[2])

    return outside_box

def body_mesh(body, index: int, scene_source: str | None = None):
    """A mesh body's checked surface: vertices (n, 3) m about the centre of its bounding box, faces, and the
    fraction of its convex hull it fills; one line naming ``bodies[i].mesh_file`` (or ``mesh_unit``) on a bad
    file."""
    keys = MeshKeys(file=f"bodies[{index}].mesh_file", unit=f"bodies[{index}].mesh_unit")
    try:
        mesh = read_mesh(resolve_mesh_path(body.mesh_file, scene_source), unit=body.mesh_unit, keys=keys, what="body")
    except FsicrInputError as exc:
        raise InputError(str(exc)) from None
    v = mesh.vertices
    return v - 0.5 * (v.min(axis=0) + v.max(axis=0)), mesh.faces, mesh.convex_fill


def half_extent(body, mesh=None) -> np.ndarray:
    """Half the body's extent along x, y, z (m): its radius, half its edges (boxes are axis-aligned), or half a
    mesh's bounding box (``mesh``: its vertices about that box's centre)."""
    if body.shape == "sphere":
        return np.full(3, float(body.radius_m))
    if body.shape == "mesh":
        return np.abs(np.asarray(mesh[0] if isinstance(mesh, tuple) else mesh, dtype=float)).max(axis=0)
    return 0.5 * np.asarray(body.size_m, dtype=float)


#: Face kinds that are solid walls (their boundary layers are what ``refinement.wall_band_m`` refines).
WALL_KINDS = ("wall", "moving_wall", "slip")

#: Share of the machine's available memory a refined scene may take.
MEMORY_SHARE = 0.8


def available_memory_bytes() -> int:
    """Memory the machine has available now (bytes): ``MemAvailable`` (:func:`iceresist.limits.available_memory_bytes`:
    free pages and the page cache the OS can drop; free pages alone fall after every checkpoint written); where the
    OS does not say, no limit."""
    free = mem_available()
    return (1 << 62) if free is None else free


def body_half_extents_m(scene: Scene) -> np.ndarray:
    """Half the extent (m) along x, y, z of each of the scene's bodies that the finest level must hold: the
    axis-aligned half size at the start (:func:`half_extent`) or, in a regridding scene,
    where bodies turn, the radius of the bounding sphere about the centre of mass along every axis."""
    out = []
    for i, body in enumerate(scene.bodies):
        mesh = body_mesh(body, i, scene.source_name) if body.shape == "mesh" else None
        h = half_extent(body, mesh)
        regrids = scene.refinement is not None and scene.refinement.regrid_every_steps is not None
        if regrids and body.shape != "sphere":
            h = np.full(3, float(np.linalg.norm(h)))
        out.append(h)
    return np.array(out, dtype=float).reshape(-1, 3)


def scene_body_boxes_m(scene: Scene) -> np.ndarray:
    """The box (lo, hi; (n, 2, 3) m) each of the scene's ``[[bodies]]`` takes at the start: its position plus and
    minus :func:`body_half_extents_m`."""
    centres = np.array([b.position_m for b in scene.bodies], dtype=float).reshape(-1, 3)
    h = body_half_extents_m(scene)
    return np.stack([centres - h, centres + h], axis=1)


def static_regions(scene: Scene, body_boxes_m: np.ndarray | None = None) -> list:
    """The regions of a scene's ``[refinement]`` as (lo, hi, level) in level-0 cell units: the boxes, the band
    around the still-water level, the bands along the solid faces, and ``refinement.body_band_m`` around each
    body's box in ``body_boxes_m`` ((n, 2, 3): lo and hi, m; default the scene's ``[[bodies]]`` at the start,
    :func:`scene_body_boxes_m`)."""
    ref = scene.refinement
    dx = scene.domain.dx_m or 1.0
    shape = scene.domain.shape_cells()
    boxes = [(np.asarray(b.lo_m) / dx, np.asarray(b.hi_m) / dx, b.level) for b in ref.boxes]
    if ref.surface_band_m is not None:
        depth, band = scene.free_surface.water_depth_m / dx, ref.surface_band_m / dx
        boxes.append((np.array([-np.inf, -np.inf, depth - band]), np.array([np.inf, np.inf, depth + band]),
                      ref.levels))
    if body_boxes_m is None and scene.bodies:
        body_boxes_m = scene_body_boxes_m(scene)
    if ref.body_band_m is not None and body_boxes_m is not None:
        band = ref.body_band_m / dx
        for lo, hi in np.asarray(body_boxes_m, dtype=float).reshape(-1, 2, 3) / dx:
            boxes.append((lo - band, hi + band, ref.levels))
    if ref.wall_band_m is not None:
        band = ref.wall_band_m / dx
        for a, axis in enumerate("xyz"):
            for side, n in (("min", 0.0), ("max", float(shape[a]))):
                if getattr(scene.domain.faces, f"{axis}_{side}").kind not in WALL_KINDS:
                    continue
                lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
                lo[a], hi[a] = (n - band, n + band)
                boxes.append((lo, hi, ref.levels))
    return boxes


def build_octree(scene: Scene, hot: np.ndarray | None = None, body_boxes_m: np.ndarray | None = None):
    """The octree of a scene's ``[refinement]``: level-0 blocks of ``domain.dx_m``; a block takes the highest level
    of the regions its box overlaps (:func:`static_regions`, the bodies in ``body_boxes_m``) and, where ``hot``
    (a bool array on the level-0 cells: the cells a moving criterion marks, e.g. vorticity) holds a True cell in its
    box, the finest level; then 2:1 balance."""
    ref = scene.refinement
    shape = scene.domain.shape_cells()
    periodic = tuple(getattr(scene.domain.faces, f"{a}_min").kind == "periodic" for a in "xyz")
    t = BlockOctree(tuple(n // 8 for n in shape), ref.levels, periodic=periodic)
    boxes = static_regions(scene, body_boxes_m)

    def wanted(lo, hi):
        level = np.zeros(len(lo), dtype=np.int64)
        for blo, bhi, lv in boxes:
            overlap = ((lo < bhi[None, :]) & (hi > blo[None, :])).all(axis=1)
            level = np.where(overlap, np.maximum(level, lv), level)
        if hot is not None:
            level = np.where(any_in_boxes(hot, lo, hi), ref.levels, level)
        return level

    return t.refine(wanted)


def scene_octree(scene: Scene, hot: np.ndarray | None = None, body_boxes_m: np.ndarray | None = None):
    """The octree of ``scene``'s blocks: :func:`build_octree` of its ``[refinement]``, or the level-0 blocks alone
    (one level) without one."""
    if scene.refinement is not None:
        return build_octree(scene, hot, body_boxes_m)
    periodic = tuple(getattr(scene.domain.faces, f"{a}_min").kind == "periodic" for a in "xyz")
    return BlockOctree(tuple(n // 8 for n in scene.domain.padded_cells()), 0, periodic=periodic)


def check_level_memory(level_bytes: dict) -> None:
    """Levels whose blocks (``level_bytes``: bytes per level) need more than :data:`MEMORY_SHARE` of the memory
    available are refused in one line naming ``refinement.levels``."""
    total = sum(level_bytes.values())
    free = available_memory_bytes()
    if total > MEMORY_SHARE * free:
        raise InputError(f"refinement.levels: the blocks need {total / 2**30:.3g} GiB, more than "
                         f"{MEMORY_SHARE:.0%} of the {free / 2**30:.3g} GiB available; use fewer levels or "
                         f"smaller refinement.boxes")
