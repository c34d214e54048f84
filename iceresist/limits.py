"""The pre-run stability limits in one place: a setting that cannot run stably is refused before anything is written.

Each check raises :class:`~iceresist.errors.StabilityError` (or :class:`InputError` for a physically impossible
input) with one line naming the scene key, the limit and a value that would work; the CLI prints it and exits 2.

Limits and where they come from (measured numbers: docs/VALIDATION.md, "Stability limits"):

* **Cell Reynolds number** ``Re_cell = u_lat / nu_lat = u dx / nu`` with ``nu_lat = (tau - 1/2) / 3``: a lattice
  Boltzmann operator stays stable only below an operator-dependent ``Re_cell``. This is the form the tau limit
  takes once the speed is fixed: ``tau - 1/2 >= 3 u_lat / Re_cell,max``. Measured on a 16^3 lid-driven cavity
  (the harsher of the cavity and the Taylor-Green vortex) by :func:`iceresist.validate.stability.measure_operator_limits`.
* **Lattice speed** ``u dt / dx`` per operator (beyond it the weakly compressible model breaks down); the schema
  ceiling :data:`iceresist.units.MACH_LATTICE_CEILING` stays the absolute cap.
* **Step count**: a run needing more than :data:`MAX_STEPS` steps (time step too small for its end time) is refused.
* **DEM**: the sub-step follows from the stiffness (:mod:`iceresist.dem.system`, ``2 sqrt(m/k)``); refused are a
  total sub-step count above :data:`MAX_DEM_SUBSTEPS` and a hull that moves more than
  :data:`SHIP_TRAVEL_PER_SUBSTEP` sphere radii in one sub-step (contacts would be skipped).
* **Memory**: a scene whose LBM populations alone (two buffers of 27 per cell) exceed the memory free on this
  machine is refused before anything is allocated (:func:`check_memory`).
* **Ice**: cubes denser than the water cannot float; more cubes than the touching limit of the channel cannot be
  placed without overlap.

``numerics.check_limits = false`` runs a fluid setting beyond the measured operator limits (Re_cell, lattice
speed) at the user's risk; the run watchdog (:mod:`iceresist.watchdog`) still stops it if it goes unstable.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import math

from iceresist.errors import InputError, StabilityError
from iceresist.scene.schema import Contact
from iceresist.ship.channel import grid_for_concentration, grid_for_count
from iceresist.units import MACH_LATTICE_CEILING

log = logging.getLogger(__name__)

#: Largest cell Reynolds number u_lat / nu_lat at which each operator ran stably for 2000 steps on the 16^3
#: lid-driven cavity at lid speed 0.1 (the default lattice velocity limit), float32. Measured: BGK stable at 15,
#: unstable at 30; cumulant stable at 60, unstable at 100 (and at 150 with lid speed 0.05). The Taylor-Green vortex
#: (16^3, u0 <= 0.3) ran stably with the cumulant down to tau - 1/2 = 1e-6: the cavity's lid corners are the harsher
#: test, and the limit is conservative for smooth flows at low lattice speed.
CELL_REYNOLDS_MAX = {"bgk": 15.0, "cumulant": 60.0}
#: Lattice speed of that measurement; above it the limit falls as (REFERENCE_LATTICE_SPEED / u)^2 (cumulant, measured:
#: lid 0.2 stable at Re 20 and unstable at 60; lid 0.3 stable at Re 9; BGK assumed to follow the same law).
REFERENCE_LATTICE_SPEED = 0.1
#: Largest lattice speed u dt/dx accepted per operator: the cumulant ran the cavity stably at lid speed 0.3
#: (tau - 1/2 = 0.1); BGK was not measured beyond 0.1 and keeps the schema ceiling.
LATTICE_SPEED_MAX = {"bgk": 0.3, "cumulant": 0.3}
#: Most time steps one run may take (a 16^3 fluid at 30 MLUPS runs 1e7 steps in about 25 min on a 2-core x86 VM).
MAX_STEPS = 10_000_000
#: Most DEM sub-steps one tier-1 run may take.
MAX_DEM_SUBSTEPS = 20_000_000
#: Largest hull travel in one DEM sub-step, in sphere radii (beyond it a hull sphere passes half way through an
#: ice sphere between two contact evaluations).
SHIP_TRAVEL_PER_SUBSTEP = 0.5
#: Largest overlap of a floe struck at the hull's speed, v sqrt(m/k) (the peak of an undamped spring of stiffness
#: k stopping the mass m), in sphere radii: beyond it the spheres of the two bodies pass through one another and
#: the contact force throws them apart. Measured on the quick tier-1 case A-c68-v1.0 (k = 5000 N/m, 2-core x86
#: VM): 2.06 and 3.0 m/s (0.72 and 1.05 radii) run to the end; 3.5, 4.0 and 4.8 m/s (1.24-1.7 radii) run away
#: within 32-70 records. The paper's fastest case, 2 knots, overlaps 0.36 radii.
IMPACT_OVERLAP_MAX = 1.0


def _g(x: float) -> str:
    return f"{x:.4g}"


# -- fluid ----------------------------------------------------------------------------------------------
def reference_lattice_speed(scene, units) -> float:
    """The largest speed the scene names, in lattice units (0 when it names none)."""
    return float(units.velocity_to_lattice(scene.largest_speed_m_s()))


def cell_reynolds_max(operator: str, u_lat: float) -> float:
    """The largest cell Reynolds number u_lat / nu_lat accepted for ``operator`` at the lattice speed ``u_lat``."""
    return CELL_REYNOLDS_MAX[operator] * min(1.0, (REFERENCE_LATTICE_SPEED / max(u_lat, 1e-300)) ** 2)


def check_cell_reynolds(scene, units) -> None:
    """Refuse tau - 1/2 too small for the operator at the scene's speed: ``u_lat / nu_lat <= CELL_REYNOLDS_MAX``."""
    op = scene.fluid.operator
    u_lat = reference_lattice_speed(scene, units)
    if u_lat <= 0.0:
        return
    re_max = cell_reynolds_max(op, u_lat)
    excess = units.tau - 0.5
    re_cell = u_lat / (excess / 3.0)
    if re_cell <= re_max * (1.0 + 1e-9):
        return
    need_excess = 3.0 * u_lat / re_max
    other = "cumulant" if op == "bgk" and cell_reynolds_max("cumulant", u_lat) >= re_cell else None
    alt = f', or fluid.operator = "{other}"' if other else ""
    if scene.is_lattice:
        key = "numerics.tau" if scene.numerics.tau is not None else "fluid.nu_m2_s"
        fix = (f"use numerics.tau >= {_g(0.5 + need_excess)}" if key == "numerics.tau"
               else f"use fluid.nu_m2_s >= {_g(need_excess / 3.0)}")
    else:
        key = "domain.dx_m"
        dx_max = re_max * units.nu_m2_s / scene.largest_speed_m_s()
        fix = f"use domain.dx_m <= {_g(dx_max)} m (cell Reynolds number u dx / nu = {_g(re_cell)})"
    raise StabilityError(
        f"{key}: tau - 1/2 = {excess:.3g} at the lattice speed {_g(u_lat)} gives a cell Reynolds number "
        f"{_g(re_cell)}, above the limit {_g(re_max)} of the {op} operator: {fix}{alt} "
        f"(or numerics.check_limits = false at your own risk)")


def check_lattice_speed_for_operator(scene, units) -> None:
    """Refuse a lattice speed above what the operator was measured to take (:data:`LATTICE_SPEED_MAX`)."""
    op = scene.fluid.operator
    u_lat = reference_lattice_speed(scene, units)
    limit = min(LATTICE_SPEED_MAX[op], MACH_LATTICE_CEILING)
    if u_lat <= limit * (1.0 + 1e-9):
        return
    fastest, speed = scene.fastest()
    if scene.is_lattice:
        fix = f"scale the speeds in the scene down by {_g(limit / u_lat)} (e.g. {fastest} <= {_g(speed * limit / u_lat)})"
        key = fastest
    else:
        fix = f"use numerics.dt_s <= {_g(units.dt_s * limit / u_lat)} s (or leave it out)"
        key = "numerics.dt_s"
    raise StabilityError(f"{key}: the largest speed ({fastest} = {_g(speed)}) is {_g(u_lat)} in lattice units, "
                         f"above the limit {_g(limit)} of the {op} operator: {fix}")


def check_step_count(scene, dt_s: float, *, dt_key: str = "numerics.dt_s") -> int:
    """Refuse a run needing more than :data:`MAX_STEPS` steps; returns the step count it needs."""
    r = scene.run
    by_time = None
    if r.end_time_s is not None:
        ratio = r.end_time_s / dt_s          # may overflow to inf for a huge end time: compare before ceil
        by_time = math.ceil(ratio - 1e-9) if ratio <= MAX_STEPS else ratio
    steps = min(s for s in (r.steps, by_time) if s is not None)
    if steps <= MAX_STEPS:
        return int(steps)
    if by_time is not None and by_time == steps:
        raise StabilityError(
            f"run.end_time_s: {_g(r.end_time_s)} s at the time step {dt_s:.3g} s needs {steps:.3g} steps, above "
            f"the maximum {MAX_STEPS:.0e}: use run.end_time_s <= {_g(MAX_STEPS * dt_s)} s or "
            f"{dt_key} >= {r.end_time_s / MAX_STEPS:.3g} s")
    raise StabilityError(f"run.steps: {steps} steps is above the maximum {MAX_STEPS:.0e}: use run.steps <= {MAX_STEPS}")


def check_fluid(scene, units) -> None:
    """All pre-run limits of a fluid scene (called by :class:`iceresist.models.FluidModel`)."""
    if scene.numerics.check_limits:
        check_lattice_speed_for_operator(scene, units)
        check_cell_reynolds(scene, units)
    else:
        log.warning("numerics.check_limits = false: the operator limits are not enforced; the watchdog stays on")
    check_step_count(scene, units.dt_s, dt_key="numerics.dt_s" if not scene.is_lattice else "the time step")


# -- ice and DEM ----------------------------------------------------------------------------------------
def available_memory_bytes() -> int | None:
    """Memory free for a new process (``MemAvailable`` of /proc/meminfo; None where it cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def release_freed_memory() -> None:
    """Free what only reference cycles still hold (a full garbage collection) and hand the heap memory the process
    has freed back to the OS (glibc's ``malloc_trim``; nothing more elsewhere).

    A regrid drops one set of level arrays and tables and allocates the next. The old levels hang in reference
    cycles (solvers, steppers and launchers that refer to one another), which Python's collector frees only when
    its oldest generation runs, and glibc keeps freed heap for reuse; without both the resident memory of the ship
    on levels grew by gigabytes over a run and a whole case ran out of memory (24 GB for 1.6e6 leaf cells, 2-core
    x86 VM)."""
    gc.collect()
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return
    trim(0)


def populations_bytes(cells: int, precision: str) -> int:
    """Bytes of the LBM populations of ``cells`` cells: two buffers of 27 values (the least a run allocates)."""
    return int(cells) * 2 * 27 * (4 if precision == "float32" else 8)


def check_memory(scene, precision: str | None = None, available: int | None = None) -> None:
    """Refuse a scene whose populations alone need more memory than is free (``available`` bytes, default the
    machine's), naming ``domain`` and a cell count that fits."""
    precision = precision or scene.numerics.precision
    free = available if available is not None else available_memory_bytes()
    shape = scene.shape_cells()
    cells = math.prod(shape)
    if cells > 10 ** 15:        # beyond any machine; the counts themselves would not print
        raise InputError(f"{scene.source_name}: domain.dx_m: {scene.domain.dx_m:g} gives about 1e{len(str(cells)) - 1} "
                         f"cells, beyond any machine: use a coarser domain.dx_m (a hundredth of the domain's longest "
                         f"side gives about 1e6 cells)")
    need = populations_bytes(cells, precision)
    if free is None or need <= free:
        return
    fits = free // populations_bytes(1, precision)
    side = max(8, int(fits ** (1.0 / 3.0)) // 8 * 8)
    raise InputError(f"{scene.source_name}: domain: {shape[0]}x{shape[1]}x{shape[2]} cells need at least {need / 2 ** 30:.3g} GiB for "
                     f"the LBM populations ({precision}), {free / 2 ** 30:.3g} GiB are free: use at most "
                     f"{fits:.3g} cells (e.g. {side}x{side}x{side}, a coarser domain.dx_m or a smaller "
                     f"domain.size_m)")


def check_ice_floats(ice_density_kg_m3: float, water_density_kg_m3: float) -> None:
    """Ice denser than (or as dense as) the water cannot float: refuse, naming a density that would."""
    if ice_density_kg_m3 < water_density_kg_m3:
        return
    ok = min(950.0 / 1000.0 * water_density_kg_m3, water_density_kg_m3 - 1.0)
    raise InputError(f"ice.density_kg_m3: {_g(ice_density_kg_m3)} kg/m^3 is not below the water density "
                     f"{_g(water_density_kg_m3)} kg/m^3, so the ice cannot float: use a value below "
                     f"{_g(water_density_kg_m3)}, e.g. {_g(ok)}")


def touching_concentration(width_m: float, length_m: float, cube_m: float) -> float:
    """The largest ``ice.concentration`` (to 0.001) whose regular pattern keeps every pitch >= the cube edge."""
    for milli in range(1000, 0, -1):
        ny, nx = grid_for_concentration(milli / 1000.0, width_m, length_m, cube_m)
        if width_m / ny >= cube_m and length_m / nx >= cube_m:
            return milli / 1000.0
    return 0.0


def touching_count(width_m: float, length_m: float, cube_m: float) -> int:
    """The most cubes a count-filled channel takes before neighbours overlap."""
    n = max(1, int((width_m // cube_m) * (length_m // cube_m)))
    while n > 1:
        ny, nx = grid_for_count(n, width_m, length_m)
        if width_m / ny >= cube_m and length_m / nx >= cube_m:
            return n
        n -= 1
    return 1


def check_ice_amount(ice, width_m: float) -> None:
    """Refuse a concentration or count above the touching limit of the channel (cubes would overlap)."""
    L, a = ice.channel_length_m, ice.size_m
    if ice.concentration is not None:
        ny, nx = grid_for_concentration(ice.concentration, width_m, L, a)
        if width_m / ny >= a and L / nx >= a:
            return
        c_max = touching_concentration(width_m, L, a)
        raise StabilityError(f"ice.concentration: {_g(ice.concentration)} puts {ny} x {nx} cubes of {a} m in the "
                             f"{_g(width_m)} m x {_g(L)} m channel, beyond the touching limit (cubes would overlap): "
                             f"use ice.concentration <= {c_max:g}")
    ny, nx = grid_for_count(int(ice.count), width_m, L)
    if width_m / ny >= a and L / nx >= a:
        return
    raise StabilityError(f"ice.count: {ice.count} cubes of {a} m overlap in the {_g(width_m)} m x {_g(L)} m channel "
                         f"(beyond the touching limit): use ice.count <= {touching_count(width_m, L, a)}")


def check_scene_ice(scene, width_m: float) -> None:
    """Ice limits that need no DEM: it floats, and it fits."""
    check_ice_floats(scene.ice.density_kg_m3, scene.rho_kg_m3)
    check_ice_amount(scene.ice, width_m)


def check_tier1(model) -> None:
    """Limits of a built :class:`~iceresist.models.tier1.Tier1Model`: record count, sub-step count, hull travel."""
    scene = model.scene
    check_step_count(scene, model.dt_s, dt_key="contact.sample_interval_s")
    r = scene.run
    records = math.ceil(r.end_time_s / model.dt_s - 1e-9) if r.end_time_s is not None else r.steps
    if r.steps is not None:
        records = min(records, r.steps)
    total = records * model.substeps_per_step
    k = model.contact.stiffness_N_m
    if total > MAX_DEM_SUBSTEPS:
        k_ok = k * (MAX_DEM_SUBSTEPS / total) ** 2
        raise StabilityError(
            f"contact.stiffness_N_m: k = {_g(k)} N/m needs a DEM sub-step of {model.substep_s:.3g} s "
            f"(2 sqrt(m/k) x contact.dem_safety), {total:.3g} sub-steps in all, above the maximum "
            f"{MAX_DEM_SUBSTEPS:.0e}: use contact.stiffness_N_m <= {_g(k_ok)} or a shorter run.end_time_s")
    radius = model.cube.sphere_radius_m
    # name first the key far from its usual value: a spring ten times softer than the default, else the speed
    soft = k < 0.1 * Contact.model_fields["stiffness_N_m"].default
    overlap = model.speed_m_s * math.sqrt(model.cube.mass_kg / k)
    if overlap > IMPACT_OVERLAP_MAX * radius:
        ratio = IMPACT_OVERLAP_MAX * radius / overlap
        fixes = [f"ship.speed_m_s <= {_g(model.speed_m_s * ratio)}", f"contact.stiffness_N_m >= {_g(k / ratio ** 2)}"]
        if soft:
            fixes.reverse()
        raise StabilityError(
            f"{fixes[0].split(' ')[0]}: a floe struck at {_g(model.speed_m_s)} m/s would overlap the hull by "
            f"{_g(overlap)} m (v sqrt(m/k), m = {_g(model.cube.mass_kg)} kg, k = {_g(k)} N/m), more than "
            f"{IMPACT_OVERLAP_MAX:g} of the sphere radius {_g(radius)} m (the bodies would pass through one "
            f"another): use {fixes[0]} or {fixes[1]}")
    travel = model.speed_m_s * model.substep_s
    if travel > SHIP_TRAVEL_PER_SUBSTEP * radius:
        ratio = SHIP_TRAVEL_PER_SUBSTEP * radius / travel        # the sub-step must shrink by this factor
        v_ok, safety_ok, k_ok = model.speed_m_s * ratio, model.contact.dem_safety * ratio, k / ratio ** 2
        fixes = [f"ship.speed_m_s <= {_g(v_ok)}", f"contact.dem_safety <= {_g(safety_ok)}",
                 f"contact.stiffness_N_m >= {_g(k_ok)}"]
        key = "contact.stiffness_N_m" if soft else "ship.speed_m_s"
        if soft:
            fixes = fixes[2:] + fixes[:2]
        raise StabilityError(
            f"{key}: the hull moves {_g(travel)} m per DEM sub-step ({_g(model.speed_m_s)} m/s x "
            f"{model.substep_s:.3g} s, the sub-step of k = {_g(k)} N/m), more than {SHIP_TRAVEL_PER_SUBSTEP:g} of "
            f"the sphere radius {_g(radius)} m (contacts would be missed): use {fixes[0]}, or {fixes[1]}, or "
            f"{fixes[2]}")
