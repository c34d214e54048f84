"""The run watchdog: every N steps it looks for the signs of an unstable run and stops it with a diagnostic.

Checks (the first that fails stops the run):

* ``finite``: NaN or Inf in the state;
* ``max_lattice_speed``: the fastest fluid cell above :data:`LATTICE_SPEED_LIMIT` (u dt/dx; the lattice sound
  speed is 0.577) -- or, for DEM models, ``max_body_speed_m_s`` above the model's own limit;
* ``bodies_outside_finest``: on refined levels, bodies that left the finest level's leaves (the coupling lives
  there; a regridding run's band that follows them was outrun);
* ``density``: a fluid cell outside :data:`DENSITY_BAND` (lattice units, rho0 = 1);
* ``kinetic_energy``: the kinetic energy grew by more than :data:`ENERGY_GROWTH` over the last
  :data:`ENERGY_WINDOW` checks, counted from at least the model's reference energy (so a flow that starts from rest
  may spin up).

A model offers the quantities through ``model.watchdog_probe() -> dict``, each entry ``name: (value, where)``
(``where``: a cell index [i, j, k] or a body index, or ``None``), plus ``kinetic_energy`` and
``kinetic_energy_ref`` as plain numbers and optional ``max_body_speed_limit_m_s``. A model without the hook is
checked for NaN only (``is_finite()``).

On a trigger the run stops as diverged (no output is written from the bad state, what was written stays), and the
diagnostic -- step, time, quantity, value, limit, where -- goes to ``<result>.watchdog.json`` and to the ``watchdog``
group of the result file.
"""

from __future__ import annotations

import json
import logging
import math
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from iceresist.simulation import Callback, IterationInterval

log = logging.getLogger(__name__)

#: Largest lattice speed u dt/dx tolerated while running.
LATTICE_SPEED_LIMIT = 0.4
#: Band of lattice density rho / rho0 tolerated while running.
DENSITY_BAND = (0.5, 1.5)
#: Largest kinetic-energy growth factor over the window.
ENERGY_GROWTH = 10.0
#: Number of checks the growth is measured over.
ENERGY_WINDOW = 5
#: Default check interval (steps) of fluid models; DEM models (whose step is a record of many sub-steps): 1.
DEFAULT_INTERVAL_FLUID = 100
DEFAULT_INTERVAL_DEM = 1


@dataclass
class WatchdogReport:
    """What stopped the run."""

    iteration: int
    time_s: float
    quantity: str
    value: float
    limit: float | list
    where: object = None
    message: str = ""
    last_good_iteration: int | None = None
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = asdict(self)
        return json.loads(json.dumps(d, default=_plain))


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


class Watchdog:
    """A :class:`~iceresist.simulation.Simulation` callback (``Callback(watchdog, IterationInterval(n))``).

    ``runfile``: the :class:`~iceresist.io.hdf5.RunFile` to put the diagnostic in (group ``watchdog``);
    ``json_path``: where to write the diagnostic as JSON. Limits default to the module constants.
    """

    def __init__(self, *, runfile=None, json_path=None, lattice_speed_limit: float = LATTICE_SPEED_LIMIT,
                 density_band=DENSITY_BAND, energy_growth: float = ENERGY_GROWTH, energy_window: int = ENERGY_WINDOW):
        self.runfile, self.json_path = runfile, (Path(json_path) if json_path is not None else None)
        self.lattice_speed_limit = float(lattice_speed_limit)
        self.density_band = tuple(float(v) for v in density_band)
        self.energy_growth, self.energy_window = float(energy_growth), int(energy_window)
        self._energy = deque(maxlen=self.energy_window + 1)
        self.report: WatchdogReport | None = None
        self.last_good_iteration: int | None = None
        self.checks = 0

    # -- the check ------------------------------------------------------------------------------------
    def inspect(self, model) -> WatchdogReport | None:
        """The first violated limit of ``model`` now, or ``None``."""
        it, t = int(model.iteration), float(model.time_s)
        probe = model.watchdog_probe()
        finite, where = probe.get("finite", (True, None))
        if not finite:
            return WatchdogReport(it, t, "finite", float("nan"), "finite", where, "NaN or Inf in the solution")
        if "max_lattice_speed" in probe:
            v, where = probe["max_lattice_speed"]
            if not v <= self.lattice_speed_limit:
                return WatchdogReport(it, t, "max_lattice_speed", v, self.lattice_speed_limit, where,
                                      "runaway velocity: lattice speed u dt/dx above the limit")
        if "max_body_speed_m_s" in probe:
            v, where = probe["max_body_speed_m_s"]
            limit = float(probe.get("max_body_speed_limit_m_s", math.inf))
            if not v <= limit:
                return WatchdogReport(it, t, "max_body_speed_m_s", v, limit, where,
                                      "runaway velocity: a body faster than the limit")
        if "bodies_outside_finest" in probe:
            v, where = probe["bodies_outside_finest"]
            if v > 0:
                return WatchdogReport(it, t, "bodies_outside_finest", v, 0, where,
                                      "a body left the finest level between two regrids: widen "
                                      "refinement.body_band_m or regrid more often")
        lo, hi = self.density_band
        if "density_min" in probe:
            v, where = probe["density_min"]
            if not v >= lo:
                return WatchdogReport(it, t, "density_min", v, lo, where, "lattice density below the band")
        if "density_max" in probe:
            v, where = probe["density_max"]
            if not v <= hi:
                return WatchdogReport(it, t, "density_max", v, hi, where, "lattice density above the band")
        if "kinetic_energy" in probe:
            e = float(probe["kinetic_energy"])
            ref = float(probe.get("kinetic_energy_ref", 0.0))
            self._energy.append(e)
            base = max(self._energy[0], ref)
            if not math.isfinite(e) or (base > 0 and e > self.energy_growth * base):
                return WatchdogReport(it, t, "kinetic_energy_growth", e / base if base > 0 else math.inf,
                                      self.energy_growth, None,
                                      f"kinetic energy grew from {base:.4g} to {e:.4g} within "
                                      f"{len(self._energy) - 1} checks", extra={"kinetic_energy": e,
                                                                                "reference": base})
        return None

    def __call__(self, sim):
        self.checks += 1
        report = self.inspect(sim.model)
        if report is None:
            self.last_good_iteration = int(sim.model.iteration)
            return
        report.last_good_iteration = self.last_good_iteration
        self.report = report
        self.write(report)
        where = "" if report.where is None else f" at {report.where}"
        limit = report.limit if isinstance(report.limit, str) else f"{report.limit:.4g}"
        reason = (f"watchdog: {report.quantity} = {report.value:.4g}{where} (limit {limit}) at iteration "
                  f"{report.iteration} (t = {report.time_s:.6g} s): {report.message}; the run was stopped, outputs "
                  f"written before stay")
        log.error(reason)
        stop = getattr(sim, "abort", None)
        if stop is not None:
            stop(reason)
        else:
            sim.diverged = True
            sim.stop(reason)

    def write(self, report: WatchdogReport):
        """The diagnostic as JSON and as attributes of the result file's ``watchdog`` group."""
        d = report.to_dict()
        if self.json_path is not None:
            self.json_path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.json_path.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(d, indent=1))
            tmp.replace(self.json_path)
        if self.runfile is not None:
            h5 = self.runfile.h5
            if "watchdog" in h5:
                del h5["watchdog"]
            g = h5.create_group("watchdog")
            for k, v in d.items():
                g.attrs[k] = json.dumps(v) if isinstance(v, (dict, list)) or v is None else v
            self.runfile.flush()


def default_interval(model) -> int:
    """Check interval of a model when the scene leaves ``run.watchdog_every_steps`` out: the model's own
    ``watchdog_interval`` where it has one, else by kind (fluid or DEM)."""
    if model.watchdog_interval is not None:
        return int(model.watchdog_interval)
    return DEFAULT_INTERVAL_FLUID if model.cells else DEFAULT_INTERVAL_DEM


def install(sim, *, interval: int | None = None, runfile=None, json_path=None, **limits) -> Watchdog:
    """Add a :class:`Watchdog` as ``sim.callbacks["watchdog"]`` every ``interval`` steps; returns it."""
    dog = Watchdog(runfile=runfile, json_path=json_path, **limits)
    sim.callbacks["watchdog"] = Callback(dog, IterationInterval(interval or default_interval(sim.model)))
    return dog


# -- probes of the models in the tree -------------------------------------------------------------------
