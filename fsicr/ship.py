"""Ship data for the FSICR calculator: main dimensions at the ice waterlines and propulsion.

Lengths in metres, areas in square metres, angles in degrees. The main fields hold the
upper ice waterline (UIWL); ``lower`` optionally gives the lower ice waterline (LIWL),
where every field left as ``None`` takes the upper-waterline value (the rules ask for
the calculation at both waterlines; at least the draught differs).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .errors import FsicrInputError
from .rules import KE_TABLE, PHI1_BULBOUS_DEG, PROPULSION_KINDS

#: Command-line flag of each field, for messages that tell the user what to change.
FLAGS = {
    "L_m": "--L",
    "B_m": "--B",
    "T_m": "--T",
    "LPAR_m": "--LPAR",
    "LBOW_m": "--LBOW",
    "Awf_m2": "--Awf",
    "alpha_deg": "--alpha",
    "phi1_deg": "--phi1",
    "phi2_deg": "--phi2",
    "bulbous_bow": "--bulbous-bow",
    "Dp_m": "--Dp",
    "n_propellers": "--propellers",
    "propulsion": "--propulsion",
}

#: Fields that describe one waterline (may differ between the upper and the lower one).
WATERLINE_FIELDS = ("L_m", "B_m", "T_m", "LPAR_m", "LBOW_m", "Awf_m2", "alpha_deg", "phi1_deg", "phi2_deg")

#: Meaning of each field, used in printed output and docs.
DESCRIPTIONS = {
    "L_m": "length between perpendiculars L [m]",
    "B_m": "maximum breadth B [m]",
    "T_m": "ice class draught T [m]",
    "LPAR_m": "length of the parallel midship body LPAR [m]",
    "LBOW_m": "length of the bow LBOW [m]",
    "Awf_m2": "area of the waterline of the bow Awf [m^2]",
    "alpha_deg": "angle of the waterline at B/4, alpha [deg]",
    "phi1_deg": "rake of the stem at the centreline, phi1 [deg]",
    "phi2_deg": "rake of the bow at B/4, phi2 [deg]",
}


def _label(field: str, prefix: str = "") -> str:
    flag = FLAGS.get(field)
    if flag and prefix:
        flag = "--" + prefix + flag[2:]
    return f"{prefix.replace('-', '_')}{field}" + (f" ({flag})" if flag else "")


def _check_number(value, field: str, prefix: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FsicrInputError(f"{_label(field, prefix)}: must be a number, got {value!r}")
    if not math.isfinite(value):
        raise FsicrInputError(f"{_label(field, prefix)}: must be a finite number, got {value!r}")
    return float(value)


#: Physical bounds of a ship, model or full scale (not the rules' range of validity, which gives warnings):
#: lengths from 1 cm (a model at 1:100) to 1 km, bow waterline areas up to 1 km^2. Outside them the formulas
#: overflow or divide by (nearly) zero, and the input is a slip of units or digits.
LENGTH_RANGE_M = (0.01, 1000.0)
AREA_MAX_M2 = 1.0e6


def _check_waterline_values(values: dict, prefix: str = "") -> None:
    """Physical sanity of one waterline's dimensions (not the rules' range of validity)."""
    lo, hi = LENGTH_RANGE_M
    for field, value in values.items():
        if value is None:
            continue
        v = _check_number(value, field, prefix)
        if field.endswith("_deg"):
            if not 0.0 < v <= 90.0:
                raise FsicrInputError(f"{_label(field, prefix)}: angle must be in (0, 90] degrees, got {v:g}")
        elif field == "LPAR_m":
            if not 0.0 <= v <= hi:
                raise FsicrInputError(f"{_label(field, prefix)}: length must be in [0, {hi:g}] m, got {v:g}")
        elif field.endswith("_m2"):
            if not 0.0 < v <= AREA_MAX_M2:
                raise FsicrInputError(f"{_label(field, prefix)}: must be in (0, {AREA_MAX_M2:g}] m^2, got {v:g}")
        elif not lo <= v <= hi:
            raise FsicrInputError(f"{_label(field, prefix)}: must be in [{lo:g}, {hi:g}] m (a ship at model or "
                                  f"full scale), got {v:g}")


@dataclass(frozen=True)
class LowerWaterline:
    """Dimensions at the lower ice waterline; ``None`` means "same as at the upper waterline"."""

    T_m: float
    L_m: float | None = None
    B_m: float | None = None
    LPAR_m: float | None = None
    LBOW_m: float | None = None
    Awf_m2: float | None = None
    alpha_deg: float | None = None
    phi1_deg: float | None = None
    phi2_deg: float | None = None

    def __post_init__(self):
        if self.T_m is None:
            raise FsicrInputError("lower_T_m (--lower-T): the lower ice waterline needs its draught")
        _check_waterline_values({f: getattr(self, f) for f in WATERLINE_FIELDS}, prefix="lower-")


@dataclass(frozen=True)
class Ship:
    """A ship for the FSICR engine-output rules (FSICR 2017, 3.2.2), main fields at the upper ice waterline.

    ``bulbous_bow``: the rules then take phi1 = 90 deg (see :attr:`phi1_effective_deg`).
    ``Dp_m``, ``n_propellers`` and ``propulsion`` ("cp", "fp", "electric", "hydraulic") are
    needed for the engine output only.
    """

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
    lower: LowerWaterline | None = None
    name: str = ""

    def __post_init__(self):
        _check_waterline_values({f: getattr(self, f) for f in WATERLINE_FIELDS})
        if not isinstance(self.bulbous_bow, bool):
            raise FsicrInputError(f"{_label('bulbous_bow')}: must be true or false, got {self.bulbous_bow!r}")
        if self.Dp_m is not None:
            dp = _check_number(self.Dp_m, "Dp_m", "")
            lo, hi = LENGTH_RANGE_M
            if not lo <= dp <= hi:
                raise FsicrInputError(f"{_label('Dp_m')}: propeller diameter must be in [{lo:g}, {hi:g}] m, "
                                      f"got {dp:g}")
        if isinstance(self.n_propellers, bool) or self.n_propellers not in KE_TABLE:
            raise FsicrInputError(f"{_label('n_propellers')}: must be 1, 2 or 3, got {self.n_propellers!r}")
        if self.propulsion not in PROPULSION_KINDS:
            raise FsicrInputError(
                f"{_label('propulsion')}: must be one of {', '.join(PROPULSION_KINDS)}, got {self.propulsion!r}"
            )
        if self.lower is not None and not isinstance(self.lower, LowerWaterline):
            raise FsicrInputError(f"lower: must be a LowerWaterline, got {type(self.lower).__name__}")
        if self.lower is not None and self.lower.T_m > self.T_m:
            raise FsicrInputError(f"{_label('T_m', 'lower-')}: the lower ice waterline ({self.lower.T_m:g} m) lies "
                                  f"deeper than the upper one ({_label('T_m')} = {self.T_m:g} m); the lower ice "
                                  f"waterline is the lightest draught: give a value <= {self.T_m:g}")

    @property
    def phi1_effective_deg(self) -> float:
        """Stem angle the rules use: 90 deg for a bulbous bow, else phi1."""
        return PHI1_BULBOUS_DEG if self.bulbous_bow else float(self.phi1_deg)

    def at_lower_waterline(self) -> Ship | None:
        """This ship with the lower-waterline dimensions (None where no lower waterline is given)."""
        if self.lower is None:
            return None
        changes = {f: getattr(self.lower, f) for f in WATERLINE_FIELDS if getattr(self.lower, f) is not None}
        return dataclasses.replace(self, lower=None, **changes)

    def waterlines(self) -> tuple[tuple[str, Ship], ...]:
        """(label, ship at that waterline) for the upper and, where given, the lower ice waterline."""
        lower = self.at_lower_waterline()
        return (("upper", self),) if lower is None else (("upper", self), ("lower", lower))

    def to_dict(self) -> dict:
        """Plain dict (JSON-ready) of the inputs, ``lower`` as a dict of its given fields."""
        out = dataclasses.asdict(self)
        if self.lower is not None:
            out["lower"] = {k: v for k, v in dataclasses.asdict(self.lower).items() if v is not None}
        out["phi1_effective_deg"] = self.phi1_effective_deg
        return out
