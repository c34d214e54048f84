"""Scene presets of the paper's ship runs (section 3) at two fidelities, and the sweep matrix.

The paper runs seven conditions, one of which is shared: concentration 50 / 68 / 88 % at 1 knot with Bow A,
speed 1 / 1.5 / 2 knots at 68 % with Bow A (68 % at 1 knot is the same run) and Bow B at 68 %, 1 knot: six
distinct cases. Names: ``<bow>-c<percent>-v<knots>``.

Fidelities (tier 1 = DEM with water models; tier 2 = the coupled LBM-DEM):

* ``paper``: the paper's tank (11.15 x 1.39 x 1.39 m, depth 1.11 m), the full 1.39 x 5.56 m channel, cubes of
  3 x 3 x 3 surface spheres, hull spheres 20 mm apart, k = 1e4 N/m; the run lasts until the stem reaches the
  channel end, and the steady window holds the whole waterline inside the channel. Tier 2 at the paper's
  finest cell 2.72 mm.
* ``quick``: a 1.39 m long channel (same width, pitch and concentration: 28 x 28 cubes at 68 %), cubes of 2 x 2 x 2 corner spheres,
  hull spheres 30 mm apart up to 6 cm above the waterline, a softer contact (k = 5e3 N/m) with a larger
  sub-step; the ship stops when the stem leaves the channel. It trades away: the parallel middle body never
  runs fully in ice (the steady window starts once the bow wedge is in, so side friction along the whole
  body is missing), a short window (about 0.8 m of travel, so a wide confidence interval), rounder cubes
  and a softer contact. Runs in well under a minute per case on a 2-core x86 VM. Tier 2 at 10.9 mm cells.
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
    start = CHANNEL_START_X_M - 0.05
    end = CHANNEL_START_X_M + f["channel_length_m"]
    return {
        "scene": {"name": f"ship_{fidelity}_t{tier}_{c.name}",
                  "description": f"B-063 Bow {c.bow}, {100 * c.concentration:g} % brash ice, {c.knots:g} knots "
                                 f"({c.speed_m_s:.3f} m/s), {fidelity} fidelity, tier {tier}"},
        "domain": {"size_m": list(DOMAIN_M), "dx_m": f["dx_m"],
                   "faces": {k: "wall" for k in ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")}},
        "fluid": {"nu_m2_s": 1.0e-6, "rho_kg_m3": 1000.0, "gravity_m_s2": [0.0, 0.0, -9.81]},
        "numerics": {"precision": "float64" if tier == 1 else "float32", "backend": "auto"},
        "run": {"end_time_s": round((end - start) / c.speed_m_s, 6)},
        "output": {"directory": "runs", "fields": [], "timeseries_every_steps": 1},
        "free_surface": {"water_depth_m": WATER_DEPTH_M},
        "ship": {"hull": "b063", "bow_angle_deg": c.bow_angle_deg, "speed_m_s": round(c.speed_m_s, 6),
                 "start_x_m": start, "tier": tier, "sphere_spacing_m": f["hull_spacing_m"],
                 "sphere_band_m": f["hull_band_m"]},
        "ice": {"concentration": c.concentration, "channel_length_m": f["channel_length_m"],
                "channel_start_x_m": CHANNEL_START_X_M, "spheres_per_edge": f["spheres_per_edge"]},
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
    """TOML text of a scene dict (sections of scalars, lists and inline tables)."""
    lines = []
    for section, values in data.items():
        lines.append(f"[{section}]")
        for k, v in values.items():
            lines.append(f"{k} = {_toml_value(v)}")
        lines.append("")
    return "\n".join(lines)
