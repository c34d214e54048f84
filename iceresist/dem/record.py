"""A small appendable HDF5 writer for DEM runs (h5py): the ice force on the hull and body states over time.

Layout::

    timeseries/time_s        (n,)          time of each record
    timeseries/ice_force_N   (n, 3)        contact force of the ice on the recorded (ship) body, x y z
    timeseries/ice_force_mean_N (n, 3)     the same averaged over the sub-steps of the last step
    bodies/positions_m       (n, bodies, 3)
    bodies/quaternions       (n, bodies, 4) (w, x, y, z) of the principal frames
    bodies/velocities_m_s    (n, bodies, 3)
    attrs: the system's ``describe()`` as JSON under ``meta``
"""

from __future__ import annotations

import json

import h5py
import numpy as np


class DEMRecorder:
    """Append the state of a :class:`~iceresist.dem.system.DEMSystem` to an HDF5 file, one row per call."""

    def __init__(self, path, system, ship_body: int | None = None, bodies: bool = True):
        self.path = str(path)
        self.system = system
        self.ship = ship_body
        self.bodies = bodies
        nb = system.n_bodies
        with h5py.File(self.path, "w") as f:
            f.attrs["meta"] = json.dumps(system.describe())
            ts = f.create_group("timeseries")
            ts.create_dataset("time_s", shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
            for name in ("ice_force_N", "ice_force_mean_N"):
                ts.create_dataset(name, shape=(0, 3), maxshape=(None, 3), dtype="f8", chunks=(1024, 3))
            if bodies:
                g = f.create_group("bodies")
                for name, w in (("positions_m", 3), ("quaternions", 4), ("velocities_m_s", 3)):
                    g.create_dataset(name, shape=(0, nb, w), maxshape=(None, nb, w), dtype="f8",
                                     chunks=(max(1, min(64, 2**20 // (8 * w * nb))), nb, w))

    @staticmethod
    def _append(ds, row):
        n = ds.shape[0]
        ds.resize(n + 1, axis=0)
        ds[n] = row

    def record(self):
        """Append the current time, ice force on the ship body (zeros without one), now and as the mean over the
        sub-steps of the last step, and body states."""
        s = self.system
        force = s.ice_force_on(self.ship) if self.ship is not None else np.zeros(3)
        mean = s.mean_contact_force_on(self.ship) if self.ship is not None else np.zeros(3)
        with h5py.File(self.path, "a") as f:
            self._append(f["timeseries/time_s"], s.time_s)
            self._append(f["timeseries/ice_force_N"], force)
            self._append(f["timeseries/ice_force_mean_N"], mean)
            if self.bodies:
                self._append(f["bodies/positions_m"], s.positions)
                self._append(f["bodies/quaternions"], s.quaternions)
                self._append(f["bodies/velocities_m_s"], s.velocities)


def read_ice_force(path, mean: bool = False):
    """``(time_s, ice_force_N)`` arrays from a file written by :class:`DEMRecorder`; ``mean``: the sub-step means."""
    with h5py.File(path, "r") as f:
        return f["timeseries/time_s"][...], f["timeseries/ice_force_mean_N" if mean else "timeseries/ice_force_N"][...]
