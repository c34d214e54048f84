"""The time loop, after Oceananigans.jl's ``Simulation``: stop criteria, callbacks and output writers on schedules.

The model is an :class:`iceresist.models.base.Model` (state and one time step, no I/O of its own); the
simulation asks it only what that contract promises.

A writer whose ``schedule`` is ``None`` writes only once, when the run ends.
``Simulation.run`` steps the model in chunks that end exactly where a schedule
is due, so ``model.step(n)`` may run many steps in one kernel launch sequence.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from iceresist.errors import InputError
from iceresist.io.checkpoint import read_checkpoint, write_checkpoint
from iceresist.io.meta import mlups
from iceresist.models.base import Model

log = logging.getLogger(__name__)

#: Wall-clock seconds between progress lines in the log of a run that shows no progress bar (a batch run, its
#: output going to a file): a tier-2 case runs for hours.
PROGRESS_LOG_S = 300.0


# -- schedules ------------------------------------------------------------------------------------------
class IterationInterval:
    """Due every ``interval`` iterations (at iterations ``offset + k * interval``)."""

    def __init__(self, interval: int, offset: int = 0):
        if int(interval) < 1:
            raise ValueError(f"IterationInterval needs an interval >= 1, not {interval}")
        self.interval, self.offset = int(interval), int(offset)

    def initialize(self, sim):
        pass

    def __call__(self, sim) -> bool:
        return (sim.model.iteration - self.offset) % self.interval == 0

    def steps_to_next(self, sim) -> int | None:
        return self.interval - (sim.model.iteration - self.offset) % self.interval

    def __repr__(self):
        return f"IterationInterval({self.interval})"


class TimeInterval:
    """Due at the first step at or after each multiple ``k * interval_s`` of simulated time."""

    def __init__(self, interval_s: float):
        if not interval_s > 0:
            raise ValueError(f"TimeInterval needs an interval > 0 s, not {interval_s}")
        self.interval_s = float(interval_s)
        self._next_k = 0

    def _eps(self, sim) -> float:
        return 1e-9 * self.interval_s + 1e-6 * (sim.model.dt_s or 0.0)

    def initialize(self, sim):
        self._next_k = max(0, math.ceil((sim.model.time_s - self._eps(sim)) / self.interval_s))

    def __call__(self, sim) -> bool:
        t = sim.model.time_s
        if t >= self._next_k * self.interval_s - self._eps(sim):
            self._next_k = math.floor((t + self._eps(sim)) / self.interval_s) + 1
            return True
        return False

    def steps_to_next(self, sim) -> int | None:
        dt = sim.model.dt_s
        if not dt:
            return 1
        remaining = self._next_k * self.interval_s - sim.model.time_s
        return max(1, math.ceil(remaining / dt - 1e-6))

    def __repr__(self):
        return f"TimeInterval({self.interval_s} s)"


class WallTimeInterval:
    """Due once ``interval_s`` seconds of wall-clock time have passed since it was last due (or since the start)."""

    def __init__(self, interval_s: float):
        if not interval_s > 0:
            raise ValueError(f"WallTimeInterval needs an interval > 0 s, not {interval_s}")
        self.interval_s = float(interval_s)
        self._last = time.perf_counter()

    def initialize(self, sim):
        self._last = time.perf_counter()

    def __call__(self, sim) -> bool:
        now = time.perf_counter()
        if now - self._last >= self.interval_s:
            self._last = now
            return True
        return False

    def steps_to_next(self, sim) -> int | None:
        return None

    def __repr__(self):
        return f"WallTimeInterval({self.interval_s} s)"


@dataclass
class Callback:
    """``func(sim)`` called whenever ``schedule`` is due."""

    func: Callable
    schedule: object

    def __call__(self, sim):
        return self.func(sim)


# -- NaN checker ----------------------------------------------------------------------------------------
def check_finite(sim):
    """Stop the run when the model holds NaN or Inf (default callback ``nan_checker``)."""
    if not sim.model.is_finite():
        sim.diverge()


# -- output writers -------------------------------------------------------------------------------------
class FieldWriter:
    """Snapshots of ``model.fields()`` (or the names in ``fields``) into a :class:`~iceresist.io.hdf5.RunFile`; for a
    model with ``level_fields`` (block refinement) also the leaf cells of every level."""

    def __init__(self, runfile, schedule, fields=None, *, units: dict | None = None, write_final: bool = True):
        self.runfile, self.schedule, self.fields = runfile, schedule, fields
        self.units, self.write_final = units, write_final
        self.last_iteration = None

    def write(self, sim):
        model = sim.model
        data = model.fields()
        levels = model.level_fields(self.fields)    # a refined model: every level's leaf cells too (rank 0, MPI)
        if data is None:            # an MPI rank other than 0: the fields were gathered there
            self.last_iteration = model.iteration
            return
        if self.fields is not None:
            data = {k: data[k] for k in self.fields}
        if not all(np.isfinite(a).all() for a in data.values() if np.issubdtype(np.asarray(a).dtype, np.floating)):
            sim.diverge()
            return
        self.runfile.write_fields(model.iteration, model.time_s, data, units=self.units)
        if levels is not None:
            self.runfile.write_level_fields(model.iteration, model.time_s, levels, units=self.units)
        self.last_iteration = model.iteration

    def pickup(self, sim):
        self.runfile.truncate_after(sim.model.iteration)
        its = self.runfile.snapshot_iterations()
        self.last_iteration = its[-1] if its else None

    def finalize(self, sim):
        if self.write_final and not sim.diverged and self.last_iteration != sim.model.iteration:
            self.write(sim)


class TimeSeriesWriter:
    """Rows ``{iteration, time_s, **diagnostics(model)}`` appended to a RunFile time-series group."""

    def __init__(self, runfile, schedule, diagnostics: Callable | None = None, *, group: str = "timeseries",
                 write_final: bool = True):
        self.runfile, self.schedule, self.group = runfile, schedule, group
        self.diagnostics, self.write_final = diagnostics, write_final
        self.last_iteration = None

    def write(self, sim):
        model = sim.model
        diag = self.diagnostics(model) if self.diagnostics is not None else model.diagnostics()
        row = {"iteration": model.iteration, "time_s": model.time_s, **diag}
        self.runfile.append_timeseries(row, self.group)
        self.last_iteration = model.iteration

    def pickup(self, sim):
        self.runfile.truncate_after(sim.model.iteration)
        self.last_iteration = sim.model.iteration

    def finalize(self, sim):
        if self.write_final and not sim.diverged and self.last_iteration != sim.model.iteration:
            self.write(sim)


class Checkpointer:
    """The whole model state in one file ``path``, replaced atomically each time the schedule is due.

    With a ``runfile`` it also notes there, at each checkpoint, the iteration reached (``checkpoint_iteration``)
    and the wall time spent up to it (``checkpoint_wall_s``: ``wall_before_s`` of earlier legs plus the time
    since ``t0``, a ``time.perf_counter()`` reading, default now), so a run continued from the checkpoint after a
    kill can report the wall time of the work it kept."""

    def __init__(self, path, schedule, *, write_final: bool = True, runfile=None, wall_before_s: float = 0.0,
                 t0: float | None = None):
        self.path, self.schedule, self.write_final = Path(path), schedule, write_final
        self.runfile, self.wall_before_s = runfile, float(wall_before_s)
        self.t0 = time.perf_counter() if t0 is None else t0
        self.last_iteration = None

    def write(self, sim):
        m = sim.model
        state = m.state()
        self.last_iteration = m.iteration
        if state is None:           # an MPI rank other than 0: the state was gathered there
            return
        write_checkpoint(self.path, {"model": state, "iteration": np.int64(m.iteration),
                                     "time_s": np.float64(m.time_s)})
        if self.runfile is not None:
            self.runfile.write_meta(checkpoint_iteration=int(m.iteration),
                                    checkpoint_wall_s=self.wall_before_s + time.perf_counter() - self.t0)
        log.debug("checkpoint at iteration %d -> %s", m.iteration, self.path)

    def finalize(self, sim):
        if self.write_final and not sim.diverged and self.last_iteration != sim.model.iteration:
            self.write(sim)


# -- the simulation -------------------------------------------------------------------------------------
class Simulation:
    """Run ``model`` until a stop criterion, calling ``callbacks`` and ``output_writers`` on their schedules.

    Stop criteria (the first reached wins): ``stop_iteration``, ``stop_time_s`` (simulated), ``wall_time_limit_s``.
    A NaN checker (``callbacks["nan_checker"]``, every ``nan_check_interval`` steps) stops a diverged run;
    outputs already written stay, and no output is written from a diverged state.
    """

    def __init__(self, model: Model, *, stop_iteration: int | None = None, stop_time_s: float | None = None,
                 wall_time_limit_s: float | None = None, progress: bool = True, nan_check_interval: int = 100):
        if not isinstance(model, Model):
            raise TypeError(f"Simulation needs an iceresist.models.base.Model, not {type(model).__name__}")
        self.model = model
        self.stop_iteration, self.stop_time_s, self.wall_time_limit_s = stop_iteration, stop_time_s, wall_time_limit_s
        self.progress = progress
        #: keep the finished progress bar on the terminal (False: a sweep's case bars make way for the next)
        self.leave_progress = True
        self.callbacks: dict[str, Callback] = {"nan_checker": Callback(check_finite,
                                                                       IterationInterval(nan_check_interval))}
        self.output_writers: dict[str, object] = {}
        #: ``func(sim)`` called once per :meth:`run`, after the pickup and before the first output.
        self.on_start: list[Callable] = []
        self.stop_reason: str | None = None
        # stopped at its stop iteration or time, not by an interrupt, a divergence, the watchdog or the wall limit
        self.completed = False
        self.diverged = False
        self.steps_done = 0
        self.start_iteration: int | None = None  # where the last run() started (after its pickup)
        self.wall_time_s = 0.0
        self.step_time_s = 0.0
        #: wall time (s) and steps of the first chunk of the last :meth:`run`, the one that compiles the kernels
        #: (or loads them from the cache): ``step_time_s - first_step_s`` over ``steps_done - first_steps`` steps
        #: is the pace of the compiled kernels
        self.first_step_s = 0.0
        self.first_steps = 0
        self._chunk_cap = 1
        self._start_wall = time.perf_counter()
        #: The MPI communicator of a model on several ranks (:attr:`Model.comm`): every decision that rests on a
        #: rank's own clock (chunk length, wall-time schedules and limit) or on what only rank 0 sees (a NaN in the
        #: gathered fields) is taken together, so all ranks step, write and stop in step.
        self.comm = model.comm

    # -- control --------------------------------------------------------------------------------------
    def stop(self, reason: str):
        if self.stop_reason is None:
            self.stop_reason = reason

    def diverge(self):
        m = self.model
        self.diverged = True
        self.stop(f"NaN or Inf in the solution at iteration {m.iteration} (t = {m.time_s:.6g} s): the run "
                  f"diverged; outputs written before stay. Lower the lattice velocity limit (numerics.mach), "
                  f"refine the grid or raise the viscosity")

    def abort(self, reason: str):
        """Stop as diverged for ``reason`` (e.g. the watchdog): no output is written from this state."""
        self.diverged = True
        self.stop(reason)

    @property
    def running(self) -> bool:
        return self.stop_reason is None

    @property
    def mlups(self) -> float:
        """Million cell updates per second of the compiled kernels: over the stepping after the first chunk of the
        last :meth:`run` (which compiles the kernels or loads them from the cache, ``first_step_s``), over all of
        it while nothing came after that chunk."""
        # a model step may hold several lattice steps (tier 2: one record = lbm_steps_per_record LBM steps)
        steps, seconds = self.steps_done - self.first_steps, self.step_time_s - self.first_step_s
        if steps <= 0 or seconds <= 0:
            steps, seconds = self.steps_done, self.step_time_s
        return mlups(self.model.lattice_updates_per_step, steps, seconds)

    def _check_stop(self):
        m = self.model
        if self.stop_iteration is not None and m.iteration >= self.stop_iteration:
            self._reach_end(f"stop iteration {self.stop_iteration} reached")
        if self.stop_time_s is not None and m.time_s >= self.stop_time_s - 1e-6 * m.dt_s:
            self._reach_end(f"stop time {self.stop_time_s:g} s reached")
        if self.wall_time_limit_s is not None and time.perf_counter() - self._start_wall >= self.wall_time_limit_s:
            self.stop(f"wall time limit {self.wall_time_limit_s:g} s reached")
        self._agree_stop()

    def _reach_end(self, reason: str):
        """Stop at the stop iteration or time; the run is ``completed`` unless something stopped it first."""
        if self.stop_reason is None:
            self.completed = True
        self.stop(reason)

    def _actions(self):
        """(name, object) in call order: NaN checker, callbacks, writers, checkpointers last."""
        acts = [("nan_checker", self.callbacks["nan_checker"])] if "nan_checker" in self.callbacks else []
        acts += [(k, c) for k, c in self.callbacks.items() if k != "nan_checker"]
        writers = list(self.output_writers.items())
        acts += [(k, w) for k, w in writers if not isinstance(w, Checkpointer)]
        acts += [(k, w) for k, w in writers if isinstance(w, Checkpointer)]
        return acts

    def _agreed(self, flag: bool) -> bool:
        """``flag`` as rank 0 has it (MPI), else ``flag``."""
        return flag if self.comm is None else bool(self.comm.bcast(bool(flag), root=0))

    def _agree_stop(self):
        """On MPI: every rank takes the stop state of the lowest rank that stopped (a wall-time limit, a divergence
        seen in rank 0's gathered fields)."""
        if self.comm is None:
            return
        states = self.comm.allgather((self.stop_reason, self.diverged, self.completed))
        for reason, diverged, completed in states:
            if reason is not None:
                self.stop_reason, self.diverged, self.completed = reason, diverged, completed
                return

    def _actuate(self):
        acts = self._actions()
        due = [(name, act) for name, act in acts if act.schedule is not None and self._agreed(act.schedule(self))]
        guard = self.callbacks.get("watchdog")
        if guard is not None and any(not isinstance(a, Callback) for _, a in due) and \
                not any(name == "watchdog" for name, _ in due):
            due.insert(0, ("watchdog", guard))  # outputs are written only from a state the watchdog passed
        for _, act in due:
            if isinstance(act, Callback):
                act(self)
            else:
                act.write(self)
            self._agree_stop()
            if self.diverged:
                return

    def _chunk(self) -> int:
        m = self.model
        n = self._chunk_cap
        if self.stop_iteration is not None:
            n = min(n, self.stop_iteration - m.iteration)
        dt = m.dt_s
        if self.stop_time_s is not None:
            n = min(n, max(1, math.ceil((self.stop_time_s - m.time_s) / dt - 1e-6)) if dt else 1)
        for _, act in self._actions():
            if act.schedule is None:
                continue
            k = act.schedule.steps_to_next(self)
            if k is not None:
                n = min(n, k)
        n = max(1, n)
        if self.comm is not None:
            from mpi4py import MPI

            n = int(self.comm.allreduce(n, op=MPI.MIN))
        return n

    def _checkpointer(self) -> Checkpointer | None:
        for w in self.output_writers.values():
            if isinstance(w, Checkpointer):
                return w
        return None

    def load_checkpoint(self, pickup=True):
        """Put the state of a checkpoint (``True``: the Checkpointer's file, or a path) into the model; a missing
        or wrong checkpoint is an :class:`InputError` and changes nothing. :meth:`run` with
        ``pickup=Simulation.LOADED`` then continues from it."""
        path = pickup if not isinstance(pickup, bool) else (self._checkpointer().path if self._checkpointer() else None)
        if path is None:
            raise InputError("pickup asked for, but there is no Checkpointer and no checkpoint path")
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: no checkpoint to pick up from")
        state = read_checkpoint(path)
        self.model.load_state(state["model"])
        log.info("picked up from %s at iteration %d", path, self.model.iteration)

    #: ``run(pickup=LOADED)``: the model holds the checkpoint's state already (:meth:`load_checkpoint`).
    LOADED = object()

    def _pickup(self, pickup):
        if pickup is not self.LOADED:
            self.load_checkpoint(pickup)
        for w in self.output_writers.values():
            if hasattr(w, "pickup"):
                w.pickup(self)
            w.last_iteration = self.model.iteration

    def _steps_to_stop(self) -> int | None:
        """Steps from now to the stop iteration or the stop time (None when only a wall-time limit is set)."""
        m = self.model
        total = None
        if self.stop_iteration is not None:
            total = self.stop_iteration - m.iteration
        dt = m.dt_s
        if self.stop_time_s is not None and dt:
            by_time = math.ceil((self.stop_time_s - m.time_s) / dt - 1e-6)
            total = by_time if total is None else min(total, by_time)
        return None if total is None else max(total, 0)

    def _log_progress(self, done: int, total: int | None, elapsed_s: float):
        """One INFO line: the step reached, the share of this run done and the wall time it will still take, at the
        pace of the steps after the first chunk (which compiles or loads the kernels: its time says nothing of the
        pace of the rest)."""
        m = self.model
        msg = f"step {m.iteration}, t = {m.time_s:.4g} s"
        if total:
            msg += f", {100.0 * done / total:.0f} % of {total} steps"
            paced = done - self.first_steps
            if paced > 0:
                per_step = max(elapsed_s - self.first_step_s, 0.0) / paced
                msg += f", about {(total - done) * per_step / 60.0:.0f} min to go"
            else:
                msg += ", the first steps compile or load the kernels"
        rate = f", {self.mlups:.2f} MLUPS" if m.cells else ""      # tier 1 has no lattice
        log.info("%s (%.0f min so far%s)", msg, elapsed_s / 60.0, rate)

    def _progress_bar(self, total: int | None):
        enabled = self.progress and sys.stderr.isatty()
        if not enabled:
            return None
        from tqdm import tqdm

        return tqdm(total=total, unit="step", dynamic_ncols=True, file=sys.stderr, leave=self.leave_progress)

    # -- the loop -------------------------------------------------------------------------------------
    def run(self, pickup=False):
        """Run to a stop criterion. ``pickup``: ``True`` (the Checkpointer's file) or a checkpoint path."""
        if self.stop_iteration is None and self.stop_time_s is None and self.wall_time_limit_s is None:
            raise InputError("the simulation has no stop criterion: set stop_iteration, stop_time_s or "
                             "wall_time_limit_s")
        self.stop_reason, self.diverged, self.completed = None, False, False
        self._start_wall = time.perf_counter()
        if pickup:
            self._pickup(pickup)
        self.start_iteration = self.model.iteration
        for func in self.on_start:
            func(self)
        for _, act in self._actions():
            if act.schedule is not None:
                act.schedule.initialize(self)
        if pickup:      # the leg before served this instant: the schedules move past it, as at a start, acting not
            for _, act in self._actions():
                if act.schedule is not None:
                    act.schedule(self)
        else:
            self._actuate()
        self._check_stop()
        total, first = self._steps_to_stop(), self.steps_done
        bar = self._progress_bar(total)
        last_log = time.perf_counter()
        try:
            while self.running:
                n = self._chunk()
                t0 = time.perf_counter()
                self.model.step(n)
                dt_wall = time.perf_counter() - t0
                if self.steps_done == first:
                    self.first_step_s, self.first_steps = dt_wall, n
                self.step_time_s += dt_wall
                self.steps_done += n
                # grow the chunk towards ~0.2 s of wall time so wall-time schedules and the bar stay responsive
                per_step = dt_wall / n
                self._chunk_cap = max(1, min(2 * self._chunk_cap, int(0.2 / per_step) if per_step > 0 else 1 << 20))
                if bar is not None:
                    bar.update(n)
                    rate = f", {self.mlups:.1f} MLUPS" if self.model.cells else ""
                    bar.set_postfix_str(f"t = {self.model.time_s:.4g} s{rate}", refresh=False)
                self._actuate()
                self._check_stop()
                now = time.perf_counter()
                if bar is None and now - last_log >= PROGRESS_LOG_S:
                    last_log = now
                    self._log_progress(self.steps_done - first, total, now - self._start_wall)
            for _, w in self.output_writers.items():
                if hasattr(w, "finalize"):
                    w.finalize(self)
        finally:
            if bar is not None:
                bar.close()
            self.wall_time_s += time.perf_counter() - self._start_wall
        (log.error if self.diverged else log.info)("simulation stopped: %s", self.stop_reason)
        return self
