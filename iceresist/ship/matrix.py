"""A user's test matrix around their own hull: ``iceresist sweep --matrix FILE.toml`` or the matrix flags.

A matrix file (docs/OWN_SHIP.md)::

    [hull]
    mesh = "my_hull.stl"        # a path relative to this file, or "b063" (the shipped B-063 mesh at 1:25)
    mesh_scale = 1              # the scale the mesh is drawn at: 1 full scale, 25 a 1:25 model
    draught_m = 6.0             # at the mesh's scale
    propeller_diameter_m = 4.0  # full scale; with it the table gives the required engine output
    ice_class = "IA"

    [matrix]
    preset = "quick"
    tier = 1
    scale = 25                  # model scale(s) 1:lambda
    concentration = [0.5, 0.68, 0.88]
    speed_knots = [3, 5, 7]     # full scale
    ice_size_m = 1.0            # full-scale edge of the ice pieces
    ice_thickness_m = 1.0       # full scale (default: the edge, cubes)
    channel_width_m = 35.0      # full scale (default: across the tank, 1.99 beams)
    ahead = ["bow", "stern"]    # going ahead with either end

Every list is one axis of the matrix; a single value is an axis of one. Each case runs at model scale (lengths /
lambda, speed / sqrt(lambda), Froude scaling) in a tank sized from the hull (:mod:`iceresist.ship.sizing`); the
table gives it at full scale beside FSICR R_CH of the same mesh at the same scale. A case's name says its
concentration and full-scale speed, and each other value where it differs from the default (``-s40`` a 1:40 model,
``-e0.8m`` ice edge, ``-h0.5m`` thickness, ``-w30m`` channel, ``-stern``), so a larger matrix of the same hull in the
same folder runs only its new cases.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from iceresist.errors import InputError
from iceresist.ship.cases import FIDELITIES, REFERENCE_ICE_M, Case
from iceresist.ship.meshhull import MeshHull, resolve_mesh_path

#: The paper's scale and full-scale ice edge: the defaults of a matrix.
DEFAULT_SCALE = 25.0
DEFAULT_ICE_EDGE_M = REFERENCE_ICE_M * DEFAULT_SCALE
#: Mesh axes and what going ahead with the other end turns them into.
OTHER_END = {"+x": "-x", "-x": "+x", "+y": "-y", "-y": "+y"}


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _axis(v):
    return v if isinstance(v, list) else [v]


class HullSpec(_Section):
    """``[hull]``: the mesh and what the FSICR power needs."""

    mesh: str = Field("b063", min_length=1, description="STL or OBJ path (relative to the matrix file) or `b063`.")
    name: str | None = Field(None, max_length=60, description="The hull's name in the report (default: the file's).")
    mesh_unit: Literal["m", "cm", "mm", "ft", "in"] = "m"
    mesh_bow: Literal["+x", "-x", "+y", "-y"] = "+x"
    mesh_up: Literal["+x", "-x", "+y", "-y", "+z", "-z"] = "+z"
    mesh_scale: float | None = Field(None, gt=0, description="The scale the mesh is drawn at (1 full scale; default 1, "
                                                             "25 for `b063`).")
    draught_m: float | None = Field(None, gt=0, description="Draught at the mesh's scale (default 0.44 for `b063`).")
    propeller_diameter_m: float | None = Field(None, gt=0, description="Full-scale propeller diameter (m).")
    propellers: Literal[1, 2, 3] = 1
    propulsion: Literal["cp", "fp", "electric", "hydraulic"] = "cp"
    ice_class: Literal["IA Super", "IA", "IB", "IC"] = "IA"

    @property
    def drawn_at(self) -> float:
        return self.mesh_scale if self.mesh_scale is not None else (DEFAULT_SCALE if self.mesh == "b063" else 1.0)

    @property
    def mesh_draught_m(self) -> float:
        if self.draught_m is not None:
            return self.draught_m
        if self.mesh == "b063":
            return 0.44
        raise InputError("hull.draught_m: missing; give the hull's draught at the mesh's scale, e.g. draught_m = 6.0")


class MatrixAxes(_Section):
    """``[matrix]``: the preset and tier, and the axes (full-scale values)."""

    preset: Literal[tuple(FIDELITIES)] = "quick"
    tier: Literal[1, 2] = 1
    amr: bool = False
    scale: list[float] = Field([DEFAULT_SCALE], min_length=1)
    concentration: list[float] = Field(..., min_length=1)
    speed_knots: list[float] = Field(..., min_length=1)
    ice_size_m: list[float] = Field([DEFAULT_ICE_EDGE_M], min_length=1)
    ice_thickness_m: list[float | None] = Field([None], min_length=1)
    channel_width_m: list[float | None] = Field([None], min_length=1)
    ahead: list[Literal["bow", "stern"]] = Field(["bow"], min_length=1)

    @field_validator("scale", "concentration", "speed_knots", "ice_size_m", "ice_thickness_m", "channel_width_m",
                     "ahead", mode="before")
    @classmethod
    def _one_or_many(cls, v):
        return _axis(v)

    @field_validator("scale", "speed_knots", "ice_size_m", "ice_thickness_m", "channel_width_m")
    @classmethod
    def _positive(cls, v):
        bad = [x for x in v if x is not None and not x > 0]
        if bad:
            raise ValueError(f"must be > 0 (got {bad[0]})")
        return v

    @field_validator("concentration")
    @classmethod
    def _fraction(cls, v):
        bad = [x for x in v if not 0 < x <= 1]
        if bad:
            raise ValueError(f"a fraction in (0, 1], e.g. 0.68 for 68 % (got {bad[0]})")
        return v


class _MatrixFile(_Section):
    hull: HullSpec = HullSpec()
    matrix: MatrixAxes


@dataclass(frozen=True)
class MatrixCase:
    """One case of a sweep: the :class:`Case` (model scale) and, for a mesh hull, its ``[ship]`` keys and the hull
    (None: the parametric B-063 of the presets)."""

    case: Case
    hull_keys: dict | None = None
    hull: MeshHull | None = None

    @property
    def name(self) -> str:
        return self.case.name


@dataclass(frozen=True)
class Matrix:
    """A hull and the axes of its test matrix (:data:`cases` in matrix order)."""

    hull: HullSpec
    axes: MatrixAxes
    source: str = "matrix.toml"

    @property
    def mesh_path(self) -> str:
        path = resolve_mesh_path(self.hull.mesh, self.source)
        return str(Path(path).resolve()) if Path(path).is_file() else path

    @property
    def hull_name(self) -> str:
        return self.hull.name or Path(self.hull.mesh).stem

    def cases(self) -> dict[str, MatrixCase]:
        """Every case, name -> :class:`MatrixCase`, reading each (end, scale) of the mesh once."""
        a = self.axes
        out = {}
        for scale, ahead, edge, thick, width, conc, knots in itertools.product(
                a.scale, a.ahead, a.ice_size_m, a.ice_thickness_m, a.channel_width_m, a.concentration, a.speed_knots):
            name = case_name(conc, knots, scale, edge, thick, width, ahead)
            ship, hull = hull_at(self.hull, self.mesh_path, scale, ahead, name=self.hull_name)
            case = Case(bow="A" if ahead == "bow" else "B", concentration=conc,
                        knots=_round(knots / math.sqrt(scale)), scale=scale, ice_size_m=_round(edge / scale),
                        ice_thickness_m=None if thick is None else _round(thick / scale),
                        channel_width_m=None if width is None else _round(width / scale), label=name)
            out[name] = MatrixCase(case, ship, hull)
        return out

    def describe(self) -> dict:
        """What a sweep folder records of its matrix (``sweep.json``): the hull and the axes."""
        return {"hull": {**self.hull.model_dump(), "mesh": self.mesh_path}, "axes": self.axes.model_dump()}


def hull_at(spec: HullSpec, mesh_path: str, scale: float, ahead: str = "bow", *, name: str | None = None,
            keys=None) -> tuple[dict, MeshHull]:
    """The ``[ship]`` keys and the read hull of ``spec``'s mesh (at ``mesh_path``) as a 1:``scale`` model going ahead
    with ``ahead`` ("bow" or "stern": the mesh's bow axis turned); ``keys``: the names bad input is reported under."""
    factor = spec.drawn_at / scale  # mesh lengths -> model lengths
    ship = {"hull": "mesh", "mesh_file": mesh_path, "mesh_unit": spec.mesh_unit,
            "mesh_bow": spec.mesh_bow if ahead == "bow" else OTHER_END[spec.mesh_bow], "mesh_up": spec.mesh_up,
            "mesh_scale": _round(1.0 / factor), "draught_m": _round(spec.mesh_draught_m * factor)}
    if ship["mesh_scale"] == 1.0:
        del ship["mesh_scale"]
    hull = MeshHull.from_file(mesh_path, ship["draught_m"], unit=spec.mesh_unit, bow=ship["mesh_bow"],
                              up=spec.mesh_up, scale=ship.get("mesh_scale", 1.0), name=name,
                              **({"keys": keys} if keys is not None else {}))
    return ship, hull


def _round(x: float) -> float:
    return float(f"{x:.9g}")


def case_name(conc, knots, scale, edge, thick, width, ahead) -> str:
    """``c68-v5kn`` and each value that is not the default (module docstring)."""
    name = f"c{round(100 * conc):d}-v{knots:g}kn"
    if scale != DEFAULT_SCALE:
        name += f"-s{scale:g}"
    if abs(edge - DEFAULT_ICE_EDGE_M) > 1e-9:
        name += f"-e{edge:g}m"
    if thick is not None and thick != edge:
        name += f"-h{thick:g}m"
    if width is not None:
        name += f"-w{width:g}m"
    return name + ("-stern" if ahead == "stern" else "")


def read_matrix(path) -> Matrix:
    """A matrix file, checked; one line naming the key on bad input."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"--matrix: cannot read {str(path)[:80]!r} ({type(exc).__name__}); give a matrix TOML file "
                         f"(docs/OWN_SHIP.md)") from None
    try:
        data = _MatrixFile.model_validate(tomllib.loads(text))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p.name}: TOML syntax error: {exc}") from None
    except ValidationError as exc:
        raise InputError(f"{p.name}: {_first_error(exc)}") from None
    return Matrix(data.hull, data.matrix, str(p))


def matrix_from_flags(hull: HullSpec, flags: dict | None = None, **axes) -> Matrix:
    """A matrix of the ``iceresist sweep`` flags (values None are left to the defaults); ``flags`` names the flag of
    each axis for messages (default ``--<axis>``)."""
    try:
        m = MatrixAxes.model_validate({k: v for k, v in axes.items() if v is not None})
    except ValidationError as exc:
        err = exc.errors()[0]
        axis = str(err["loc"][0])
        flag = (flags or {}).get(axis, f"--{axis.replace('_', '-')}")
        got = f" (got {err['input']!r})" if err["type"] == "literal_error" else ""
        raise InputError(f"{flag}: {err['msg'].removeprefix('Value error, ')}{got[:60]}") from None
    return Matrix(hull, m, "flags")


def _first_error(exc: ValidationError) -> str:
    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"] if not isinstance(p, int))
    more = f" [and {len(exc.errors()) - 1} more]" if len(exc.errors()) > 1 else ""
    got = f" (got {err['input']!r})" if "input" in err and not isinstance(err["input"], dict) else ""
    return f"{where}: {err['msg'].removeprefix('Value error, ')}{got[:80]}{more}"
