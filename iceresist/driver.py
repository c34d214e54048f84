"""The one driver: a model and a scene in, a result file out (after Oceananigans' ``run!(simulation; pickup)``).

:func:`run_model` is the only place that builds a result file, the :class:`~iceresist.simulation.Simulation`
around a model, its writers, its checkpointer, its watchdog and the run-leg metadata. ``iceresist run``
(:mod:`iceresist.run`), every case of ``iceresist sweep`` (:mod:`iceresist.sweep`) and the ``iceresist
validate`` runs that step a scene (:mod:`iceresist.validate`) go through it, so a result looks the same
whichever command wrote it:

* ``meta``: what ran (scene text, model description, units, versions, device), each leg of a run continued with
  ``pickup`` (``legs``, ``legs_json``, written when the leg starts, so a killed leg is on record), and at the end
  of every leg the iteration, time, steps, wall time, MLUPS, stop reason and ``finished``;
* ``timeseries``: one row of ``model.diagnostics()`` per schedule;
* ``fields``: snapshots of ``model.fields()`` with an XDMF sidecar (where the run asks for fields);
* the checkpoint beside it, replaced atomically on its schedule (``checkpoint_iteration`` and
  ``checkpoint_wall_s`` in ``meta``).

Stop criteria are the simulation's; the NaN checker and the watchdog are callbacks on schedules.
"""

from __future__ import annotations

import datetime as _dt
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from iceresist import watchdog
from iceresist.backends import compilelog
from iceresist.io.hdf5 import NullRunFile, RunFile
from iceresist.io.meta import leg_meta, run_meta
from iceresist.models.base import Model
from iceresist.simulation import (Callback, Checkpointer, FieldWriter, IterationInterval, Simulation, TimeSeriesWriter,
                                  WallTimeInterval)

log = logging.getLogger(__name__)

#: Wall time (s) between checkpoints of a run that names no checkpoint schedule: a killed long run keeps its
#: work (a tier-2 quick case runs for hours on a 2-core machine).
DEFAULT_CHECKPOINT_WALL_S = 600.0


@dataclass
class Stop:
    """When a run ends: the first of ``iteration``, ``time_s`` (simulated) and ``wall_s`` reached."""

    iteration: int | None = None
    time_s: float | None = None
    wall_s: float | None = None


@dataclass
class Outputs:
    """What a run writes besides its metadata, and when (schedules of :mod:`iceresist.simulation`)."""

    #: When a time-series row is appended.
    timeseries: object = field(default_factory=lambda: IterationInterval(1))
    #: Fields to snapshot (names of ``model.fields()``); empty: no field output.
    fields: tuple[str, ...] = ()
    #: When fields are written; None: only at the end.
    fields_schedule: object | None = None
    #: When the checkpoint is replaced; None (and no final checkpoint): a run that keeps no checkpoint.
    checkpoint: object | None = field(default_factory=lambda: WallTimeInterval(DEFAULT_CHECKPOINT_WALL_S))
    #: Write a checkpoint of the final state too (a run that may be continued past its stop).
    checkpoint_final: bool = True
    #: Model steps between watchdog checks; None: the model's default (:func:`iceresist.watchdog.default_interval`).
    watchdog_every: int | None = None
    #: Extra time-series columns ``{name: func(model) -> float}`` beside ``model.diagnostics()`` (e.g. the mode
    #: amplitude of a validation case).
    probes: dict = field(default_factory=dict)


@dataclass
class RunResult:
    """What a finished leg left: the result file, the simulation (stop reason, timings) and the watchdog."""

    path: Path
    sim: Simulation
    watchdog: object


def _with_probes(probes: dict) -> Callable | None:
    """The diagnostics of a time-series row: ``model.diagnostics()`` and the ``probes`` columns."""
    if not probes:
        return None
    return lambda model: {**model.diagnostics(), **{k: float(f(model)) for k, f in probes.items()}}


def run_model(model: Model, scene, path, checkpoint_path=None, *, stop: Stop, outputs: Outputs | None = None,
              pickup=False, meta: dict | None = None, lattice_units: bool = False, progress: bool = True,
              callbacks: dict | None = None, on_new: Callable | None = None, on_completed: Callable | None = None,
              build_s: float = 0.0, leave_progress: bool = True) -> RunResult:
    """Run ``model`` (built from ``scene``) into the result file ``path``, checkpointing to ``checkpoint_path``
    (None: no checkpoint, and no pickup).

    ``pickup``: False (a new result; an old file at ``path`` is replaced), True (continue ``path`` from its own
    checkpoint) or a checkpoint path. ``meta``: extra run metadata written with the first leg.
    ``lattice_units``: the scene is written in lattice units (field units say so). ``callbacks``:
    ``{name: (func(sim), every_steps)}``. ``on_new(runfile, model)``: called once when a new result file is made;
    ``on_completed(runfile, model, sim)``: called when the leg reached its stop criterion (not after an interrupt,
    a divergence or the watchdog). ``build_s``: wall time the caller spent building the model, counted into the
    leg's wall time. ``progress``: a progress bar on a terminal (kept after the run unless not
    ``leave_progress``). Everything that can fail on bad input must be checked by the caller before this opens a
    file.
    """
    outputs = outputs or Outputs()
    path = Path(path)
    checkpoint_path = None if checkpoint_path is None else Path(checkpoint_path)
    t0 = time.perf_counter() - build_s
    root = model.comm is None or model.comm.rank == 0   # an MPI run: rank 0 writes, every rank steps
    if root:
        path.parent.mkdir(parents=True, exist_ok=True)
    if root and not pickup and checkpoint_path is not None:
        checkpoint_path.unlink(missing_ok=True)  # the checkpoint of a result this run replaces
    sim = Simulation(model, stop_iteration=stop.iteration, stop_time_s=stop.time_s,
                     wall_time_limit_s=stop.wall_s, progress=progress)
    sim.leave_progress = leave_progress
    if pickup:  # a missing or wrong checkpoint stops here, before the result file is touched
        sim.load_checkpoint(checkpoint_path if pickup is True else pickup)
    dog_json = path.with_suffix(".watchdog.json") if root else None
    if root:
        dog_json.unlink(missing_ok=True)  # the diagnostic of an earlier leg or run
    desc = model.describe()
    units = model.units.describe() if model.units is not None else None
    dx_m = model.units.dx_m if model.units is not None else 1.0  # places the fields' grid (none without a lattice)
    runfile = RunFile(path, "a" if pickup else "w", shape_cells=model.shape_cells, dx_m=dx_m,
                      write_xdmf=bool(outputs.fields)) if root else NullRunFile()
    with runfile as rf:
        if not pickup and root:
            rf.write_meta(**run_meta(scene_text=scene.source_text, backend=desc["backend"],
                                     precision=desc["precision"], cells=model.cells),
                          scene_name=scene.scene.name, scene_source=scene.source_name,
                          description=scene.scene.description, model=desc, units=units,
                          shape_cells=None if model.shape_cells is None else list(model.shape_cells),
                          **(meta or {}))
            if on_new is not None:
                on_new(rf, model)
        earlier = rf.meta if pickup else None
        # the file notes the wall time up to its own checkpoint, not up to one named with pickup=PATH
        wall_before_s = float(earlier.get("checkpoint_wall_s", 0.0)) if pickup is True else 0.0
        if root and pickup and (pickup is not True or "checkpoint_wall_s" not in earlier):
            log.warning("%s: the wall time up to the checkpoint is not known (%s): its wall_time_s will count from "
                        "the pickup", path, "another checkpoint" if pickup is not True else "an older iceresist "
                        "wrote the file")

        if outputs.fields:
            field_units = {k: v for k, v in model.field_units(lattice_units).items() if k in outputs.fields}
            sim.output_writers["fields"] = FieldWriter(rf, outputs.fields_schedule, list(outputs.fields),
                                                       units=field_units)
        sim.output_writers["timeseries"] = TimeSeriesWriter(rf, outputs.timeseries, _with_probes(outputs.probes))
        if checkpoint_path is not None:
            sim.output_writers["checkpointer"] = Checkpointer(checkpoint_path, outputs.checkpoint,
                                                              write_final=outputs.checkpoint_final, runfile=rf,
                                                              wall_before_s=wall_before_s, t0=t0)
        dog = watchdog.install(sim, interval=outputs.watchdog_every, runfile=rf, json_path=dog_json)
        for name, (func, every) in (callbacks or {}).items():
            sim.callbacks[name] = Callback(func, IterationInterval(every))

        def start_leg(s):  # after the pickup: the iteration this leg starts from is known
            if root:
                rf.write_meta(**leg_meta(earlier, s.start_iteration, desc["backend"]), finished=False)

        sim.on_start.append(start_leg)
        log.info("running %s: %s, %d cells, %.4g s per step, %s on %s -> %s", scene.scene.name,
                 "+".join(model.components), model.cells, model.dt_s, model.precision, model.target.name, path)
        try:
            sim.run(pickup=Simulation.LOADED if pickup else False)
        finally:
            # totals over the legs of the run: steps from iteration 0, the wall time of the work kept (a leg
            # killed after its last checkpoint loses the steps and the time after it); mlups: this leg's rate
            rf.write_meta(iteration=model.iteration, time_s=model.time_s, steps=int(model.iteration),
                          wall_time_s=wall_before_s + sim.wall_time_s + build_s, build_time_s=build_s,
                          step_time_s=sim.step_time_s, first_step_s=sim.first_step_s, mlups=sim.mlups,
                          stop_reason=sim.stop_reason or "interrupted", diverged=sim.diverged,
                          finished=sim.completed,
                          finished_utc=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
        if sim.completed and on_completed is not None and root:
            on_completed(rf, model, sim)
    log.info("%s -> %s", closing_line(sim, model, build_s, since=t0), path)
    return RunResult(path, sim, dog)


def closing_line(sim: Simulation, model: Model, build_s: float = 0.0, since: float = 0.0) -> str:
    """What a leg took, each figure named: its wall time (the one the result file records for the leg), the model's
    set-up within it, the stepping, the first step's share of the stepping (compiling or loading the kernels) and
    the kernels compiled since ``since`` (``time.perf_counter()`` at the leg's start, its set-up included); the rate
    over the steps after the first where there were any."""
    kernels, seconds = compilelog.compiled_since(since)
    compiled = f", {kernels} kernels compiled in {seconds:.1f} s" if kernels else ", kernels loaded from the cache"
    text = (f"{sim.stop_reason}: {sim.steps_done} steps; wall time {sim.wall_time_s + build_s:.1f} s: "
            f"{build_s:.1f} s setting up, {sim.step_time_s:.1f} s stepping ({sim.first_step_s:.1f} s of it in the "
            f"first step{compiled})")
    if model.cells:     # tier 1 has no lattice
        after = sim.steps_done > sim.first_steps
        text += f"; {sim.mlups:.2f} MLUPS {'after the first step' if after else 'with the first step'}"
    return text
