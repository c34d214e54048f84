"""Scene presets of the paper's ship runs (section 3) at two fidelities, and the sweep matrix.

The paper runs seven conditions, one of which is shared: concentration 50 / 68 / 88 % at 1 knot with Bow A,
speed 1 / 1.5 / 2 knots at 68 % with Bow A (68 % at 1 knot is the same run) and Bow B at 68 %, 1 knot: six
distinct cases. Names: ``<bow>-c<percent>-v<knots>``.

Fidelities (tier 1 = DEM with water models; tier 2 = the coupled LBM-DEM): ``paper`` and ``quick``, each
described, with what it trades away, in ``FIDELITY_NOTES`` (the report prints the quick ones beside its table).
Tier 2 (:mod:`iceresist.models.tier2`) changes the tank where the flow field makes it expensive (``TIER2``).
"""

from __future__ import annotations

from dataclasses import dataclass

from iceresist.errors import InputError

KNOT_M_S = 0.514  # the paper's model-scale knot (full-scale 5 knots at 1:25)
DOMAIN_M = (11.15, 1.39, 1.39)
WATER_DEPTH_M = 1.11
CHANNEL_START_X_M = 4.0


@dataclass(frozen=True)
class Case:
    """One ship run: bow (``"A"``/``"B"``), concentration (fraction) and speed (knots, model scale)."""

    bow: str
    concentration: float
    knots: float

    @property
    def name(self) -> str:
        return f"{self.bow}-c{round(100 * self.concentration):d}-v{self.knots:.1f}"

    @property
    def speed_m_s(self) -> float:
        return self.knots * KNOT_M_S

    @property
    def bow_angle_deg(self) -> float:
        return 30.0 if self.bow == "A" else 45.0


CASES = {c.name: c for c in (Case("A", 0.50, 1.0), Case("A", 0.68, 1.0), Case("A", 0.88, 1.0),
                             Case("A", 0.68, 1.5), Case("A", 0.68, 2.0), Case("B", 0.68, 1.0))}

FIDELITIES = {
    "paper": {"channel_length_m": 5.56, "spheres_per_edge": 3, "hull_spacing_m": 0.02, "hull_band_m": 0.1,
              "stiffness_N_m": 1.0e4, "dem_safety": 0.2, "sample_interval_s": 0.005, "dx_m": 0.00272},
    "quick": {"channel_length_m": 1.39, "spheres_per_edge": 2, "hull_spacing_m": 0.03, "hull_band_m": 0.06,
              "stiffness_N_m": 5.0e3, "dem_safety": 0.3, "sample_interval_s": 0.004, "dx_m": 0.010875},
}


#: Tier-2 (coupled LBM-DEM) tank and lattice per fidelity (module docstring): domain cells, cell size, water
#: depth, channel start, lattice velocity limit, viscosity (m^2/s; 1e-6 = water).
TIER2 = {
    "paper": {"cells": (4104, 512, 512), "dx_m": 1.39 / 512, "water_depth_m": WATER_DEPTH_M,
              "channel_start_x_m": CHANNEL_START_X_M, "mach": 0.1, "nu_m2_s": 1.0e-6},
    "quick": {"cells": (384, 104, 80), "dx_m": 1.39 / 104, "water_depth_m": 0.9, "channel_start_x_m": 3.4,
              "mach": 0.2, "nu_m2_s": 1.0e-5},
}


#: What each fidelity is and what it trades away, per (fidelity, tier); plain text (the report prints it).
FIDELITY_NOTES = {
    ("paper", 1): (
        "the paper's tank (11.15 x 1.39 x 1.39 m, depth 1.11 m), the full 1.39 x 5.56 m channel, cubes of "
        "3 x 3 x 3 surface spheres, hull spheres 20 mm apart, k = 1e4 N/m; the run lasts until the stem reaches "
        "the channel end, and the steady window holds the whole waterline inside the channel."),
    ("quick", 1): (
        "a 1.39 m long channel (same width, pitch and concentration: 28 x 28 cubes at 68 %), cubes of 2 x 2 x 2 "
        "corner spheres, hull spheres 30 mm apart up to 6 cm above the waterline, a softer contact (k = 5e3 N/m) "
        "with a larger sub-step; the ship stops when the stem leaves the channel. It trades away: the parallel "
        "middle body never runs fully in ice (the steady window starts once the bow wedge is in, so side "
        "friction along the whole body is missing), a short window (about 0.8 m of travel, so a wide confidence "
        "interval), rounder cubes and a softer contact. Runs in well under a minute per case on a 2-core x86 VM "
        "(tier 1)."),
    ("paper", 2): (
        "the paper's tank and water depth on a uniform grid of 2.715 mm cells (1.39 m / 512; the paper's finest "
        "cell is 2.72 mm, with AMR coarsening to 43.4 mm): 4104 x 512 x 512 cells (1.08e9 cells, the paper's "
        "AMR grid has 1.6e8), the water's viscosity (cumulant operator without a turbulence model, as the "
        "paper), lattice velocity limit 0.1. A job for GPUs, not for a CPU."),
    ("quick", 2): (
        "3 cells per 41 mm cube (dx = 1.39 m / 104 = 13.4 mm), a shorter and shallower tank (5.13 x 1.39 x "
        "1.07 m, 384 x 104 x 80 = 3.19e6 cells): water 0.9 m deep (0.46 m under the keel instead of 0.67 m), "
        "0.17 m of air above it (the hull's deck reaches out of the top of the domain, where no fluid is), the "
        "channel from x = 3.4 m so that the whole hull starts in the tank, and the tank ending 0.34 m after the "
        "channel. The depth is set by the tank's blockage (iceresist.ship.tank): the hull fills m = 0.25 of the "
        "section, and Schijf's limiting speed is then a depth Froude number of 0.42, against 0.35 at 2 knots "
        "(the paper's tank: 0.47 and 0.31). A 0.56 m deep tank (m = 0.40, limit 0.28) put 1.5 and 2 knots above "
        "the limit: the ship pushed a bore ahead, the bow wave reached the top of the domain and the 2-knot case "
        "went to NaN. Lattice velocity limit 0.2 against the shallow-water wave speed sqrt(g h) (the hydrostatic "
        "density changes by 3 x 0.2^2 = 12 % over the depth, against 3 % at the default 0.1) and a viscosity of "
        "1e-5 m^2/s (tau - 1/2 = 1.5e-4; ten times water) as a stability floor at this resolution. It trades "
        "away, beyond the tier-1 quick trades: resolved cubes (3 cells per edge: their wake, the water between "
        "them and their buoyancy distribution are coarse), the flow under the keel (a shallower tank, more "
        "blockage and squat), the true viscosity, and compressibility (12 % density change). 1 550 (2 knots) to "
        "3 100 (1 knot) LBM steps per case: hours on a 2-core x86 VM (docs/PERFORMANCE.md \"Tier 2 ship\"); "
        "TINY_TIER2_OVERRIDES of iceresist.sweep is the CI-sized version. Not grid-converged: on 2.1 cells per "
        "cube the 68 % and 88 %, 1-knot ice resistances are 0.3-0.4 x those on these 3.1, so they are "
        "under-resolved and may rise on a finer grid; the 50 % one is the same on both grids and with the "
        "viscosity of water, a seventh of tier 1's. The paper's water depth (1.11 m) lifted it 2.6 x on 2.1 "
        "cells per cube, but not on these 3.1 (0.95 against 1.15 N), so the shallower quick tank is not what "
        "keeps it low (docs/SHIP.md, \"The paper's depth on the quick grid\")."),
}


def case_names() -> list[str]:
    return list(CASES)


def get_case(name: str) -> Case:
    if name not in CASES:
        raise InputError(f"--cases: unknown case {name!r}; known cases: {', '.join(CASES)}")
    return CASES[name]


def scene_data(case: str, fidelity: str, tier: int = 1) -> dict:
    """The scene of one case as a dict of TOML sections (validated by :class:`~iceresist.scene.schema.Scene`)."""
    c = get_case(case)
    if fidelity not in FIDELITIES:
        raise InputError(f"--preset: unknown preset {fidelity!r}; use one of {', '.join(FIDELITIES)}")
    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    f = FIDELITIES[fidelity]
    t2 = TIER2[fidelity] if tier == 2 else None
    channel_start = CHANNEL_START_X_M if t2 is None else t2["channel_start_x_m"]
    start = channel_start - 0.05
    end = channel_start + f["channel_length_m"]
    if t2 is None:
        domain = {"size_m": list(DOMAIN_M), "dx_m": f["dx_m"]}
        fluid = {"nu_m2_s": 1.0e-6, "rho_kg_m3": 1000.0, "gravity_m_s2": [0.0, 0.0, -9.81]}
        numerics = {"precision": "float64" if tier == 1 else "float32", "backend": "auto"}
        depth = WATER_DEPTH_M
    else:
        domain = {"cells": list(t2["cells"]), "dx_m": t2["dx_m"]}
        fluid = {"nu_m2_s": t2["nu_m2_s"], "rho_kg_m3": 1000.0, "gravity_m_s2": [0.0, 0.0, -9.81],
                 "operator": "cumulant"}
        numerics = {"precision": "float32", "backend": "auto", "mach": t2["mach"]}
        depth = t2["water_depth_m"]
    return {
        "scene": {"name": f"ship_{fidelity}_t{tier}_{c.name}",
                  "description": f"B-063 Bow {c.bow}, {100 * c.concentration:g} % brash ice, {c.knots:g} knots "
                                 f"({c.speed_m_s:.3f} m/s), {fidelity} fidelity, tier {tier}"},
        "domain": {**domain,
                   "faces": {k: "wall" for k in ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")}},
        "fluid": fluid,
        "numerics": numerics,
        "run": {"end_time_s": round((end - start) / c.speed_m_s, 6)},
        "output": {"directory": "runs", "fields": [], "timeseries_every_steps": 1},
        "free_surface": {"water_depth_m": depth},
        "ship": {"hull": "b063", "bow_angle_deg": c.bow_angle_deg, "speed_m_s": round(c.speed_m_s, 6),
                 "start_x_m": start, "tier": tier, "sphere_spacing_m": f["hull_spacing_m"],
                 "sphere_band_m": f["hull_band_m"]},
        "ice": {"concentration": c.concentration, "channel_length_m": f["channel_length_m"],
                "channel_start_x_m": channel_start, "spheres_per_edge": f["spheres_per_edge"]},
        "contact": {"stiffness_N_m": f["stiffness_N_m"], "dem_safety": f["dem_safety"],
                    "sample_interval_s": f["sample_interval_s"]},
    }


def case_scene(case: str, fidelity: str, tier: int = 1, **overrides):
    """A validated :class:`~iceresist.scene.schema.Scene` of one case; ``overrides`` replace section keys,
    e.g. ``ice={"channel_length_m": 0.3}``."""
    from iceresist.scene.schema import Scene

    data = scene_data(case, fidelity, tier)
    for section, values in overrides.items():
        data.setdefault(section, {}).update(values)
    scene = Scene.model_validate(data)
    scene._source_text = to_toml(data)
    scene._source_name = f"{data['scene']['name']}.toml"
    return scene


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    return repr(v)


def to_toml(data: dict) -> str:
    """TOML text of a scene dict (sections of scalars, lists and inline tables). TOML has no null: a key whose
    value is None is left out, which gives it its default (None for every optional scene key)."""
    lines = []
    for section, values in data.items():
        lines.append(f"[{section}]")
        for k, v in values.items():
            if v is not None:
                lines.append(f"{k} = {_toml_value(v)}")
        lines.append("")
    return "\n".join(lines)
