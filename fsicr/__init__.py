"""Finnish-Swedish Ice Class Rules (2017): brash-ice channel resistance R_CH and required engine output.

Imports nothing from the engine. Public API::

    from fsicr import Ship, LowerWaterline, r_ch, r_ch_at_waterlines, required_power, load_ship
"""

from .errors import FsicrInputError
from .power import PowerResult, required_power
from .resistance import ResistanceResult, r_ch, r_ch_at_waterlines
from .ship import LowerWaterline, Ship
from .shipfile import load_ship

__all__ = [
    "FsicrInputError",
    "LowerWaterline",
    "PowerResult",
    "ResistanceResult",
    "Ship",
    "load_ship",
    "r_ch",
    "r_ch_at_waterlines",
    "required_power",
]
