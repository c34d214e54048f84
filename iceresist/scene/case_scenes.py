"""Scene presets of the paper's ship runs (section 3) at two fidelities, and the sweep matrix.

The cases, fidelities, tier-2 tanks and their notes are data (``cases.toml``, read by :mod:`iceresist.ship.cases`,
whose names this module re-exports); :func:`case_scene` builds the validated scene of one case.
"""

from __future__ import annotations

from iceresist.scene.schema import Scene
from iceresist.scene.write import to_toml
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


def case_scene(case, fidelity: str, tier: int = 1, amr: bool = False, *, hull=None, hull_keys: dict | None = None,
               **overrides) -> Scene:
    """A validated :class:`~iceresist.scene.schema.Scene` of one case (a name or a :class:`Case`; ``amr``: tier 2 on
    the preset's refined levels; ``hull`` with its ``[ship]`` keys ``hull_keys``: a mesh hull the tank is sized
    around); ``overrides`` replace section keys, e.g. ``ice={"channel_length_m": 0.3}``."""
    data = scene_data(case, fidelity, tier, amr, hull_keys=hull_keys, hull=hull)
    for section, values in overrides.items():
        data.setdefault(section, {}).update(values)
    scene = Scene.model_validate(data)
    scene._source_text = to_toml(data)
    scene._source_name = f"{data['scene']['name']}.toml"
    return scene
