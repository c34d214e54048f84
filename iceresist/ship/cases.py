"""The paper's ship runs (section 3) as data: ``cases.toml`` beside this module, read once and checked.

Six cases (names ``<bow>-c<percent>-v<knots>``) at two fidelities, ``paper`` and ``quick`` (tier 1 = DEM with
water models; tier 2 = the coupled LBM-DEM, which changes the tank where the flow field makes it expensive:
``TIER2``). :func:`scene_data` turns one (case, fidelity, tier) into the sections of a scene file;
:func:`iceresist.scene.case_scenes.case_scene` validates them. This module imports nothing from the scene package,
so the scene schema may check case names against :data:`CASES`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from iceresist.errors import InputError
from iceresist.ship.hull import b063_hull
from iceresist.ship.sizing import BLOCK_CELLS, Reference, lattice_cells, size_case

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
    regrid_slack: float = Field(default=0.0, ge=0)
    regrid_lookahead_steps: int = Field(default=0, ge=0)


#: The keys of a preset's ``[tier2.<preset>.amr]`` that are a scene's ``[refinement]``.
REFINEMENT_KEYS = ("levels", "surface_band_m", "body_band_m", "regrid_every_steps", "regrid_slack",
                   "regrid_lookahead_steps")


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
    """One ship run: bow (``"A"``/``"B"``: for a mesh hull ``"A"`` goes ahead with the mesh's bow, ``"B"`` with its
    other end), concentration (fraction) and speed (knots at model scale, the paper's convention); a case of a
    user's matrix (:mod:`iceresist.ship.matrix`) also carries its model scale, the ice piece's edge and thickness
    and the channel width (m, model scale; None: the piece a cube, the channel across the tank) and its name."""

    bow: str
    concentration: float
    knots: float
    scale: float = 25.0
    ice_size_m: float | None = None
    ice_thickness_m: float | None = None
    channel_width_m: float | None = None
    label: str | None = None

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        return f"{self.bow}-c{round(100 * self.concentration):d}-v{self.knots:.1f}"

    @property
    def speed_m_s(self) -> float:
        return self.knots * KNOT_M_S

    @property
    def full_scale_knots(self) -> float:
        """The speed at full scale (knots), by Froude scaling: V_model sqrt(scale)."""
        return self.knots * math.sqrt(self.scale)

    @property
    def bow_angle_deg(self) -> float:
        return BOW_ANGLE_DEG[self.bow]

    def meta(self) -> dict:
        """What a case file records of the case (its ``meta``), beside its scene."""
        out = {"bow": self.bow, "concentration_nominal": self.concentration, "knots": self.knots,
               "scale": self.scale, "full_scale_knots": self.full_scale_knots}
        for key in ("ice_size_m", "ice_thickness_m", "channel_width_m"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out


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
    a = _amr(fidelity)
    domain = {"cells": list(a["cells"]), **({"dx_m": a["dx_m"]} if a.get("dx_m") else {})}
    return {"domain": domain, "free_surface": {"water_depth_m": a["water_depth_m"]},
            "refinement": {k: a[k] for k in REFINEMENT_KEYS}}


def _amr(fidelity: str) -> dict:
    a = TIER2.get(fidelity, {}).get("amr")
    if not a:
        raise InputError(f"--amr: refined levels are a tier-2 tank of the presets "
                         f"{', '.join(amr_fidelities()) or '(none)'}; use one of them with --tier 2")
    return a


#: The reference hull of every preset: B-063 (paper table 1 at 1:25), the hull its tanks were built around.
REFERENCE_HULL = b063_hull("A")
#: The ice cube of every preset (m): the paper's 41 mm.
REFERENCE_ICE_M = 0.041


def reference(fidelity: str, tier: int = 1, amr: bool = False) -> Reference:
    """The preset's tank, channel and ice around B-063 (:mod:`iceresist.ship.sizing`): tier 1 the paper's tank, tier 2
    the preset's lattice (cells x cell), on refined levels its level 0."""
    f = FIDELITIES[fidelity]
    if tier == 1:
        tank, depth, start = tuple(DOMAIN_M), WATER_DEPTH_M, CHANNEL_START_X_M
    else:
        t2 = TIER2[fidelity]
        cells, dx, depth, start = t2["cells"], t2["dx_m"], t2["water_depth_m"], t2["channel_start_x_m"]
        if amr:
            a = _amr(fidelity)
            cells, dx, depth = a["cells"], a.get("dx_m") or dx, a["water_depth_m"]
        tank = tuple(n * dx for n in cells)
    h = REFERENCE_HULL
    return Reference(length_overall_m=h.length_overall_m, beam_m=h.beam_m, draught_m=h.draught_m,
                     waterline_length_m=h.waterline_length_m, end_length_m=h.end_length_m, tank_m=tank,
                     water_depth_m=depth, channel_start_x_m=start, channel_length_m=f["channel_length_m"],
                     ice_size_m=REFERENCE_ICE_M)


#: The shortest steady window a case may have, in waterline lengths of its hull: the quick preset's on B-063.
MIN_WINDOW_HULL_LENGTHS = reference("quick").window_hull_lengths


def scene_data(case, fidelity: str, tier: int = 1, amr: bool = False, *, hull_keys: dict | None = None,
               hull=None) -> dict:
    """The scene of one case (a name of :data:`CASES` or a :class:`Case`) as a dict of TOML sections (validated by
    :class:`~iceresist.scene.schema.Scene`); ``amr``: tier 2 on the refined levels of the preset's
    ``[tier2.<fidelity>.amr]``. ``hull``: the hull to size the tank, channel and window around
    (:func:`iceresist.ship.sizing.size_case`; default B-063, the presets' own numbers) with ``hull_keys`` the
    ``[ship]`` keys that make it (a mesh's file, unit, axes, scale and draught)."""
    c = case if isinstance(case, Case) else get_case(case)
    if fidelity not in FIDELITIES:
        raise InputError(f"--preset: unknown preset {fidelity!r}; use one of {', '.join(FIDELITIES)}")
    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    if amr and tier != 2:
        raise InputError("amr: refined levels are a tier-2 tank; set tier = 2 (--tier 2)")
    f = FIDELITIES[fidelity]
    ref = reference(fidelity, tier, amr)
    geometry = hull if hull is not None else b063_hull(c.bow)
    q = (c.ice_size_m or ref.ice_size_m) / ref.ice_size_m  # the ice piece over the preset's
    sized = size_case(geometry, ref, channel_width_m=c.channel_width_m)
    if tier == 1:
        domain = {"size_m": list(sized.tank_m), "dx_m": _scaled(f["dx_m"], q)}
        fluid = {"nu_m2_s": 1.0e-6, "rho_kg_m3": 1000.0, "gravity_m_s2": [0.0, 0.0, -9.81]}
        numerics = {"precision": "float64", "backend": "auto"}
    else:
        t2 = TIER2[fidelity]
        dx = _scaled((_amr(fidelity).get("dx_m") if amr else None) or t2["dx_m"], q)
        domain = {"cells": lattice_cells(sized.tank_m, dx, BLOCK_CELLS if amr else 1), "dx_m": dx}
        fluid = {"nu_m2_s": t2["nu_m2_s"], "rho_kg_m3": 1000.0, "gravity_m_s2": [0.0, 0.0, -9.81],
                 "operator": "cumulant"}
        numerics = {"precision": "float32", "backend": "auto", "mach": t2["mach"]}
    start, end = sized.start_x_m, sized.end_x_m
    what = (f"B-063 Bow {c.bow}" if hull is None else
            f"{getattr(hull, 'name', 'mesh hull')} ({'its bow' if c.bow == 'A' else 'its other end'} ahead, 1:{c.scale:g})")
    ship_keys = {"hull": "b063", "bow_angle_deg": c.bow_angle_deg} if hull is None else dict(hull_keys or {})
    out = {
        "scene": {"name": f"ship_{fidelity}_t{tier}{'_amr' if amr else ''}_{c.name}",
                  "description": f"{what}, {100 * c.concentration:g} % brash ice, {c.knots:g} knots "
                                 f"({c.speed_m_s:.3f} m/s), {fidelity} fidelity, tier {tier}"},
        "domain": {**domain,
                   "faces": {k: "wall" for k in ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")}},
        "fluid": fluid,
        "numerics": numerics,
        "run": {"end_time_s": round((end - start) / c.speed_m_s, 6)},
        "output": {"directory": "runs", "fields": [], "timeseries_every_steps": 1},
        "free_surface": {"water_depth_m": sized.water_depth_m},
        "ship": {**ship_keys, "speed_m_s": round(c.speed_m_s, 6), "start_x_m": start, "tier": tier,
                 "sphere_spacing_m": _scaled(f["hull_spacing_m"], q), "sphere_band_m": _scaled(f["hull_band_m"], q)},
        "ice": {"concentration": c.concentration, "channel_length_m": sized.channel_length_m,
                "channel_start_x_m": sized.channel_start_x_m, "spheres_per_edge": f["spheres_per_edge"],
                **_ice_piece(c, sized)},
        "contact": {"stiffness_N_m": _scaled(f["stiffness_N_m"], q * q), "dem_safety": f["dem_safety"],
                    **({"dashpot": f["dashpot"]} if f["dashpot"] != "sphere_pair" else {}),
                    "sample_interval_s": f["sample_interval_s"]},
    }
    if amr:
        refinement = {k: _amr(fidelity)[k] for k in REFINEMENT_KEYS}
        out["refinement"] = refinement
        out["scene"]["description"] += f", on {refinement['levels'] + 1} refined levels"
    return out


def _scaled(value: float, factor: float) -> float:
    """A preset's length, stiffness, ... for another ice piece (``factor`` 1: the preset's number, untouched)."""
    return value if factor == 1.0 else float(f"{value * factor:.6g}")


def _ice_piece(c: Case, sized) -> dict:
    """The ``[ice]`` keys of a case's ice piece and channel width (none for the presets' 41 mm cube across the
    tank). A piece thinner or thicker than its edge is a square floe of one size (an ice field, no yaw)."""
    out = {}
    if c.ice_size_m is not None:
        out["size_m"] = c.ice_size_m
        if c.ice_thickness_m is not None and c.ice_thickness_m != c.ice_size_m:
            out.update(size_distribution="uniform", size_min_m=c.ice_size_m, size_max_m=c.ice_size_m,
                       thickness_m=c.ice_thickness_m, yaw="none")
    if c.channel_width_m is not None:
        out["channel_width_m"] = sized.channel_width_m
    return out
