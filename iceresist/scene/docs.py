"""The scene-key reference of ``docs/SCENES.md``, generated from the schema so the two cannot drift.

``python -m iceresist.scene.docs`` prints the whole of ``docs/SCENES.md``.
"""

from __future__ import annotations

import typing
from importlib import resources

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from iceresist.scene import schema as S
from iceresist.scene.load import preset_text

#: (heading, model, key prefix) for each table, in file order.
SECTIONS = [
    ("[case] (optional: start from a ship case)", S.CaseBase, "case"),
    ("[scene]", S.SceneInfo, "scene"),
    ("[domain]", S.Domain, "domain"),
    ("[domain.faces.<face>] (face = x_min, x_max, y_min, y_max, z_min, z_max)", S.Face, "domain.faces.<face>"),
    ("[fluid]", S.Fluid, "fluid"),
    ("[numerics]", S.Numerics, "numerics"),
    ("[run]", S.RunSettings, "run"),
    ("[output]", S.Output, "output"),
    ("[free_surface] (optional)", S.FreeSurface, "free_surface"),
    ("[ship] (optional)", S.Ship, "ship"),
    ("[ice] (optional)", S.Ice, "ice"),
    ("[contact] (optional)", S.Contact, "contact"),
    ("[[bodies]] (optional, repeatable)", S.Body, "bodies[]"),
    ("[bodies.oscillation] (optional, a prescribed body)", S.Oscillation, "bodies[].oscillation"),
    ("[refinement] (optional)", S.Refinement, "refinement"),
    ("[[refinement.boxes]] (repeatable)", S.RefinementBox, "refinement.boxes[]"),
]

_UNITS = [("_m2_s", "m^2/s"), ("_m_s2", "m/s^2"), ("_m_s", "m/s"), ("_kg_m3", "kg/m^3"), ("_N_m3", "N/m^3"),
          ("_N_m", "N/m"), ("_deg", "deg"), ("_cells", "cells"), ("_lattice", "lattice units"), ("_m", "m"),
          ("_s", "s")]


def _unit(name: str) -> str:
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return "-"


def _allowed(field) -> str:
    if isinstance(field.json_schema_extra, dict) and "allowed" in field.json_schema_extra:
        return field.json_schema_extra["allowed"]
    parts = []
    for m in field.metadata:
        for attr, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            v = getattr(m, attr, None)
            if v is not None:
                parts.append(f"{op} {v:g}")
        if getattr(m, "pattern", None):
            parts.append("letters, digits, `_ . -`")
    lits = _literals(field.annotation)
    if lits:
        parts.append(" \\| ".join(f"`{v}`" for v in lits))
    ann = str(field.annotation)
    if not parts and "tuple" in ann:
        parts.append("3 integers >= 1" if "int" in ann else "3 numbers > 0" if "gt=0" in ann else "3 numbers")
    return ", ".join(parts) or "any"


def _literals(ann):
    if typing.get_origin(ann) is typing.Literal:
        return list(typing.get_args(ann))
    for a in typing.get_args(ann):
        found = _literals(a)
        if found:
            return found
    return []


def _default(field) -> str:
    if field.is_required() or field.default is PydanticUndefined:
        return "required"
    d = field.default
    if d is None:
        return "absent"
    if isinstance(d, BaseModel):
        return "see table"
    if isinstance(d, str):
        return f'`"{d}"`'
    if isinstance(d, (list, tuple)):
        return "`[" + ", ".join(f'"{v}"' if isinstance(v, str) else f"{v:g}" for v in d) + "]`"
    if isinstance(d, float):
        return f"`{d:g}`"
    return f"`{d}`"


def reference_markdown() -> str:
    """Markdown tables of every key: meaning, unit, default, allowed values."""
    out = []
    for heading, model, prefix in SECTIONS:
        out.append(f"### `{prefix}` — {heading}\n\n{(model.__doc__ or '').strip()}\n\n")
        out.append("| key | meaning | unit | default | allowed |\n|---|---|---|---|---|\n")
        for name, field in model.model_fields.items():
            desc = (field.description or "").replace("|", "\\|")
            out.append(f"| `{prefix}.{name}` | {desc} | {_unit(name)} | {_default(field)} | {_allowed(field)} |\n")
        out.append("\n")
    return "".join(out)


INTRO = """# Scene files

A scene file is TOML. It declares the domain, the resolution, the fluid, the
numerics, when to stop and what to write, and, optionally, the free surface,
the ship, the ice field, the contact law and extra bodies. Run one with

    iceresist run my_scene.toml [--backend auto|cpu|cuda] [--precision float32|float64]
                                [--steps N] [--output DIR] [--force] [--pickup [CHECKPOINT]]

`iceresist run cavity` (or `poiseuille`) runs a built-in scene. The result is
`<output.directory>/<scene.name>.h5` with an XDMF sidecar `<scene.name>.xdmf`
(open it in ParaView; a scene with `[refinement]` also writes
`<scene.name>.levels.xdmf`, every level's cells at their own size, one block per
level) and a checkpoint `<scene.name>.checkpoint.h5`. An
existing result is never overwritten without `--force`; `--pickup` continues it
from its checkpoint to the (new) stop criterion. The result's `steps` and
`wall_time_s` then count the work it kept over all its legs (`legs`), not the
steps a killed leg did after its last checkpoint; `legs_json` lists each leg's
start iteration, time, code revision, backend and device.

A ship scene can start from one of the paper's cases instead of spelling out
every section: a `[case]` table names the case, the fidelity and the tier
(the scene `iceresist sweep` would run, docs/SHIP.md), and each other section
of the file changes only the keys it names. A finer grid for the quick tier-2
68 % case is then

    [case]
    name = "A-c68-v1.0"
    fidelity = "quick"
    tier = 2

    [scene]
    name = "finer_A-c68"

    [domain]
    cells = [504, 136, 104]
    dx_m = 0.010220588235294117

(`validation/scenes/` holds such files). The result file keeps the text as
written.

## Rules

* **Unknown keys are errors.** Every problem is reported on one line that
  names the key, e.g. `scene.toml: domain.dx_m: must be > 0 (got -1)`, and the
  command exits with status 2.
* **Units are in the key name** (`_m`, `_s`, `_m_s`, `_kg_m3`, `_N_m`, ...).
  With `[scene] units = "lattice"` every number is in lattice units instead
  (cell size, time step and reference density are 1); the key names stay.
* **Time step.** `dt = mach * dx / u_ref`, where `u_ref` is the largest speed
  the scene names (moving faces, inlets, initial flow, ship, bodies,
  `numerics.u_max_m_s`) or, with a free surface, the shallow-water wave speed
  `sqrt(g h)` if that is larger. `mach` is the lattice velocity limit
  `u dt/dx` (default 0.1, i.e. Mach 0.17 against the lattice sound speed
  `1/sqrt(3)`). The relaxation time is `tau = 1/2 + 3 nu dt / dx^2`.
* **Refusals.** A scene that cannot run stably is refused with the fix named:
  `tau <= 1/2`, `tau - 1/2 < numerics.min_tau_excess` (default 1e-8; a warning
  below 1e-4, where only the cumulant operator is expected to hold), or a
  speed above the lattice velocity limit.
* **Blocks.** The grid is made of 8x8x8-cell blocks: each cell count must be a
  multiple of 8 (`size_m / dx_m` is rounded to whole cells first).
* **Optional sections** (`[free_surface]`, `[ship]`, `[ice]`, `[contact]`,
  `[[bodies]]`): a scene that leaves them out allocates nothing for them.
  `iceresist run` runs fluid-only scenes, free-surface scenes
  (`[free_surface]` alone), ship scenes (`[ship]` with `[ice]`:
  `ship.tier = 1` is the DEM with water models, `ship.tier = 2` the coupled
  LBM-DEM, which also needs `[free_surface]`) and body scenes (`[[bodies]]`,
  with or without `[free_surface]` and `[contact]`, no ship; see "Bodies"
  below); any other combination is refused with a message.
* **Tank blockage (tier 2).** The hull's midship section fills a part m of
  the tank's wet section (width x `free_surface.water_depth_m`). Above
  Schijf's limiting speed (depth Froude number 0.47 at the paper's m = 0.20,
  0.28 at m = 0.40) no steady flow past the hull exists: the ship pushes a
  bore ahead. The run warns then; make the tank deeper or wider
  (docs/SHIP.md, "The tank's limiting speed").
* **Start wave (tier 2).** The ship starts at full speed. Until the stern's
  start wave reaches the bow, t_s = (V / A_s) / (sqrt(g h) - U) after the
  start, the water ahead of the bow drifts forward at U m / 2 in a tank of
  any length. The run warns when the steady window (`ship.steady_window_m`
  or its default) begins before t_s and names the run-up U t_s it needs:
  start the ship further aft (`ship.start_x_m`) or begin the window later
  (docs/SHIP.md, "The start wave").

## Result file

| path | content |
|---|---|
| `meta` (attributes) | scene TOML text, version, git revision, backend, device, precision, cells, steps, wall time, MLUPS, units, stop reason |
| `fields/<iteration>/rho`, `u`, `pressure`, `flags` (free surface also `phi`, `surface`) | snapshots, float32 (flags uint8), stored `[z, y, x]` (`u`: `[z, y, x, 3]`) as ParaView reads them; attributes `iteration`, `time_s`, `units` |
| `timeseries/iteration`, `time_s`, `mass_kg`, `kinetic_energy_J`, `max_speed_m_s`, `max_lattice_speed` (free surface also `water_volume_m3`, `water_volume_drift`, `surface_mean_m`, `f_rows_in_use`; bodies: the per-body columns of "Bodies") | one row every `output.timeseries_every_steps` |

Read a field back in the engine's `[x, y, z]` order with
`iceresist.io.RunFile(path).read_field(iteration, "u")`.

## Bodies

A scene with `[[bodies]]` and no ship runs boxes and spheres in the fluid
(`iceresist.models.BodiesModel`): the LBM, the DEM and the coupling of the
paper (interpolated bounce-back, momentum exchange, eqs. 16-21).

* `motion = "free"`: the body moves under gravity, the fluid force and the
  contacts (`density_kg_m3` sets its mass); `"fixed"`: at rest;
  `"prescribed"`: moves at `velocity_m_s`. Fixed and prescribed bodies push
  the fluid and the free bodies and are not moved by either.
* A prescribed body with `oscillation = { amplitude_m = [0, 0, 0.015],
  period_s = 0.78 }` heaves (surges, sways) about its path, the amplitude
  ramped up over `ramp_periods`: a forced-oscillation test, the fluid force
  in the time series gives added mass and damping (the validation case
  `heave_added_mass`).
* Without `[free_surface]` the box's faces are the scene's (inlets, outlets,
  periodic, walls); gravity (`fluid.gravity_m_s2`) acts on the bodies and the
  fluid adds the buoyancy -rho V g to each (the flow carries no hydrostatic
  pressure). `domain.pad_to_blocks` keeps a box that is not whole blocks.
* With `[free_surface]` the domain is a closed tank (every face a `wall`) of
  still water at `free_surface.water_depth_m`; the buoyancy is the water's
  hydrostatic pressure. Populations are kept in every block.
* The domain's wall faces are contact planes. Without `[contact]` the DEM
  keeps its own contact law; with it, its stiffness, restitution, friction
  (`friction_ice_ice` between free bodies, `friction_ice_hull` against fixed
  and prescribed ones and walls) and sub-step apply.
* Refused with one line: a body reaching outside the domain, bodies
  overlapping at t = 0, a free body without `density_kg_m3`, a fixed body
  with a velocity, bodies in a ship scene, a sphere or box under two cells of
  the finest level across (it may cover no cell centre: the fluid would not
  see it).
* **Water that starts inside a body** is taken out: the cells a body covers
  at t = 0 are solid, their water leaves the water volume, and the level
  stays at `free_surface.water_depth_m` (the body does not raise it). Give
  the level you want with the bodies in place; `water_volume_m3` counts the
  water outside the bodies.
* **`_Fz_N` is the fluid's force, not the body's weight**: pressure (the
  buoyancy included) and friction. A body floating at rest has `_Fz_N` equal
  to its weight m g; a fixed body wholly under still water, the buoyancy
  rho V g.
* **Real water and the cell size.** `tau - 1/2 = 3 nu dt / dx^2`, and the
  time step is `dt = mach dx / u_ref` with `u_ref` at least `sqrt(g h)` under
  a free surface, so `tau - 1/2 = 3 nu mach / (u_ref dx)` falls as the cells
  grow (a smaller `numerics.dt_s` lowers it too). For water (`nu_m2_s = 1.0e-6`) 0.9 m deep it is 5.0e-6 at 20 mm
  cells, 2.0e-5 at 5 mm and 1.0e-4 at 1 mm: coarser than about 1 mm, the
  warning below 1e-4 fires. It says that BGK would not hold there; the
  cumulant operator (the default) is meant to, and the paper's water at
  2.7 mm cells runs at such values. Cells of 1 mm or less keep real water
  above the warning; a larger `nu_m2_s` is a model fluid of your choice, not
  water.

The time series holds, per body `<name>`, every `output.timeseries_every_steps`:

| column | content |
|---|---|
| `<name>_x_m`, `_y_m`, `_z_m` | centre of mass (m) |
| `<name>_vx_m_s`, `_vy_m_s`, `_vz_m_s` | velocity (m/s) |
| `<name>_Fx_N`, `_Fy_N`, `_Fz_N` | force of the fluid on the body (N): the momentum exchange averaged over two steps (eq. 20), the buoyancy included |
| `<name>_Tx_N_m`, `_Ty_N_m`, `_Tz_N_m` | torque of the fluid about the centre of mass (N m, eq. 21) |

and the fluid's `mass_kg`, `kinetic_energy_J`, `max_speed_m_s`,
`max_lattice_speed` over the cells that are fluid now (with a free surface
also `water_volume_m3`, `water_volume_drift` and `water_level_m`, the mean
height of the surface over the columns no body reaches). A lattice-unit scene
writes every column in lattice units. The three reference cases with bodies
are scene files that run as they stand:
`iceresist/validate/scenes/{sphere_drag,floating_cube,settling_sphere}.toml`.

## Key reference

"""

FULL_EXAMPLE = """# Paper case (Watanabe, Hu and Aoki 2023, section 3): the keys of a ship in a brash-ice channel.
# `iceresist run` runs it at ship.tier 1 (DEM with water models); ship.tier = 2 runs the coupled LBM-DEM on this grid.
[scene]
name = "b063_bow_a_c68_1kn"
description = "B-063 Bow A, 68 % brash ice, 1 knot, model scale 1:25"

[domain]
size_m = [11.15, 1.39, 1.39]
dx_m = 0.0434                 # a coarse uniform grid; the paper refines to 2.72 mm

[domain.faces]
x_min = "wall"
x_max = "wall"
y_min = "wall"
y_max = "wall"
z_min = "wall"
z_max = "wall"

[fluid]
nu_m2_s = 1.0e-6
rho_kg_m3 = 1000.0
gravity_m_s2 = [0.0, 0.0, -9.81]

[numerics]
precision = "float32"
backend = "auto"
mach = 0.1

[run]
end_time_s = 20.0
wall_time_limit_s = 86400

[output]
directory = "runs"
fields_every_s = 0.5
timeseries_every_steps = 10
checkpoint_wall_s = 3600

[free_surface]
water_depth_m = 1.11

[ship]
hull = "b063"
bow_angle_deg = 30            # Bow A; 45 for Bow B
speed_m_s = 0.514             # 1 knot

[ice]
size_m = 0.041
density_kg_m3 = 950.0
count = 3136                  # 68 %: 28 x 112 cubes
channel_width_m = 1.39
channel_length_m = 5.56

[contact]
stiffness_N_m = 1.0e4
restitution = 0.3
friction_ice_ice = 0.3
friction_ice_hull = 0.1
"""


#: Complete ``[[bodies]]`` scenes (title, TOML) for docs/SCENES.md; tests/test_bodies.py parses them.
SPHERE_EXAMPLE = """# A 10 mm sphere held fixed in a water channel at 10 mm/s (Re = 100): velocity inlet, pressure outlet, periodic
# sides. Its drag is sphere_Fx_N of the time series.
[scene]
name = "sphere_in_channel"

[domain]
size_m = [0.16, 0.08, 0.08]
dx_m = 0.002

[domain.faces]
x_min = { kind = "velocity_inlet", velocity_m_s = [0.01, 0.0, 0.0] }
x_max = "pressure_outlet"
y_min = "periodic"
y_max = "periodic"
z_min = "periodic"
z_max = "periodic"

[fluid]
nu_m2_s = 1.0e-6
initial_velocity_m_s = [0.01, 0.0, 0.0]

[run]
end_time_s = 60.0

[output]
fields = ["u", "pressure", "flags"]
fields_every_s = 10.0
timeseries_every_steps = 10

[[bodies]]
name = "sphere"
shape = "sphere"
radius_m = 0.005
position_m = [0.04, 0.04, 0.04]
motion = "fixed"
"""

#: The sphere above on two levels of blocks (static refinement around it).
REFINED_SPHERE_EXAMPLE = SPHERE_EXAMPLE.replace(
    "# A 10 mm sphere held fixed in a water channel at 10 mm/s (Re = 100): velocity inlet, pressure outlet, periodic\n"
    "# sides. Its drag is sphere_Fx_N of the time series.\n",
    "# The fixed sphere above on two levels of blocks: 2 mm cells far from it, 1 mm cells (level 1) in the blocks within\n"
    "# 10 mm of it, where the sphere and its coupling live (10 cells per diameter) at level 1's own time step; 22 % of\n"
    "# the uniform 1 mm grid's cells. The sphere must lie in the finest level, two cells inside it.\n").replace(
    'name = "sphere_in_channel"', 'name = "sphere_in_channel_refined"') + """
[refinement]
levels = 1
body_band_m = 0.01
"""

def _settling_levels_example() -> str:
    """The settling sphere's scene file (iceresist/validate/scenes/settling_sphere.toml: E1 at 6 cells per diameter,
    the box in whole blocks) on two levels that follow the sphere."""
    # the file as package data (the validation cases run above the scene package: their code is not imported)
    text = resources.files("iceresist").joinpath("validate/scenes/settling_sphere.toml").read_text(encoding="utf-8")
    text = text[text.index("[scene]"):]
    for old, new in (('name = "settling_sphere"', 'name = "settling_sphere_levels"'),
                     ("6 cells per diameter (quick ladder, middle rung)", "12 per diameter on levels that follow it"),
                     ("pad_to_blocks = true\n", "")):
        if old not in text:
            raise RuntimeError(f"settling_sphere.toml no longer holds {old!r}: update the SCENES.md example")
        text = text.replace(old, new)
    return ("# ten Cate's sphere E1 of iceresist/validate/scenes/settling_sphere.toml on two levels that follow it: 2.5 mm\n"
            "# cells (6 per diameter) on level 0, 1.25 mm (12 per diameter) within 5 mm of the sphere's box. Every 10\n"
            "# steps the blocks are drawn again around the sphere where it is then and the flow carried over\n"
            "# (refinement.regrid_every_steps; the band must outrun the sphere between regrids). It settles at\n"
            "# 0.0365 m/s (-3.97 % against the measured 0.038) with 15.5 % of the uniform 1.25 mm grid's cell updates.\n"
            + text.rstrip() + "\n\n[refinement]\nlevels = 1\nbody_band_m = 0.005\nregrid_every_steps = 10\n")


SETTLING_LEVELS_EXAMPLE = _settling_levels_example()

BODY_EXAMPLES = [("A fixed sphere in a channel (bodies, SI units)", SPHERE_EXAMPLE), ("A floating box (bodies with a free surface)", """# A 40 mm ice block (900 kg/m^3) released in still water 60 mm deep, in a closed tank: it heaves and settles
# at 90 % of its height under the level (floe_z_m, floe_Fz_N, water_level_m of the time series).
[scene]
name = "floating_box"

[domain]
cells = [24, 24, 24]
dx_m = 0.005

[domain.faces]
x_min = "wall"
x_max = "wall"
y_min = "wall"
y_max = "wall"
z_min = "wall"
z_max = "wall"

[fluid]
nu_m2_s = 5.0e-6
gravity_m_s2 = [0.0, 0.0, -9.81]
operator = "bgk"

[numerics]
dt_s = 0.0007
mach = 0.2

[run]
end_time_s = 1.0

[output]
fields = ["u", "flags", "phi"]
fields_every_s = 0.1
timeseries_every_steps = 5

[free_surface]
water_depth_m = 0.06

[[bodies]]
name = "floe"
shape = "box"
size_m = [0.04, 0.04, 0.04]
position_m = [0.06, 0.06, 0.06]
density_kg_m3 = 900.0
motion = "free"
"""), ("A fixed sphere on refined levels (bodies, refinement)", REFINED_SPHERE_EXAMPLE),
                 ("A settling sphere on levels that follow it (bodies, regridding)", SETTLING_LEVELS_EXAMPLE)]


#: A ship scene on the user's own hull, for docs/SCENES.md; tests/test_mesh_hull.py runs it.
MESH_EXAMPLE = """# Your own hull in the quick tier-1 case: the case's ice and contact law, the hull from a mesh, and the tank,
# channel and steady window sized from the hull (docs/OWN_SHIP.md). The mesh is a closed surface (STL or
# OBJ); its path is relative to this file ("b063" is the shipped B-063 model with Bow A at +x); mesh_scale divides
# its lengths (25 runs a full-scale mesh as a 1:25 model). The reader puts the keel at z = 0, the centreline at
# y = 0 and the stem at the waterline at x = 0; FSICR inputs are measured on it at draught_m (docs/FSICR.md).
[case]
name = "A-c68-v1.0"
fidelity = "quick"
tier = 1

[ship]
hull = "mesh"
mesh_file = "b063"            # e.g. "my_hull.stl"
mesh_unit = "m"               # m, cm, mm, ft, in
mesh_bow = "+x"               # the mesh's axis toward the bow
mesh_up = "+z"                # the mesh's upward axis
mesh_scale = 1                # the mesh's lengths / this = the model's
draught_m = 0.44              # the model's
"""


def scenes_markdown() -> str:
    """The whole of docs/SCENES.md."""
    out = [INTRO, reference_markdown(), "## Complete examples\n\n"]
    for name, what in (("cavity", "Lid-driven cavity in lattice units (the default scene)"),
                       ("poiseuille", "Plane Poiseuille flow of water in SI units"),
                       ("still_tank", "Still water in a closed tank (free surface), lattice units"),
                       ("dam_break", "Dam break in a flume (free surface), lattice units"),
                       ("refined_channel", "Plane Poiseuille flow on two levels of blocks (static refinement)"),
                       ("refined_tank", "Still water with its surface on the finer of two levels (static refinement)")):
        out.append(f"### `{name}` — {what}\n\n```toml\n{preset_text(name).rstrip()}\n```\n\n")
    for title, text in BODY_EXAMPLES:
        out.append(f"### {title}\n\n```toml\n{text.rstrip()}\n```\n\n")
    out.append(f"### A ship in a brash-ice channel (all sections)\n\n```toml\n{FULL_EXAMPLE.rstrip()}\n```\n\n")
    out.append(f"### Your own hull (a mesh)\n\n```toml\n{MESH_EXAMPLE.rstrip()}\n```\n")
    return "".join(out)


if __name__ == "__main__":  # pragma: no cover
    print(scenes_markdown(), end="")
