"""One rung of a reference case through the one driver (:func:`iceresist.driver.run_model`).

A case builds its scene (a TOML text, parsed like any scene file) and the model of that scene, sets an initial
condition the scene keys do not express (a vortex, a wave) on the model, and hands both to :func:`run_rung`,
which runs it into ``DIR/runs/CASE/LABEL.h5``: the scene text, the model, the units and the case's parameters in
``meta``, one time-series row of ``model.diagnostics()`` plus the case's probes per sample, and the final fields
the case asks for. The case then reduces that file to its :class:`~iceresist.validate.result.CaseResult`; the
file stays beside ``ladder.csv`` for a second look (``iceresist inspect``).
"""

from __future__ import annotations

import contextlib
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iceresist.driver import Outputs, Stop, run_model
from iceresist.io.hdf5 import RunFile
from iceresist.scene.load import parse_scene
from iceresist.scene.write import to_toml
from iceresist.simulation import IterationInterval


@dataclass
class Rung:
    """What a rung's run left: its result file, the time series, the final fields it kept, and timings."""

    path: Path
    timeseries: dict
    fields: dict
    steps: int
    #: wall time (s) of the stepping after the first (compiling) chunk, and the steps it covers
    wall_s: float
    timed_steps: int
    meta: dict

    @property
    def run_time_s(self) -> float:
        """Wall time of all ``steps`` at the pace of the compiled kernels (the first chunk, which compiles or
        loads them, replaced by the same pace): the run time a ladder sets against the error."""
        return self.wall_s * self.steps / self.timed_steps if self.timed_steps > 0 else float("nan")


def scene_of(data: dict, source: str):
    """A scene from the nested ``data`` of a scene file (validated like a file on disk; ``source`` names it)."""
    return parse_scene(to_toml(data), source)


def slug(label: str) -> str:
    """A file name from a rung label: ``"16 cells/width"`` -> ``"16-cells-width"``."""
    return re.sub(r"[^A-Za-z0-9.]+", "-", label).strip("-")


def result_path(out_dir, case: str, label: str) -> Path:
    """Where a rung's result file goes: ``OUT/runs/CASE/LABEL.h5``."""
    return Path(out_dir) / "runs" / case / f"{slug(label)}.h5"


@contextlib.contextmanager
def rung_folder(out_dir, case: str, label: str):
    """A folder for a rung that runs a sweep case (the ship ladders): ``OUT/runs/CASE/LABEL/`` (kept, so a killed
    rung continues from its checkpoint when the ladder is run again), or a scratch folder where ``out_dir`` is
    None."""
    if out_dir is None:
        with tempfile.TemporaryDirectory(prefix="iceresist-rung-") as tmp:
            yield Path(tmp)
        return
    folder = result_path(out_dir, case, label).with_suffix("")
    folder.mkdir(parents=True, exist_ok=True)
    yield folder


def run_rung(model, scene, out_dir, case: str, params: dict, *, steps: int, sample_every: int,
             probes: dict | None = None, fields: tuple[str, ...] = (), initial: str | None = None,
             callbacks: dict | None = None) -> Rung:
    """Run ``model`` for ``steps`` steps into :func:`result_path`, a time-series row every ``sample_every`` steps
    (and at the start and the end) with the ``probes`` columns ``{name: func(model)}``, the ``fields`` at the
    end; ``initial`` describes an initial condition set on the model beside the scene's (written to ``meta``);
    ``callbacks``: ``{name: (func(sim), every_steps)}`` (:func:`iceresist.driver.run_model`).
    No checkpoint: a rung is short, and a killed ladder reruns the rungs not yet in ``ladder.csv``.
    ``out_dir`` None: a scratch folder, removed after the run (the returned path no longer exists)."""
    if out_dir is None:
        with tempfile.TemporaryDirectory(prefix="iceresist-rung-") as tmp:
            return run_rung(model, scene, tmp, case, params, steps=steps, sample_every=sample_every, probes=probes,
                            fields=fields, initial=initial, callbacks=callbacks)
    path = result_path(out_dir, case, params["label"])
    outputs = Outputs(timeseries=IterationInterval(sample_every), fields=tuple(fields), checkpoint=None,
                      checkpoint_final=False, probes=dict(probes or {}))
    meta = {"validation_case": case, "rung": dict(params)}
    if initial:
        meta["initial_condition"] = initial
    res = run_model(model, scene, path, None, stop=Stop(iteration=steps), outputs=outputs, meta=meta,
                    lattice_units=scene.scene.units == "lattice", progress=False, callbacks=callbacks)
    sim = res.sim
    if not sim.completed:
        raise RuntimeError(f"{case} {params['label']}: {sim.stop_reason} ({path})")
    with RunFile(path) as rf:
        ts = rf.timeseries()
        its = rf.snapshot_iterations()
        last = {name: rf.read_field(its[-1], name) for name in fields} if its else {}
        meta_out = rf.meta
    return Rung(path=path, timeseries={k: np.asarray(v) for k, v in ts.items()}, fields=last,
                steps=int(sim.steps_done), wall_s=float(sim.step_time_s - sim.first_step_s),
                timed_steps=int(sim.steps_done - sim.first_steps), meta=meta_out)
