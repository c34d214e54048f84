"""Watchdog probes of a lattice fluid on dense arrays: what :mod:`iceresist.watchdog` checks, read by the models.

Each quantity is ``name: (value, where)``, ``where`` the cell ``[i, j, k]`` of the dense grid. The same quantities
are reduced per block on the target by :mod:`iceresist.freesurface.probe`; these dense readings are its reference.
"""

from __future__ import annotations

import math

import numpy as np


def _speed_probe(u_lat: np.ndarray, fluid: np.ndarray, finite: np.ndarray) -> tuple[dict, np.ndarray | None]:
    """(finite and the fastest ``fluid`` cell, speed^2 on the cells) or (the first non-finite cell, None)."""
    bad = fluid & ~(finite & np.isfinite(u_lat).all(axis=0))
    if bad.any():
        return {"finite": (False, [int(v) for v in np.argwhere(bad)[0]])}, None
    speed2 = np.where(fluid, (np.nan_to_num(u_lat) ** 2).sum(axis=0), -1.0)
    i_s = np.unravel_index(int(np.argmax(speed2)), speed2.shape)
    return {"finite": (True, None),
            "max_lattice_speed": (float(math.sqrt(max(speed2[i_s], 0.0))), [int(v) for v in i_s])}, speed2


def fluid_speed_probe(u_lat: np.ndarray, fluid: np.ndarray) -> dict:
    """Watchdog quantities of a lattice velocity ``[3, x, y, z]`` alone on the ``fluid`` cells: finite, and the
    fastest cell (the cheap probe: no density, no kinetic energy)."""
    return _speed_probe(u_lat, fluid, True)[0]


def fluid_probe(rho_lat: np.ndarray, u_lat: np.ndarray, fluid: np.ndarray, kinetic_energy_ref: float) -> dict:
    """Watchdog quantities of a lattice density ``[x, y, z]`` and velocity ``[3, x, y, z]`` on the ``fluid`` cells:
    finite, the fastest cell, the density band, the kinetic energy sum 1/2 rho u^2 and the mass sum rho."""
    probe, speed2 = _speed_probe(u_lat, fluid, np.isfinite(rho_lat))
    if speed2 is None:
        return probe
    r_lo = np.where(fluid, rho_lat, np.inf)
    r_hi = np.where(fluid, rho_lat, -np.inf)
    i_lo = np.unravel_index(int(np.argmin(r_lo)), r_lo.shape)
    i_hi = np.unravel_index(int(np.argmax(r_hi)), r_hi.shape)
    ke = 0.5 * float((rho_lat[fluid] * speed2[fluid]).sum())
    return {**probe,
            "density_min": (float(r_lo[i_lo]), [int(v) for v in i_lo]),
            "density_max": (float(r_hi[i_hi]), [int(v) for v in i_hi]),
            "kinetic_energy": ke, "kinetic_energy_ref": float(kinetic_energy_ref),
            "mass": float(rho_lat[fluid].sum())}
