"""Scene files: the TOML schema (:mod:`.schema`), the loader (:mod:`.load`) and built-in scenes (``presets/``)."""

from iceresist.scene.load import load_scene, parse_scene, preset_names, preset_text
from iceresist.scene.schema import Scene

__all__ = ["Scene", "load_scene", "parse_scene", "preset_names", "preset_text"]
