"""Blockage of a towing tank and the limiting (critical) speed of a ship in it, after Schijf (1949).

A hull of midship section A_s in a tank of section W h (width W, water depth h) blocks the fraction
m = A_s / (W h). The water the hull displaces must flow back past it, and the water level beside it drops. In
one-dimensional channel hydraulics (continuity and Bernoulli over the section, Schijf 1949) a steady return flow
exists only below a limiting depth Froude number F_L = U_L / sqrt(g h), the root in (0, 1) of

    1 - m + F^2 / 2 - (3/2) F^(2/3) = 0,   that is   F_L = [2 sin(arcsin(1 - m) / 3)]^(3/2)

(with s = F^(2/3) the equation is the cubic s^3 - 3 s + 2 (1 - m) = 0, solved by s = 2 sin(theta),
sin(3 theta) = 1 - m; F_L = 1 in open water, m = 0). Faster than U_L the ship pushes a bore ahead of it and the
flow past the hull is not steady: neither a towing tank nor a tank of the simulation gives a steady resistance
there. The paper's tank (1.39 m wide, 1.11 m deep, m = 0.20) has F_L = 0.47 against F_h = 0.31 at 2 knots.

Reference: J. B. Schijf, "Protection of embankments and bed in inland and maritime waters, and in overflows or
weirs", XVII International Navigation Congress (PIANC), Lisbon, 1949.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from iceresist.errors import InputError
from iceresist.units import GRAVITY_M_S2


def blockage_ratio(midship_area_m2: float, width_m: float, depth_m: float) -> float:
    """m = A_s / (W h): the part of the tank's wet section the hull fills."""
    if not (width_m > 0 and depth_m > 0):
        raise InputError(f"tank: width and water depth must be > 0 (got {width_m} m, {depth_m} m)")
    return float(midship_area_m2) / (float(width_m) * float(depth_m))


def depth_froude(speed_m_s: float, depth_m: float, g_m_s2: float = GRAVITY_M_S2) -> float:
    """F_h = U / sqrt(g h)."""
    return float(speed_m_s) / math.sqrt(g_m_s2 * float(depth_m))


def schijf_limit_froude(blockage: float) -> float:
    """Schijf's limiting depth Froude number F_L(m) (module docstring); 0 for a fully blocked tank (m >= 1)."""
    if blockage >= 1.0:
        return 0.0
    if blockage < 0.0:
        raise InputError(f"tank: blockage ratio must be >= 0 (got {blockage})")
    return (2.0 * math.sin(math.asin(1.0 - blockage) / 3.0)) ** 1.5


@dataclass(frozen=True)
class TankFlow:
    """A hull moving in a tank: blockage m, depth Froude number F_h, Schijf's limit F_L."""

    blockage: float
    depth_froude: float
    limit_froude: float

    @property
    def fraction_of_limit(self) -> float:
        """F_h / F_L: below 1 a steady return flow exists."""
        return self.depth_froude / self.limit_froude if self.limit_froude > 0 else math.inf

    @property
    def subcritical(self) -> bool:
        return self.fraction_of_limit < 1.0

    def describe(self) -> dict:
        return {"blockage": self.blockage, "depth_froude": self.depth_froude,
                "schijf_limit_froude": self.limit_froude, "fraction_of_limit": self.fraction_of_limit}


def tank_flow(midship_area_m2: float, width_m: float, depth_m: float, speed_m_s: float) -> TankFlow:
    m = blockage_ratio(midship_area_m2, width_m, depth_m)
    return TankFlow(m, depth_froude(speed_m_s, depth_m), schijf_limit_froude(m))
