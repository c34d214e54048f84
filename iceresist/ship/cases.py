"""The paper's ship runs (section 3) as data: ``cases.toml`` beside this module, read once and checked.

Six cases (names ``<bow>-c<percent>-v<knots>``) at two fidelities, ``paper`` and ``quick`` (tier 1 = DEM with
water models; tier 2 = the coupled LBM-DEM, which changes the tank where the flow field makes it expensive:
``TIER2``). :func:`scene_data` turns one (case, fidelity, tier) into the sections of a scene file;
:func:`iceresist.ship.presets.case_scene` validates them. This module imports nothing from the scene package,
so the scene schema may check case names against :data:`CASES`.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from iceresist.errors import InputError

DATA_FILE = "cases.toml"


class _Data(BaseModel):
    model_config = ConfigDict(extra="forbid")


class _CaseRow(_Data):
    bow: Literal["A", "B"]
    concentration: float = Field(gt=0, lt=1)
    knots: float = Field(gt=0)


class _Tank(_Data):
    domain_m: tuple[float, float, float]
    water_depth_m: float = Field(gt=0)
    channel_start_x_m: float = Field(gt=0)


class _Fidelity(_Data):
    channel_length_m: float = Field(gt=0)
    spheres_per_edge: int = Field(ge=1)
    hull_spacing_m: float = Field(gt=0)
    hull_band_m: float = Field(gt=0)
    stiffness_N_m: float = Field(gt=0)
    dem_safety: float = Field(gt=0, le=1)
    dashpot: Literal["sphere_pair", "face"] = "sphere_pair"
    sample_interval_s: float = Field(gt=0)
    dx_m: float = Field(gt=0)


class _Amr(_Data):
    levels: int = Field(ge=1)
    cells: tuple[int, int, int]
    #: level 0's cell (m); default the preset's tier-2 cell
    dx_m: float | None = Field(default=None, gt=0)
    water_depth_m: float = Field(gt=0)
    surface_band_m: float = Field(gt=0)
    body_band_m: float = Field(gt=0)
    regrid_every_steps: int = Field(ge=1)


class _Tier2(_Data):
    cells: tuple[int, int, int]
    dx_m: float = Field(gt=0)
    water_depth_m: float = Field(gt=0)
    channel_start_x_m: float = Field(gt=0)
    mach: float = Field(gt=0)
    nu_m2_s: float = Field(gt=0)
    amr: _Amr | None = None


class _Notes(_Data):
    tier1: str = Field(min_length=1)
    tier2: str = Field(min_length=1)


class _CaseFile(_Data):
    cases: list[_CaseRow] = Field(min_length=1)
    knot_m_s: float = Field(gt=0)
    bow_angle_deg: dict[Literal["A", "B"], float]
    tank: _Tank
    fidelity: dict[str, _Fidelity]
    tier2: dict[str, _Tier2]
    notes: dict[str, _Notes]


def _load() -> _CaseFile:
    text = (resources.files(__package__) / DATA_FILE).read_text(encoding="utf-8")
    try:
        data = _CaseFile.model_validate(tomllib.loads(text))
    except (tomllib.TOMLDecodeError, ValidationError) as exc:  # a broken package file, not a user's input
        raise RuntimeError(f"iceresist/ship/{DATA_FILE}: {exc}") from None
    if not set(data.fidelity) == set(data.tier2) == set(data.notes):
        raise RuntimeError(f"iceresist/ship/{DATA_FILE}: [fidelity], [tier2] and [notes] must name the same "
                           f"presets (got {sorted(data.fidelity)}, {sorted(data.tier2)}, {sorted(data.notes)})")
    return data


_DATA = _load()

KNOT_M_S = _DATA.knot_m_s
DOMAIN_M = _DATA.tank.domain_m
WATER_DEPTH_M = _DATA.tank.water_depth_m
CHANNEL_START_X_M = _DATA.tank.channel_start_x_m
BOW_ANGLE_DEG = dict(_DATA.bow_angle_deg)


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
        return BOW_ANGLE_DEG[self.bow]


CASES = {c.name: c for c in (Case(r.bow, r.concentration, r.knots) for r in _DATA.cases)}

#: Ice channel, DEM and hull spheres per fidelity: channel_length_m, spheres_per_edge, hull_spacing_m,
#: hull_band_m, stiffness_N_m, dem_safety, dashpot, sample_interval_s, dx_m (the tier-1 tank's nominal cell).
FIDELITIES = {name: f.model_dump() for name, f in _DATA.fidelity.items()}

#: Tier-2 (coupled LBM-DEM) tank and lattice per fidelity: domain cells, cell size, water depth, channel start,
#: lattice velocity limit, viscosity (m^2/s; 1e-6 = water).
TIER2 = {name: t.model_dump() for name, t in _DATA.tier2.items()}

#: What each fidelity is and what it trades away, one sentence per (fidelity, tier); plain text (the report
#: prints the quick ones beside its table).
FIDELITY_NOTES = {(name, tier): getattr(n, f"tier{tier}") for name, n in _DATA.notes.items() for tier in (1, 2)}


def case_names() -> list[str]:
    return list(CASES)


def get_case(name: str) -> Case:
    if name not in CASES:
        raise InputError(f"--cases: unknown case {name!r}; known cases: {', '.join(CASES)}")
    return CASES[name]


def amr_fidelities() -> list[str]:
    """The presets whose tier-2 tank also runs on refined levels."""
    return [name for name, t in TIER2.items() if t.get("amr")]


def amr_overrides(fidelity: str) -> dict:
    """The sections that put a preset's tier-2 tank on refined levels (its ``[tier2.<fidelity>.amr]``): the level-0
    tank's cells, the water depth and ``[refinement]``; merged over a tier-2 case's own (:func:`scene_data`, or
    the ``overrides`` of a sweep)."""
    a = TIER2.get(fidelity, {}).get("amr")
    if not a:
        raise InputError(f"--amr: refined levels are a tier-2 tank of the presets "
                         f"{', '.join(amr_fidelities()) or '(none)'}; use one of them with --tier 2")
    domain = {"cells": list(a["cells"]), **({"dx_m": a["dx_m"]} if a.get("dx_m") else {})}
    return {"domain": domain, "free_surface": {"water_depth_m": a["water_depth_m"]},
            "refinement": {k: a[k] for k in ("levels", "surface_band_m", "body_band_m", "regrid_every_steps")}}


def scene_data(case: str, fidelity: str, tier: int = 1, amr: bool = False) -> dict:
    """The scene of one case as a dict of TOML sections (validated by :class:`~iceresist.scene.schema.Scene`);
    ``amr``: tier 2 on the refined levels of the preset's ``[tier2.<fidelity>.amr]`` (:func:`amr_overrides`)."""
    c = get_case(case)
    if fidelity not in FIDELITIES:
        raise InputError(f"--preset: unknown preset {fidelity!r}; use one of {', '.join(FIDELITIES)}")
    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    if amr and tier != 2:
        raise InputError("amr: refined levels are a tier-2 tank; set tier = 2 (--tier 2)")
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
    out = {
        "scene": {"name": f"ship_{fidelity}_t{tier}{'_amr' if amr else ''}_{c.name}",
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
                    **({"dashpot": f["dashpot"]} if f["dashpot"] != "sphere_pair" else {}),
                    "sample_interval_s": f["sample_interval_s"]},
    }
    if amr:
        for section, values in amr_overrides(fidelity).items():
            out.setdefault(section, {}).update(values)
        out["scene"]["description"] += f", on {out['refinement']['levels'] + 1} refined levels"
    return out
