"""``iceresist run SCENE.toml``: one simulation from a scene file to an HDF5 result with its XDMF sidecar.

Everything that can fail on bad input (scene file, flags, stability, backend,
model construction) is checked before any file is opened, so a failed start
never touches an existing result. An existing result is kept unless
``--force`` (start again) or ``--pickup`` (continue from its checkpoint).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import logging
from pathlib import Path

from iceresist.errors import InputError
from iceresist.io.hdf5 import RunFile
from iceresist.io.meta import leg_meta, run_meta
from iceresist.scene.load import load_scene, preset_names
from iceresist.scene.schema import Scene
from iceresist.simulation import (Checkpointer, FieldWriter, IterationInterval, Simulation, TimeInterval,
                                  TimeSeriesWriter, WallTimeInterval)

log = logging.getLogger(__name__)


def add_run_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``iceresist run`` on a (sub)parser; sets ``func=cmd_run``."""
    p.add_argument("scene", metavar="SCENE.toml",
                   help=f"scene file, or the name of a built-in scene ({', '.join(preset_names())})")
    p.add_argument("--backend", choices=("auto", "cpu", "cuda"), help="override numerics.backend")
    p.add_argument("--precision", choices=("float32", "float64"), help="override numerics.precision")
    p.add_argument("--steps", type=int, metavar="N", help="stop at iteration N (replaces run.steps and run.end_time_s)")
    p.add_argument("--output", metavar="DIR", help="result folder (override output.directory)")
    p.add_argument("--force", action="store_true", help="overwrite an existing result")
    p.add_argument("--pickup", nargs="?", const=True, default=False, metavar="CHECKPOINT",
                   help="continue an existing result from its checkpoint (or from CHECKPOINT)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_run)
    return p


def _override(scene: Scene, section: str, **values) -> Scene:
    """A copy of ``scene`` with keys of one section replaced, validated again."""
    data = scene.model_dump()
    data[section].update(values)
    new = Scene.model_validate(data)
    new._source_text, new._source_name = scene.source_text, scene.source_name
    return new


#: Wall time (s) between checkpoints of a run whose scene sets neither ``output.checkpoint_every_steps`` nor
#: ``output.checkpoint_wall_s``; the sweep's :data:`iceresist.sweep.CHECKPOINT_WALL_S` is this value.
DEFAULT_CHECKPOINT_WALL_S = 600.0


def result_paths(scene: Scene, output_dir=None) -> tuple[Path, Path]:
    """(result file, checkpoint file) of a scene."""
    out = Path(output_dir if output_dir is not None else scene.output.directory)
    return out / f"{scene.scene.name}.h5", out / f"{scene.scene.name}.checkpoint.h5"


def build_simulation(scene: Scene, model, runfile: RunFile, checkpoint_path, *, progress: bool = True,
                     wall_before_s: float = 0.0) -> Simulation:
    """The Simulation of a scene: stop criteria from ``[run]``, writers from ``[output]``. ``wall_before_s``:
    wall time of the earlier legs of a continued run (the checkpointer notes the running total in the file)."""
    r, o = scene.run, scene.output
    sim = Simulation(model, stop_iteration=r.steps, stop_time_s=r.end_time_s, wall_time_limit_s=r.wall_time_limit_s,
                     progress=progress)
    if o.fields_every_steps is not None:
        fields_schedule = IterationInterval(o.fields_every_steps)
    elif o.fields_every_s is not None:
        fields_schedule = TimeInterval(o.fields_every_s)
    else:
        fields_schedule = None
    units = {k: v for k, v in model.field_units(scene.is_lattice).items() if k in o.fields} \
        if hasattr(model, "field_units") else None
    sim.output_writers["fields"] = FieldWriter(runfile, fields_schedule, list(o.fields), units=units)
    sim.output_writers["timeseries"] = TimeSeriesWriter(runfile, IterationInterval(o.timeseries_every_steps))
    if o.checkpoint_every_steps is not None:
        chk_schedule = IterationInterval(o.checkpoint_every_steps)
    else:  # a killed long run keeps its work: by default every DEFAULT_CHECKPOINT_WALL_S of wall time
        chk_schedule = WallTimeInterval(o.checkpoint_wall_s or DEFAULT_CHECKPOINT_WALL_S)
    sim.output_writers["checkpointer"] = Checkpointer(checkpoint_path, chk_schedule, runfile=runfile,
                                                      wall_before_s=wall_before_s)
    from iceresist import watchdog

    watchdog.install(sim, interval=r.watchdog_every_steps, runfile=runfile,
                     json_path=Path(runfile.path).with_suffix(".watchdog.json"))
    return sim


def cmd_run(args) -> int:
    """Run one scene. Exit status 0 when it reached its stop criterion, 1 when it diverged."""
    from iceresist.model import build_model

    scene = load_scene(args.scene)
    if args.steps is not None:
        if args.steps < 0:
            raise InputError(f"--steps: must be >= 0 (got {args.steps})")
        scene = _override(scene, "run", steps=args.steps, end_time_s=None)
    h5_path, chk_path = result_paths(scene, args.output)
    pickup = args.pickup
    if pickup:
        if not h5_path.is_file():
            raise InputError(f"{h5_path}: no result to continue (--pickup); run without --pickup first")
        if pickup is True and not chk_path.is_file():
            raise InputError(f"{chk_path}: no checkpoint to continue from")
        if args.force:
            raise InputError("--force and --pickup exclude each other: --force starts again, --pickup continues")
    elif h5_path.exists() and not args.force:
        raise InputError(f"{h5_path}: a result already exists; use --force to overwrite it or --pickup to continue it")

    model = build_model(scene, backend=args.backend, precision=args.precision)

    h5_path.parent.mkdir(parents=True, exist_ok=True)
    if not pickup and chk_path.exists():
        chk_path.unlink()  # a stale checkpoint of the overwritten result
    stale = h5_path.with_suffix(".watchdog.json")
    if stale.exists():
        stale.unlink()  # the diagnostic of an earlier run of this result
    mode = "a" if pickup else "w"
    u = model.units
    with RunFile(h5_path, mode, shape_cells=model.shape_cells, dx_m=u.dx_m) as rf:
        desc = model.describe()
        if not pickup:
            rf.write_meta(**run_meta(scene_text=scene.source_text, backend=desc["backend"],
                                     precision=desc["precision"], cells=model.cells),
                          scene_name=scene.scene.name, scene_source=scene.source_name,
                          description=scene.scene.description, model=desc, units=u.describe(),
                          shape_cells=None if model.shape_cells is None else list(model.shape_cells))
        earlier = rf.meta if pickup else {}
        # the file notes the wall time up to its own checkpoint, not up to one named with --pickup CHECKPOINT
        wall_before_s = float(earlier.get("checkpoint_wall_s", 0.0)) if pickup is True else 0.0
        if pickup and (pickup is not True or "checkpoint_wall_s" not in earlier):
            log.warning("%s: the wall time up to the checkpoint is not known (%s): its wall_time_s will count from "
                        "the pickup", h5_path, "another checkpoint" if pickup is not True else "an older iceresist "
                        "wrote the file")
        sim = build_simulation(scene, model, rf, chk_path, progress=not args.no_progress,
                               wall_before_s=wall_before_s)
        rf.write_meta(finished=False)  # a result being continued is unfinished until this leg completes
        log.info("running %s: %d cells, dt = %.4g s, tau = %.6g, %s on %s -> %s", scene.scene.name, model.cells,
                 u.dt_s, u.tau, model.precision, model.target.name, h5_path)
        try:
            sim.run(pickup=chk_path if pickup is True else pickup)
        finally:
            # totals over the legs of the run: steps from iteration 0, the wall time of the work kept (a leg
            # killed after its last checkpoint loses the steps and the time after it); mlups: this leg's rate
            start = sim.start_iteration if sim.start_iteration is not None else model.iteration
            rf.write_meta(**leg_meta(earlier, start, desc["backend"]),
                          iteration=model.iteration, time_s=model.time_s, steps=int(model.iteration),
                          wall_time_s=wall_before_s + sim.wall_time_s, step_time_s=sim.step_time_s, mlups=sim.mlups,
                          stop_reason=sim.stop_reason or "interrupted", diverged=sim.diverged, finished=sim.completed,
                          finished_utc=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
    log.info("%s: %d steps in %.2f s (%.2f MLUPS) -> %s", sim.stop_reason, sim.steps_done, sim.wall_time_s,
             sim.mlups, h5_path)
    return 1 if sim.diverged else 0
