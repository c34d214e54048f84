"""Required engine output of a new ship (FSICR 2017, 3.2.2): P = Ke (R_CH/1000)^1.5 / Dp, class minimum."""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Mapping

from . import formulas
from .errors import FsicrInputError
from .resistance import ResistanceResult, r_ch_at_waterlines
from .rules import parse_ice_class
from .ship import Ship


@dataclass(frozen=True)
class PowerResult:
    """Engine output at each ice waterline, the class minimum and the required output (the largest)."""

    ice_class: str
    Ke: float
    Dp_m: float
    n_propellers: int
    propulsion: str
    resistances: tuple[ResistanceResult, ...]
    power_by_waterline_kW: Mapping[str, float]
    minimum_kW: float
    required_kW: float
    governing: str
    warnings: tuple[str, ...]

    def to_dict(self) -> dict:
        return {
            "ice_class": self.ice_class,
            "Ke": self.Ke,
            "Dp_m": self.Dp_m,
            "n_propellers": self.n_propellers,
            "propulsion": self.propulsion,
            "power_by_waterline_kW": dict(self.power_by_waterline_kW),
            "minimum_kW": self.minimum_kW,
            "required_kW": self.required_kW,
            "governing": self.governing,
            "warnings": list(self.warnings),
            "waterlines": [r.to_dict() for r in self.resistances],
        }


def required_power(ship: Ship, ice_class: str) -> PowerResult:
    """Required engine output [kW]: the larger of the two waterlines' outputs, not below the class minimum."""
    cls = parse_ice_class(ice_class)
    if ship.Dp_m is None:
        raise FsicrInputError("Dp_m (--Dp): propeller diameter missing; the engine output needs it (m, > 0)")
    k = formulas.ke(ship.n_propellers, ship.propulsion)
    results = r_ch_at_waterlines(ship, cls)
    by_wl = {r.waterline: formulas.engine_power(r.r_ch_N, k, ship.Dp_m) for r in results}
    minimum = formulas.minimum_power(cls)
    top_wl = max(by_wl, key=by_wl.get)
    required = max(by_wl[top_wl], minimum)
    governing = f"{top_wl} ice waterline" if by_wl[top_wl] >= minimum else f"class minimum ({cls})"
    warnings = tuple(w for r in results for w in r.warnings)
    return PowerResult(
        ice_class=cls,
        Ke=k,
        Dp_m=float(ship.Dp_m),
        n_propellers=ship.n_propellers,
        propulsion=ship.propulsion,
        resistances=results,
        power_by_waterline_kW=types.MappingProxyType(by_wl),
        minimum_kW=minimum,
        required_kW=required,
        governing=governing,
        warnings=warnings,
    )
