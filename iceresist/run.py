"""``iceresist run SCENE.toml``: one simulation from a scene file to an HDF5 result with its XDMF sidecar.

The scene's ``[run]`` and ``[output]`` sections become the stop criteria and outputs of the one driver
(:func:`iceresist.driver.run_model`).

Everything that can fail on bad input (scene file, flags, stability, backend,
model construction) is checked before any file is opened, so a failed start
never touches an existing result. An existing result is kept unless
``--force`` (start again) or ``--pickup`` (continue from its checkpoint).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from iceresist import parallel
from iceresist.backends.jit import resolve_target
from iceresist.driver import DEFAULT_CHECKPOINT_WALL_S, Outputs, Stop, run_model
from iceresist.errors import InputError
from iceresist.io.paths import check_output_dir
from iceresist.limits import check_memory
from iceresist.models import build_model
from iceresist.post.case import window_summary
from iceresist.scene.load import load_scene, preset_names
from iceresist.scene.schema import Scene
from iceresist.simulation import IterationInterval, TimeInterval, WallTimeInterval

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


def result_paths(scene: Scene, output_dir=None) -> tuple[Path, Path]:
    """(result file, checkpoint file) of a scene."""
    out = Path(output_dir if output_dir is not None else scene.output.directory)
    return out / f"{scene.scene.name}.h5", out / f"{scene.scene.name}.checkpoint.h5"


def scene_outputs(scene: Scene) -> tuple[Stop, Outputs]:
    """The stop criteria (``[run]``) and outputs (``[output]``) of a scene."""
    r, o = scene.run, scene.output
    if o.fields_every_steps is not None:
        fields_schedule = IterationInterval(o.fields_every_steps)
    elif o.fields_every_s is not None:
        fields_schedule = TimeInterval(o.fields_every_s)
    else:
        fields_schedule = None
    if o.checkpoint_every_steps is not None:
        checkpoint = IterationInterval(o.checkpoint_every_steps)
    else:  # a killed long run keeps its work: by default every DEFAULT_CHECKPOINT_WALL_S of wall time
        checkpoint = WallTimeInterval(o.checkpoint_wall_s or DEFAULT_CHECKPOINT_WALL_S)
    return (Stop(iteration=r.steps, time_s=r.end_time_s, wall_s=r.wall_time_limit_s),
            Outputs(timeseries=IterationInterval(o.timeseries_every_steps), fields=tuple(o.fields),
                    fields_schedule=fields_schedule, checkpoint=checkpoint, watchdog_every=r.watchdog_every_steps))


def cmd_run(args) -> int:
    """Run one scene. Exit status 0 when it reached its stop criterion, 1 when it diverged."""
    t_start = time.perf_counter()
    scene = load_scene(args.scene)
    if args.steps is not None:
        if args.steps < 0:
            raise InputError(f"--steps: must be >= 0 (got {args.steps})")
        scene = _override(scene, "run", steps=args.steps, end_time_s=None)
    h5_path, chk_path = result_paths(scene, args.output)
    pickup = args.pickup

    def check_files():
        check_output_dir(args.output if args.output is not None else scene.output.directory,
                         "--output" if args.output is not None else "output.directory")
        if pickup:
            if not h5_path.is_file():
                raise InputError(f"{h5_path}: no result to continue (--pickup); run without --pickup first")
            if pickup is True and not chk_path.is_file():
                raise InputError(f"{chk_path}: no checkpoint to continue from")
            if args.force:
                raise InputError("--force and --pickup exclude each other: --force starts again, --pickup continues")
        elif h5_path.exists() and not args.force:
            raise InputError(f"{h5_path}: a result already exists; use --force to overwrite it or --pickup to "
                             f"continue it")

    comm = parallel.world()
    if args.backend is not None:           # the flag the user typed is the key a refusal names
        resolve_target(args.backend, "--backend")
    parallel.on_rank0(check_files, comm)   # the files as rank 0 sees them, before it writes any
    if scene.has_lattice:
        check_memory(scene, args.precision)
    if comm is not None and (args.backend or scene.numerics.backend) in ("cuda", "auto"):
        parallel.use_local_gpu(comm)       # several GPUs on a node: one per rank
    model = build_model(scene, backend=args.backend, precision=args.precision,
                        **({} if comm is None else {"comm": comm}))
    if comm is not None:
        log.info("MPI: %d ranks, blocks per rank %s", comm.size, model.describe()["mpi"]["blocks_per_rank"])
    stop, outputs = scene_outputs(scene)
    result = run_model(model, scene, h5_path, chk_path, stop=stop, outputs=outputs, pickup=pickup,
                       lattice_units=scene.is_lattice, progress=not args.no_progress and parallel.rank() == 0,
                       build_s=time.perf_counter() - t_start)
    if scene.ship is not None and getattr(result.sim, "completed", False) and parallel.rank() == 0:
        summary = window_summary(h5_path)
        if summary:
            log.info("%s: %s", scene.scene.name, summary)
    return 1 if result.sim.diverged else 0
