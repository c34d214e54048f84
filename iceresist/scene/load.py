"""Read a scene file into a :class:`~iceresist.scene.schema.Scene`; every failure is one line naming the key.

Messages look like ``scene.toml: domain.dx_m: must be > 0 (got -1)`` and are
raised as :class:`iceresist.errors.InputError` (the CLI prints them and exits 2).
"""

from __future__ import annotations

import re
import tomllib
import typing
from importlib import resources
from pathlib import Path

from pydantic import BaseModel, ConfigDict, ValidationError

from fsicr.errors import unusable_name

from iceresist.errors import InputError, StabilityError
from iceresist.scene.schema import CaseBase, Scene, Ship
from iceresist.scene.write import toml_value
from iceresist.ship.cases import scene_data
from iceresist.ship.meshhull import MeshHull

PRESETS_PACKAGE = "iceresist.scene.presets"
DEFAULT_PRESET = "cavity"

_KEYED = re.compile(r"^([A-Za-z_][A-Za-z0-9_.\[\]]*): (.+)$", re.S)


def _show(value) -> str:
    """A value as TOML would write it (a table as the words "a table"; a long one shortened)."""
    text = "a table" if isinstance(value, dict) else toml_value(value)
    return text if len(text) <= 80 else f"{text[:60]}... ({len(text)} characters)"


def _model_at(loc) -> type[BaseModel] | None:
    """The model class whose fields live at ``loc`` (a path of keys and list indices below Scene)."""
    cls = Scene
    for part in loc:
        if isinstance(part, int):
            continue
        field = cls.model_fields.get(part)
        if field is None:
            return None
        nxt = None
        stack = [field.annotation]
        while stack:
            ann = stack.pop()
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                nxt = ann
                break
            stack.extend(typing.get_args(ann))
        if nxt is None:
            return None
        cls = nxt
    return cls


def _path(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


_TYPE_WORDS = {"int": "an integer", "float": "a number", "string": "text in quotes", "bool": "true or false",
               "tuple": "a list", "list": "a list", "dict": "a table", "model": "a table"}


def _describe(err) -> tuple[str, bool]:
    """(message, show the input?) for one pydantic error."""
    t, ctx = err["type"], err.get("ctx") or {}
    bounds = {"greater_than": (">", "gt"), "greater_than_equal": (">=", "ge"), "less_than": ("<", "lt"),
              "less_than_equal": ("<=", "le")}
    if t in bounds:
        op, key = bounds[t]
        return f"must be {op} {ctx[key]:g}", True
    if t == "missing":
        return "required key is missing", False
    if t == "literal_error":
        return f"must be one of {ctx.get('expected', '')}", True
    if t == "string_pattern_mismatch":
        return "must start with a letter, digit or '_' and hold only letters, digits, '_', '.' and '-'", True
    if t == "string_too_short":
        return "must not be empty", True
    if t == "string_too_long":
        return f"must be at most {ctx.get('max_length')} characters (it has {len(err.get('input', ''))})", False
    if t in ("too_short", "too_long"):
        n = ctx.get("min_length") if t == "too_short" else ctx.get("max_length")
        return f"must have {n} items" if isinstance(err.get("input"), (list, tuple)) else \
            f"must be at most {n} characters", True
    for prefix, word in _TYPE_WORDS.items():
        if t.startswith(prefix + "_") or t == prefix + "_type":
            return f"must be {word}", True
    return err["msg"][:1].lower() + err["msg"][1:], True


def format_validation_error(exc: ValidationError, source: str) -> str:
    """One line for the first error of ``exc``: ``source: section.key: what is wrong (got value)``."""
    errors = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")  # a misspelt key first
    err = errors[0]
    loc = tuple(err["loc"])
    if err["type"] == "missing" and loc and isinstance(loc[-1], int):
        n = loc[-1] + 1
        loc, err = loc[:-1], dict(err, type="too_short", ctx={"min_length": n})
    if err["type"] == "extra_forbidden":
        cls = _model_at(loc[:-1])
        allowed = ", ".join(cls.model_fields) if cls is not None else ""
        msg = f"unknown key (allowed: {allowed})" if allowed else "unknown key"
    elif err["type"] == "value_error":
        text = str(err.get("ctx", {}).get("error", err["msg"]))
        text = text.removeprefix("Value error, ")
        m = _KEYED.match(text)
        if m:
            loc = loc + tuple(re.split(r"\.", m.group(1)))
            text = m.group(2)
        msg = text
    else:
        msg, show = _describe(err)
        if show and "input" in err and not isinstance(err["input"], dict):
            msg += f" (got {_show(err['input'])})"
    where = _path(loc) or "(top level)"
    more = f" [and {len(errors) - 1} more]" if len(errors) > 1 else ""
    return f"{source}: {where}: {msg}{more}".replace("\n", " ")


class _CaseOnly(BaseModel):
    """The ``[case]`` table of a scene file, checked before the rest (the other keys wait for the merge)."""

    model_config = ConfigDict(extra="ignore")
    case: CaseBase


def _mesh_hull(data: dict, source: str) -> tuple[dict | None, "MeshHull | None"]:
    """A ``[case]`` scene whose ``[ship]`` is a mesh: its mesh keys and the hull, read once here so the case's tank,
    channel and window are sized around it (:func:`iceresist.ship.sizing.size_case`); (None, None) otherwise."""
    ship = data.get("ship")
    if not isinstance(ship, dict) or ship.get("hull") != "mesh":
        return None, None
    try:
        keys = Ship.model_validate({"speed_m_s": 0.0, **{k: v for k, v in ship.items() if k in MESH_KEYS}})
    except ValidationError:  # the scene's own check names the key in full
        return None, None
    hull = MeshHull.from_file(keys.mesh_file, keys.draught_m, unit=keys.mesh_unit, bow=keys.mesh_bow,
                              up=keys.mesh_up, scale=keys.mesh_scale, scene_source=source)
    return {k: getattr(keys, k) for k in MESH_KEYS}, hull


#: The ``[ship]`` keys that make a mesh hull.
MESH_KEYS = ("hull", "mesh_file", "mesh_unit", "mesh_bow", "mesh_up", "mesh_scale", "draught_m")


def _with_case(data: dict, source: str = "scene.toml") -> dict:
    """The scene data with its ``[case]`` (if any) expanded: the case's sections
    (:func:`iceresist.ship.cases.scene_data`), each changed by the keys the file's section of that name gives."""
    if "case" not in data:
        return data
    case = _CaseOnly.model_validate(data).case
    ship, hull = _mesh_hull(data, source)
    merged = scene_data(case.name, case.fidelity, case.tier, case.amr, hull_keys=ship, hull=hull)
    for section, values in data.items():
        if isinstance(values, dict) and isinstance(merged.get(section), dict):
            merged[section] = {**merged[section], **values}
        else:
            merged[section] = values
    return merged


def parse_scene(text: str, source: str = "scene.toml") -> Scene:
    """Parse TOML text into a checked Scene (schema and stability); InputError on any problem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: TOML syntax error: {exc}") from None
    try:
        scene = Scene.model_validate(_with_case(data, source))
    except ValidationError as exc:
        raise InputError(format_validation_error(exc, source)) from None
    try:
        if scene.has_lattice:
            scene.units()
    except StabilityError as exc:
        raise StabilityError(f"{source}: {exc}") from None
    scene._source_text = text
    scene._source_name = source
    return scene


def preset_names() -> list[str]:
    """Names of the built-in scenes (``iceresist/scene/presets/*.toml``)."""
    return sorted(p.name[:-5] for p in resources.files(PRESETS_PACKAGE).iterdir() if p.name.endswith(".toml"))


def preset_text(name: str) -> str:
    """The TOML text of a built-in scene."""
    res = resources.files(PRESETS_PACKAGE) / f"{name}.toml"
    if not res.is_file():
        raise InputError(f"no built-in scene {name!r} (built-in: {', '.join(preset_names())})")
    return res.read_text(encoding="utf-8")


def load_scene(path) -> Scene:
    """Read a scene file (or, where no such file exists, a built-in scene of that name)."""
    p = Path(path)
    source = str(path)
    try:
        is_file, exists = p.is_file(), p.exists()
    except (OSError, ValueError) as exc:  # a name the file system refuses (too long, a NUL byte)
        raise InputError(f"{unusable_name(source, exc, 'scene file')}; give the path of a scene file") from None
    if is_file:
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{source}: cannot read the scene file: {exc}") from None
        return parse_scene(text, source)
    if p.suffix == "" and p.name in preset_names():
        return parse_scene(preset_text(p.name), f"{p.name} (built-in)")
    if exists:
        raise InputError(f"{source}: not a file")
    raise InputError(f"{source}: no such scene file (built-in scenes: {', '.join(preset_names())})")
