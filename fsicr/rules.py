"""Constants and tables of the Finnish-Swedish Ice Class Rules 2017 (chapter 3, engine output).

Source: "Finnish-Swedish Ice Class Rules 2017" (TRAFI/494131/03.04.01.00/2016, in force
1 December 2017), section 3.2 (required engine output of new ships), as quoted in
Watanabe, Hu and Aoki (2023) eqs. (22)-(26) and section 4.2 for C3, C4, C5.
All quantities in SI units: N, m, degrees for angles, kW for power.
"""

from __future__ import annotations

from .errors import FsicrInputError

#: Ice classes in the rules' own spelling, strongest first.
ICE_CLASSES = ("IA Super", "IA", "IB", "IC")

#: Thickness of the brash ice in mid channel H_M [m] per ice class.
HM_BY_CLASS_M = {"IA Super": 1.0, "IA": 1.0, "IB": 0.8, "IC": 0.6}

#: Minimum engine output per ice class [kW].
MIN_POWER_KW = {"IA Super": 2800.0, "IA": 1000.0, "IB": 1000.0, "IC": 1000.0}

#: Brash-ice coefficients of eq. (22): C3, C4 [kg/(m^2 s^2) = N/m^3], C5 [kg/s^2 = N/m].
C3 = 845.0
C4 = 42.0
C5 = 825.0

#: Consolidated-layer coefficients (IA Super only); angles enter in degrees.
F1 = 23.0  # N/m^2
F2 = 45.8  # N/m
F3 = 14.7  # N/m
F4 = 29.0  # N/m^2
G1 = 1530.0  # N
G2 = 170.0  # N/m
G3 = 400.0  # N/m^1.5

#: Lower bound of the friction-and-bow-shape coefficient C_mu (eq. 23).
C_MU_MIN = 0.45
#: psi at or below which C_psi = 0 [deg] (eq. 24).
PSI_CPSI_ZERO_DEG = 45.0
#: Bounds of the shape factor (L T / B^2)^3 in eq. (22).
SHAPE_FACTOR_MIN = 5.0
SHAPE_FACTOR_MAX = 20.0
#: Stem angle used for a bulbous bow [deg].
PHI1_BULBOUS_DEG = 90.0

#: Propulsion kinds; "cp", "electric" and "hydraulic" share one Ke column, "fp" the other.
PROPULSION_KINDS = ("cp", "fp", "electric", "hydraulic")

#: Ke for conventional propulsion: {number of propellers: (CP or electric/hydraulic, FP)}.
KE_TABLE = {1: (2.03, 2.26), 2: (1.44, 1.60), 3: (1.18, 1.31)}

#: Range of validity of the R_CH formula: (name, lower, upper, unit).
#: Outside it the rules ask for model tests or another approved method.
VALIDITY_RANGES = (
    ("alpha", 15.0, 55.0, "deg"),
    ("phi1", 25.0, 90.0, "deg"),
    ("phi2", 45.0, 90.0, "deg"),
    ("L", 65.0, 250.0, "m"),
    ("B", 11.0, 40.0, "m"),
    ("T", 4.0, 15.0, "m"),
    ("LBOW/L", 0.15, 0.40, ""),
    ("LPAR/L", 0.25, 0.75, ""),
    ("Dp/T", 0.45, 0.75, ""),
    ("Awf/(L*B)", 0.09, 0.27, ""),
)


def parse_ice_class(text: str) -> str:
    """Return the rules' spelling of an ice class ("IA Super", "IA", "IB", "IC").

    Accepts case, spaces, underscores and hyphens freely, "1A" for "IA" and "IAS" for "IA Super".
    """
    if not isinstance(text, str):
        raise FsicrInputError(f"ice class: must be text, one of {', '.join(ICE_CLASSES)}; got {text!r}")
    key = text.upper().replace(" ", "").replace("_", "").replace("-", "")
    if key.startswith("1"):
        key = "I" + key[1:]
    table = {"IASUPER": "IA Super", "IAS": "IA Super", "IA": "IA", "IB": "IB", "IC": "IC"}
    if key not in table:
        raise FsicrInputError(f"ice class: unknown class {text!r}; allowed: {', '.join(ICE_CLASSES)}")
    return table[key]


def ke_coefficient(n_propellers: int, propulsion: str) -> float:
    """Ke of the engine-output formula for conventional propulsion (FSICR 2017, 3.2.2)."""
    if n_propellers not in KE_TABLE:
        raise FsicrInputError(f"n_propellers (--propellers): must be 1, 2 or 3, got {n_propellers!r}")
    if propulsion not in PROPULSION_KINDS:
        raise FsicrInputError(f"propulsion (--propulsion): must be one of {', '.join(PROPULSION_KINDS)}, got {propulsion!r}")
    cp_or_electric, fixed_pitch = KE_TABLE[n_propellers]
    return fixed_pitch if propulsion == "fp" else cp_or_electric
