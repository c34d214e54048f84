"""Range of validity of the FSICR 2017 R_CH formula: one warning per parameter outside it.

Outside the range the rules ask for model tests (or another approved method) instead of the
formula; the calculator still computes R_CH and reports each parameter that is outside.
"""

from __future__ import annotations

from .rules import VALIDITY_RANGES
from .ship import Ship


def validity_values(ship: Ship) -> dict[str, float | None]:
    """The checked quantities of one waterline (phi1 as the rules use it; Dp/T None without Dp)."""
    return {
        "alpha": ship.alpha_deg,
        "phi1": ship.phi1_effective_deg,
        "phi2": ship.phi2_deg,
        "L": ship.L_m,
        "B": ship.B_m,
        "T": ship.T_m,
        "LBOW/L": ship.LBOW_m / ship.L_m,
        "LPAR/L": ship.LPAR_m / ship.L_m,
        "Dp/T": None if ship.Dp_m is None else ship.Dp_m / ship.T_m,
        "Awf/(L*B)": ship.Awf_m2 / (ship.L_m * ship.B_m),
    }


def validity_warnings(ship: Ship, waterline: str = "upper") -> tuple[str, ...]:
    """One line per parameter outside the range of validity, naming it, its value and the range."""
    values = validity_values(ship)
    out = []
    for name, lo, hi, unit in VALIDITY_RANGES:
        value = values[name]
        if value is None or lo <= value <= hi:
            continue
        u = f" {unit}" if unit else ""
        out.append(
            f"{waterline} ice waterline: {name} = {value:.4g}{u} is outside the FSICR 2017 range of validity "
            f"{lo:g}-{hi:g}{u}; the rules then ask for model tests"
        )
    return tuple(out)
