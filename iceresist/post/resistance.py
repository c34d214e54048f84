"""Ice resistance from the recorded contact force on the hull.

Ice resistance (paper section 4.2) is the sum of the DEM contact forces that the
ice exerts on the hull, projected on the direction of motion and counted
positive when it opposes the motion; water resistance is excluded. For a ship
moving in +x the resistance is therefore ``R = -F_x``; for a ship moving in -x
it is ``R = +F_x``. The direction is the parameter ``motion_direction``
(+1 or -1), never guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iceresist.errors import InputError
from iceresist.post.statistics import SteadyMean, steady_mean


def resistance_from_contact_force(Fx_N, motion_direction: int = +1):
    """Ice resistance [N] from the x-component of the ice contact force on the hull [N].

    R = -motion_direction * Fx: positive when the ice pushes against the motion.
    """
    if motion_direction not in (1, -1):
        raise InputError(f"motion_direction={motion_direction!r} must be +1 (ship moves in +x) or -1 (in -x)")
    return -float(motion_direction) * np.asarray(Fx_N, dtype=float)


def ice_resistance_from_timeseries(t_s, Fx_N, x_ship_m=None, *, window_s=None, window_m=None,
                                   motion_direction: int = +1, n_batches: int | None = None,
                                   confidence: float = 0.95, warn_short_batches: bool = True) -> SteadyMean:
    """Mean ice resistance over the steady window with its batch-means uncertainty.

    Args:
        t_s: sample times [s], strictly increasing and uniform.
        Fx_N: x-component of the ice contact force on the hull [N] (model scale).
        x_ship_m: ship position at each sample [m]; needed for window_m.
        window_s: steady window as a time range (t0, t1) [s]; or
        window_m: steady window as a ship-position range (x0, x1) [m]. Neither: whole record.
        motion_direction: +1 when the ship moves in +x (R = -Fx), -1 when it moves in -x (R = +Fx).
        n_batches: batch count; None chooses it from the autocorrelation time.
        confidence: confidence level of the interval.
        warn_short_batches: see :func:`~iceresist.post.statistics.steady_mean`.

    Returns:
        :class:`SteadyMean` of the resistance R [N] (positive opposes the motion).
    """
    r_n = resistance_from_contact_force(Fx_N, motion_direction)
    return steady_mean(t_s, r_n, window_s=window_s, window_m=window_m, x_ship_m=x_ship_m,
                       n_batches=n_batches, confidence=confidence, signal_name="Fx_N",
                       warn_short_batches=warn_short_batches)


#: Batches per half of the window in :func:`window_halves` (a half of a short window holds too few samples for
#: the automatic count; the interval of each half is then likely too narrow, which makes the check stricter).
HALF_WINDOW_BATCHES = 5


@dataclass(frozen=True)
class WindowHalves:
    """Mean ice resistance over the first and the second half of a steady window (:func:`window_halves`)."""

    first: SteadyMean
    second: SteadyMean

    @property
    def change_N(self) -> float:
        """Second-half mean minus first-half mean (N)."""
        return self.second.mean_N - self.first.mean_N

    @property
    def change_ci_N(self) -> float:
        """Half-width of the interval of the change: the two halves' half-widths added in quadrature."""
        return math.hypot(self.first.ci_half_width_N, self.second.ci_half_width_N)

    @property
    def ratio(self) -> float:
        """Second-half mean over first-half mean (NaN when the first is not positive)."""
        return self.second.mean_N / self.first.mean_N if self.first.mean_N > 0 else math.nan

    @property
    def steady(self) -> bool:
        """The halves agree: the change lies within its interval. False means the force is still rising or
        falling across the window, so its mean depends on where the window ends."""
        return abs(self.change_N) <= self.change_ci_N


def window_parts(t_s, Fx_N, x_ship_m=None, *, edges_s=None, edges_m=None, motion_direction: int = +1,
                 n_batches: int = HALF_WINDOW_BATCHES, confidence: float = 0.95) -> list[SteadyMean]:
    """Mean ice resistance over consecutive parts of a record: :func:`ice_resistance_from_timeseries` between
    each pair of neighbouring ``edges_s`` (s) or ``edges_m`` (ship position, m), ``n_batches`` batch means
    each. Does the force settle along the channel? Read the means part by part. Parts are short by design, so
    short batches are not warned of; each part's ``interval_too_narrow`` says so."""
    if (edges_s is None) == (edges_m is None):
        raise InputError("window_parts needs exactly one of edges_s (s) and edges_m (m)")
    edges = np.asarray(edges_s if edges_s is not None else edges_m, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.diff(edges) > 0):
        raise InputError(f"window edges {edges.tolist()} must be two or more increasing values")
    key = "window_s" if edges_s is not None else "window_m"
    return [ice_resistance_from_timeseries(t_s, Fx_N, x_ship_m, motion_direction=motion_direction,
                                           n_batches=n_batches, confidence=confidence,
                                           warn_short_batches=False, **{key: (lo, hi)})
            for lo, hi in zip(edges[:-1], edges[1:])]


def window_halves(t_s, Fx_N, x_ship_m=None, *, window_s=None, window_m=None, motion_direction: int = +1,
                  n_batches: int = HALF_WINDOW_BATCHES, confidence: float = 0.95) -> WindowHalves:
    """The steadiness check of a steady window: :func:`window_parts` over each half of it (split at the
    middle of ``window_s`` or ``window_m``), ``n_batches`` batch means each."""
    if (window_s is None) == (window_m is None):
        raise InputError("window_halves needs exactly one of window_s (s) and window_m (m)")
    lo, hi = (float(v) for v in (window_s if window_s is not None else window_m))
    edges = (lo, 0.5 * (lo + hi), hi)
    key = {"edges_s": edges} if window_s is not None else {"edges_m": edges}
    return WindowHalves(*window_parts(t_s, Fx_N, x_ship_m, motion_direction=motion_direction,
                                      n_batches=n_batches, confidence=confidence, **key))
