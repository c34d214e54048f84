"""Ship files: TOML read with tomllib, checked with pydantic v2 (unknown keys refused).

Keys are the :class:`fsicr.ship.Ship` field names (``L_m``, ``alpha_deg``, ...), plus
``name``, ``source``, ``ice_class`` and an optional ``[lower_waterline]`` table that needs
``T_m`` and may override any other waterline dimension. Every error becomes one
:class:`FsicrInputError` line naming the key and what is allowed.
"""

from __future__ import annotations

import importlib.resources
import tomllib
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError

from .errors import FsicrInputError, short_text, unusable_name
from .ship import DESCRIPTIONS, FLAGS, LowerWaterline, Ship


class LowerWaterlineModel(BaseModel):
    """``[lower_waterline]``: T_m required; other dimensions default to the upper waterline's."""

    model_config = ConfigDict(extra="forbid", strict=True)
    T_m: float
    L_m: float | None = None
    B_m: float | None = None
    LPAR_m: float | None = None
    LBOW_m: float | None = None
    Awf_m2: float | None = None
    alpha_deg: float | None = None
    phi1_deg: float | None = None
    phi2_deg: float | None = None


class ShipModel(BaseModel):
    """Schema of a ship file (and of the merged file + command-line data)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    name: str = ""
    source: str = ""
    ice_class: str | None = None
    L_m: float
    B_m: float
    T_m: float
    LPAR_m: float
    LBOW_m: float
    Awf_m2: float
    alpha_deg: float
    phi1_deg: float
    phi2_deg: float
    bulbous_bow: bool = False
    Dp_m: float | None = None
    n_propellers: int = 1
    propulsion: str = "cp"
    lower_waterline: LowerWaterlineModel | None = None


def builtin_ships() -> dict[str, Path]:
    """Ship files shipped with the package, by name without ``.toml``."""
    folder = importlib.resources.files("fsicr") / "ships"
    return {Path(p.name).stem: Path(str(p)) for p in folder.iterdir() if p.name.endswith(".toml")}


def resolve_ship_path(text: str) -> Path:
    """A path to an existing file, or the name of a built-in ship (``b063_bow_a``)."""
    path = Path(text)
    builtin = builtin_ships()
    try:
        if path.is_file():
            return path
        if Path(text).stem in builtin and not path.exists() and path.parent == Path("."):
            return builtin[Path(text).stem]
        why = "is not a file" if path.exists() else "not found"
    except (OSError, ValueError) as exc:  # a name the file system refuses (too long, a NUL byte)
        raise FsicrInputError(f"ship file: {unusable_name(text, exc, 'file')}; give a TOML file or a built-in "
                              f"ship: {', '.join(sorted(builtin))}") from None
    raise FsicrInputError(f"ship file {short_text(text)}: {why} (give a TOML file or a built-in ship: "
                          f"{', '.join(sorted(builtin))})")


def read_ship_file(text: str) -> dict[str, Any]:
    """The raw key/value table of a ship file."""
    path = resolve_ship_path(text)
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise FsicrInputError(f"ship file {text!r}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise FsicrInputError(f"ship file {text!r}: not a text file (byte {exc.start} is not UTF-8); give a TOML "
                              f"ship file such as fsicr/ships/b063_bow_a.toml") from None
    except OSError as exc:
        raise FsicrInputError(f"ship file {text!r}: cannot be read: {exc.strerror}") from None


def _flag(loc: tuple) -> str:
    if len(loc) == 2 and loc[0] == "lower_waterline":
        return "--lower-" + FLAGS.get(str(loc[1]), "--" + str(loc[1]))[2:]
    return FLAGS.get(str(loc[0]), "") if loc else ""


def _one_line(exc: ValidationError, where: str) -> str:
    """The first pydantic error as one line naming the key, its flag and what is allowed."""
    err = exc.errors()[0]
    loc = tuple(err["loc"])
    key = ".".join(str(p) for p in loc)
    flag = _flag(loc)
    named = f"'{key}'" + (f" ({flag})" if flag else "")
    kind, got = err["type"], err.get("input")
    if kind == "missing":
        what = DESCRIPTIONS.get(str(loc[-1]), str(loc[-1]))
        return f"{where}: missing field {named}: {what}; give it in the ship file or as {flag or 'a key'}"
    if kind == "extra_forbidden":
        fields = LowerWaterlineModel.model_fields if loc[0] == "lower_waterline" else ShipModel.model_fields
        return f"{where}: unknown key '{key}'; allowed keys: {', '.join(fields)}"
    if kind in ("float_type", "float_parsing", "finite_number"):
        return f"{where}: {named} must be a number, got {got!r}"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"{where}: {named} must be a whole number (1, 2 or 3 propellers), got {got!r}"
    if kind in ("bool_type", "bool_parsing"):
        return f"{where}: {named} must be true or false, got {got!r}"
    if kind == "string_type":
        return f"{where}: {named} must be text in quotes, got {got!r}"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"{where}: {named} must be a table ([{key}]) with T_m and optional dimensions, got {got!r}"
    return f"{where}: {named}: {err['msg']}"


def ship_from_mapping(data: dict[str, Any], where: str = "ship data") -> tuple[Ship, str | None, dict]:
    """Check ``data`` and build the :class:`Ship`; returns (ship, ice class or None, metadata)."""
    try:
        model = ShipModel.model_validate(data)
    except ValidationError as exc:
        raise FsicrInputError(_one_line(exc, where)) from None
    fields = model.model_dump(exclude={"name", "source", "ice_class", "lower_waterline"})
    lower = None
    if model.lower_waterline is not None:
        lower = LowerWaterline(**model.lower_waterline.model_dump())
    ship = Ship(**fields, lower=lower, name=model.name)
    return ship, model.ice_class, {"name": model.name, "source": model.source}


def load_ship(text: str) -> tuple[Ship, str | None, dict]:
    """Read and check a ship file (path or built-in name); returns (ship, ice class or None, metadata)."""
    return ship_from_mapping(read_ship_file(text), where=f"ship file {text!r}")
