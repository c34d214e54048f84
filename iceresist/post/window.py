"""Selection of the steady window of a time series, by time or by ship position.

The paper averages the ice force while the ship is fully inside the brash-ice
channel (section 4.2, figures 9 and 10, whose horizontal axis is the ship
position). A window is therefore given either as a time range ``window_s =
(t0, t1)`` in seconds or as a ship-position range ``window_m = (x0, x1)`` in
metres with the ship positions ``x_ship_m`` sampled beside the times. Both
bounds are inclusive.

Every check raises :class:`iceresist.errors.InputError` with a one-line
message that names the parameter and the fix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iceresist.errors import InputError

#: Relative spread of the sampling interval above which a record counts as non-uniform.
UNIFORM_DT_RTOL = 1e-2


@dataclass(frozen=True)
class WindowSamples:
    """Samples of one steady window.

    Attributes:
        t_s: sample times inside the window [s], strictly increasing.
        values: signal inside the window (unit of the input, e.g. N).
        dt_s: sampling interval [s] (mean over the window).
        label: the window as the user gave it, for messages (e.g. ``"window_s=(2, 8)"``).
    """

    t_s: np.ndarray
    values: np.ndarray
    dt_s: float
    label: str


def _as_1d_float(name: str, a) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 1:
        raise InputError(f"{name} must be a 1-D array of samples, got shape {arr.shape}")
    return arr


def _check_range(name: str, window, unit: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a pair (start, end) of numbers, got {window!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise InputError(f"{name}={window!r} must hold finite numbers")
    if not lo < hi:
        raise InputError(f"{name}=({lo:g}, {hi:g}) {unit} is empty: the start must be below the end")
    return lo, hi


def check_record(t_s, signal, signal_name: str = "signal") -> tuple[np.ndarray, np.ndarray]:
    """Validate a record (times, signal): same length, finite, strictly increasing uniform times.

    Returns both as 1-D float arrays.
    """
    t = _as_1d_float("t_s", t_s)
    y = _as_1d_float(signal_name, signal)
    if t.size != y.size:
        raise InputError(f"{signal_name} has {y.size} samples but t_s has {t.size}: give one value per time")
    if t.size < 2:
        raise InputError(f"t_s holds {t.size} sample(s): a record needs at least 2")
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(f"t_s[{i}] is {t[i]}: times must be finite")
    bad = np.flatnonzero(~np.isfinite(y))
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"{signal_name}[{i}] at t={t[i]:g} s is {y[i]} ({bad.size} non-finite samples): "
            "the signal must hold no NaN or inf; check the run for a blow-up"
        )
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        i = int(np.flatnonzero(dt <= 0.0)[0])
        raise InputError(
            f"t_s is not strictly increasing at index {i + 1} (t={t[i]:g} s then {t[i + 1]:g} s): "
            "sort the record and drop repeated times"
        )
    dt_mean = (t[-1] - t[0]) / (t.size - 1)
    spread = float(np.max(np.abs(dt - dt_mean)) / dt_mean)
    if spread > UNIFORM_DT_RTOL:
        raise InputError(
            f"t_s is not uniformly sampled (sampling interval varies by {100 * spread:.1f} %): "
            "interpolate the record onto uniform times first (numpy.interp)"
        )
    return t, y


def select_window(t_s, signal, *, window_s=None, window_m=None, x_ship_m=None,
                  signal_name: str = "signal") -> WindowSamples:
    """Cut the steady window out of a uniformly sampled record.

    Args:
        t_s: sample times [s], strictly increasing, uniform.
        signal: values at those times (any unit; finite).
        window_s: time range (t0, t1) [s], inclusive; or
        window_m: ship-position range (x0, x1) [m], inclusive, with
        x_ship_m: ship position at each time [m], monotonic (either direction; a ship at rest
            for a while is fine).
        signal_name: name of the signal in messages.

    With neither window the whole record is used. A window must lie inside the
    record (within half a sampling interval, or half a position step).
    """
    t, y = check_record(t_s, signal, signal_name)
    dt_s = float((t[-1] - t[0]) / (t.size - 1))
    if window_s is not None and window_m is not None:
        raise InputError("give either window_s (time range) or window_m (ship-position range), not both")
    if window_s is not None:
        lo, hi = _check_range("window_s", window_s, "s")
        label = f"window_s=({lo:g}, {hi:g}) s"
        tol = 0.5 * dt_s
        if lo < t[0] - tol or hi > t[-1] + tol:
            raise InputError(
                f"{label} reaches outside the record t_s in [{t[0]:g}, {t[-1]:g}] s: choose a window inside it"
            )
        mask = (t >= lo) & (t <= hi)
    elif window_m is not None:
        if x_ship_m is None:
            raise InputError("window_m needs x_ship_m, the ship position at each time [m]")
        x = _as_1d_float("x_ship_m", x_ship_m)
        if x.size != t.size:
            raise InputError(f"x_ship_m has {x.size} samples but t_s has {t.size}: give one position per time")
        if not np.all(np.isfinite(x)):
            i = int(np.flatnonzero(~np.isfinite(x))[0])
            raise InputError(f"x_ship_m[{i}] is {x[i]}: ship positions must be finite")
        dx = np.diff(x)
        if not (np.all(dx >= 0.0) or np.all(dx <= 0.0)) or not np.any(dx):
            raise InputError(
                "x_ship_m is not monotonic: a position window needs a ship moving one way; use window_s"
            )
        lo, hi = _check_range("window_m", window_m, "m")
        label = f"window_m=({lo:g}, {hi:g}) m"
        tol = 0.5 * float(np.max(np.abs(dx)))
        x_min, x_max = float(min(x[0], x[-1])), float(max(x[0], x[-1]))
        if lo < x_min - tol or hi > x_max + tol:
            raise InputError(
                f"{label} reaches outside the ship track x_ship_m in [{x_min:g}, {x_max:g}] m: "
                "choose a window inside it"
            )
        mask = (x >= lo) & (x <= hi)
    else:
        label = "whole record"
        mask = np.ones(t.size, dtype=bool)
    if not np.any(mask):
        raise InputError(f"{label} holds no samples (sampling interval {dt_s:g} s): widen the window")
    return WindowSamples(t_s=t[mask], values=y[mask], dt_s=dt_s, label=label)
