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

The start wave (:func:`start_wave`). A ship that starts at full speed U sends long waves both ways. In the
linear long-wave equations (Lamb, Hydrodynamics, ch. VIII) the hull's ends act as a source and a sink of flux
U A_s: the bow pushes water ahead, the stern leaves a hollow. Each sends half its flux each way at
c = sqrt(g h). Ahead of the bow the water stands eta = U A_s / (2 W c) high and moves forward at
u = g eta / c = U m / 2, until the stern's negative wave catches the bow and cancels it. That takes
t_s = L_s / (c - U), where L_s is the spacing of the source and the sink. With the hull's section area A(x),
the centroid of the bow's source -dA/dx lies V_end / A_s ahead of the full section. So L_s = V / A_s exactly,
the displaced volume over the midship section (the prismatic length C_P L). In a long tank the water ahead
of the bow is at rest after t_s, apart from the bow's own local flow; before t_s a measured resistance is
that of a ship pushing ice that drifts away from it. The estimate is linear in m and F_h; near Schijf's
limit the disturbance is larger.

References: J. B. Schijf, "Protection of embankments and bed in inland and maritime waters, and in overflows
or weirs", XVII International Navigation Congress (PIANC), Lisbon, 1949. H. Lamb, Hydrodynamics, 6th ed.,
Cambridge University Press, 1932, chapter VIII (long waves in canals).
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


@dataclass(frozen=True)
class StartWave:
    """The long wave of an impulsive start ahead of the bow (module docstring): ``level_m`` eta,
    ``drift_m_s`` u, ``duration_s`` t_s after the start, for a ship at ``speed_m_s``."""

    level_m: float
    drift_m_s: float
    duration_s: float
    speed_m_s: float

    @property
    def run_up_m(self) -> float:
        """Distance the ship covers before the stern's wave reaches the bow: U t_s."""
        return self.speed_m_s * self.duration_s

    def window_fraction(self, window_start_s: float, window_end_s: float) -> float:
        """Part of the window [start, end] (s after the start) that lies before t_s, in [0, 1]."""
        span = float(window_end_s) - float(window_start_s)
        if not span > 0:  # also a ship at rest (an infinite window)
            return 0.0
        return min(1.0, max(0.0, (self.duration_s - float(window_start_s)) / span))

    def warning(self, window_start_s: float, window_end_s: float) -> str | None:
        """A one-line warning when the steady window starts before t_s, else None."""
        part = self.window_fraction(window_start_s, window_end_s)
        if part <= 0.0:
            return None
        return (f"the steady window starts {window_start_s:.2f} s after the ship's impulsive start, before the "
                f"stern's start wave reaches the bow ({self.duration_s:.2f} s, linear long-wave estimate): over "
                f"the first {100 * part:.0f} % of the window the water ahead of the bow drifts forward at about "
                f"{self.drift_m_s:.2g} m/s ({100 * self.drift_m_s / self.speed_m_s:.0f} % of the ship's speed) in "
                f"a tank of any length; a run-up of {self.run_up_m:.2f} m before the window (ship.start_x_m "
                f"further aft, or a later ship.steady_window_m) avoids it")

    def describe(self) -> dict:
        return {"level_m": self.level_m, "drift_m_s": self.drift_m_s, "duration_s": self.duration_s,
                "run_up_m": self.run_up_m}


def start_wave(midship_area_m2: float, width_m: float, depth_m: float, speed_m_s: float,
               source_spacing_m: float, g_m_s2: float = GRAVITY_M_S2) -> StartWave:
    """The start wave of a hull of midship section A_s (m^2) started at ``speed_m_s`` in a tank ``width_m``
    wide and ``depth_m`` deep; ``source_spacing_m`` L_s = V / A_s (module docstring). t_s is infinite at or
    above the long-wave speed c."""
    m = blockage_ratio(midship_area_m2, width_m, depth_m)
    c = math.sqrt(g_m_s2 * float(depth_m))
    u = float(speed_m_s)
    if not source_spacing_m > 0:
        raise InputError(f"tank: the hull's source spacing V / A_s must be > 0 (got {source_spacing_m} m)")
    duration = float(source_spacing_m) / (c - u) if u < c else math.inf
    return StartWave(level_m=u * midship_area_m2 / (2.0 * float(width_m) * c), drift_m_s=0.5 * m * u,
                     duration_s=duration, speed_m_s=u)
