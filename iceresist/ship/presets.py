"""Scene presets of the paper's ship runs (section 3) at two fidelities, and the sweep matrix.

The cases, fidelities, tier-2 tanks and their notes are data (``cases.toml``, read by :mod:`iceresist.ship.cases`,
whose names this module re-exports); :func:`case_scene` builds the validated scene of one case.
"""

from __future__ import annotations

from iceresist.scene.schema import Scene
from iceresist.ship.cases import (
    CASES,
    CHANNEL_START_X_M,
    DOMAIN_M,
    FIDELITIES,
    FIDELITY_NOTES,
    KNOT_M_S,
    TIER2,
    WATER_DEPTH_M,
    Case,
    case_names,
    get_case,
    scene_data,
)

__all__ = ["CASES", "CHANNEL_START_X_M", "DOMAIN_M", "FIDELITIES", "FIDELITY_NOTES", "KNOT_M_S", "TIER2",
           "WATER_DEPTH_M", "Case", "case_names", "case_scene", "get_case", "scene_data", "to_toml"]


def case_scene(case: str, fidelity: str, tier: int = 1, **overrides) -> Scene:
    """A validated :class:`~iceresist.scene.schema.Scene` of one case; ``overrides`` replace section keys,
    e.g. ``ice={"channel_length_m": 0.3}``."""
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
