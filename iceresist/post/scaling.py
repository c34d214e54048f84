"""Model scale <-> full scale by Froude similarity.

With geometric scale ``scale = lambda = L_full / L_model`` (25 in the paper,
section 4.1) and equal Froude number Fn = V / sqrt(g L):

    length  L_full = L_model lambda
    speed   V_full = V_model lambda^(1/2)
    time    t_full = t_model lambda^(1/2)
    force   F_full = F_model lambda^3 (rho_full / rho_model)     (the "cubic law", section 4.2)
    power   P_full = P_model lambda^(7/2) (rho_full / rho_model)

The density ratio corrects for model tests in fresh water (1000 kg/m^3) set
against sea water at full scale (about 1025 kg/m^3); it is 1 by default, as in
the paper. Each ``*_to_model_scale`` function inverts its ``*_to_full_scale``
partner. All functions accept scalars or NumPy arrays.
"""

from __future__ import annotations

import numpy as np

from iceresist.errors import InputError

#: Geometric scale of the paper's model ship B-063 against the table-1 ship.
PAPER_SCALE = 25.0
#: Density of sea water at full scale [kg/m^3] (a common design value).
RHO_SEA_WATER_KG_M3 = 1025.0
#: Density of fresh water in a model basin [kg/m^3].
RHO_FRESH_WATER_KG_M3 = 1000.0


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}={value!r} must be a positive number") from None
    if not (np.isfinite(v) and v > 0.0):
        raise InputError(f"{name}={value!r} must be a positive finite number")
    return v


def _force_factor(scale, density_ratio) -> float:
    return _positive("scale", scale) ** 3 * _positive("density_ratio", density_ratio)


def force_to_full_scale(F_model_N, scale: float, density_ratio: float = 1.0):
    """Full-scale force [N] from a model-scale force [N]: F_model scale^3 density_ratio (cubic law)."""
    return _times(F_model_N, _force_factor(scale, density_ratio))


def force_to_model_scale(F_full_N, scale: float, density_ratio: float = 1.0):
    """Model-scale force [N] from a full-scale force [N]: F_full / (scale^3 density_ratio)."""
    return _times(F_full_N, 1.0 / _force_factor(scale, density_ratio))


def speed_to_full_scale(V_model_m_s, scale: float):
    """Full-scale speed [m/s] from a model-scale speed [m/s]: V_model sqrt(scale)."""
    return _times(V_model_m_s, np.sqrt(_positive("scale", scale)))


def speed_to_model_scale(V_full_m_s, scale: float):
    """Model-scale speed [m/s] from a full-scale speed [m/s]: V_full / sqrt(scale)."""
    return _times(V_full_m_s, 1.0 / np.sqrt(_positive("scale", scale)))


def time_to_full_scale(t_model_s, scale: float):
    """Full-scale time [s] from a model-scale time [s]: t_model sqrt(scale)."""
    return _times(t_model_s, np.sqrt(_positive("scale", scale)))


def time_to_model_scale(t_full_s, scale: float):
    """Model-scale time [s] from a full-scale time [s]: t_full / sqrt(scale)."""
    return _times(t_full_s, 1.0 / np.sqrt(_positive("scale", scale)))


def length_to_full_scale(L_model_m, scale: float):
    """Full-scale length [m] from a model-scale length [m]: L_model scale."""
    return _times(L_model_m, _positive("scale", scale))


def length_to_model_scale(L_full_m, scale: float):
    """Model-scale length [m] from a full-scale length [m]: L_full / scale."""
    return _times(L_full_m, 1.0 / _positive("scale", scale))


def power_to_full_scale(P_model_W, scale: float, density_ratio: float = 1.0):
    """Full-scale power [W] from a model-scale power [W]: P_model scale^3.5 density_ratio (force x speed)."""
    return _times(P_model_W, _force_factor(scale, density_ratio) * np.sqrt(float(scale)))


def power_to_model_scale(P_full_W, scale: float, density_ratio: float = 1.0):
    """Model-scale power [W] from a full-scale power [W]: P_full / (scale^3.5 density_ratio)."""
    return _times(P_full_W, 1.0 / (_force_factor(scale, density_ratio) * np.sqrt(float(scale))))


def _times(value, factor: float):
    if np.ndim(value):
        return np.asarray(value, dtype=float) * factor
    return float(value) * factor
