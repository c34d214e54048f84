"""Ice resistance from the recorded contact force on the hull.

Ice resistance (paper section 4.2) is the sum of the DEM contact forces that the
ice exerts on the hull, projected on the direction of motion and counted
positive when it opposes the motion; water resistance is excluded. For a ship
moving in +x the resistance is therefore ``R = -F_x``; for a ship moving in -x
it is ``R = +F_x``. The direction is the parameter ``motion_direction``
(+1 or -1), never guessed.
"""

from __future__ import annotations

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
                                   confidence: float = 0.95) -> SteadyMean:
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

    Returns:
        :class:`SteadyMean` of the resistance R [N] (positive opposes the motion).
    """
    r_n = resistance_from_contact_force(Fx_N, motion_direction)
    return steady_mean(t_s, r_n, window_s=window_s, window_m=window_m, x_ship_m=x_ship_m,
                       n_batches=n_batches, confidence=confidence, signal_name="Fx_N")
