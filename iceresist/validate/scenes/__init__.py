"""Scene files of the reference cases that run bodies (``sphere_drag.toml``, ``floating_cube.toml``,
``settling_sphere.toml``): each is the middle rung of its case's quick ladder and runs as it stands with
``iceresist run``; the case reads it and sets a rung's parameters over it (:func:`scene_data`)."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path


def scene_path(name: str) -> Path:
    """The scene file of case ``name``."""
    return Path(str(resources.files(__name__) / f"{name}.toml"))


def scene_data(name: str) -> dict:
    """The parsed data of the scene file of case ``name`` (a fresh dict: a rung changes it freely)."""
    return tomllib.loads(scene_path(name).read_text(encoding="utf-8"))
