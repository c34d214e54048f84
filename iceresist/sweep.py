"""``iceresist sweep``: the paper's ship cases at one fidelity and tier, one HDF5 per case and a sweep table.

Layout of a sweep folder::

    DIR/sweep.json            preset, tier, cases asked for (written first)
    DIR/cases/<case>.h5       one finished run: meta, timeseries (Fx_N, x_bow_m, ...), bodies (ice start/end)
    DIR/sweep.csv             one row per finished case (pandas), built from the case files by
                              :func:`iceresist.post.sweeptable.sweep_table` at the end of the sweep

A case is written to ``<case>.partial.h5`` and renamed when it has finished, so a killed sweep leaves no
half-finished result under the final name. A running case also writes its whole state to
``<case>.checkpoint.h5`` every ``CHECKPOINT_WALL_S`` of wall time (deleted when the case finishes). Started
again, the sweep skips every finished case, continues an unfinished one from its checkpoint (when the
partial file holds the same scene; otherwise it runs the case from its start) and rebuilds the table from the
files, so it ends with the table an uninterrupted sweep gives: bit for bit in the tests (tier 1, and the
CI-sized tier 2), statistically for a long tier-2 case (docs/SHIP.md, "Reproducibility"). A finished case whose
scene is not what the preset gives now (the preset has changed since) stops the sweep with a one-line error
before anything runs, so one table never mixes two versions of a preset.

Under ``mpirun -n N`` the sweep spreads whole cases over the ranks (each case on one process; docs/PARALLEL.md):
rank 0 holds the folder's lock and writes ``sweep.json`` and ``sweep.csv``, every rank runs its share of the cases
not yet finished.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import pandas as pd

from iceresist import parallel
from iceresist.driver import DEFAULT_CHECKPOINT_WALL_S
from iceresist.errors import InputError
from iceresist.io.paths import check_output_dir
from iceresist.models.fluid import resolve_target
from iceresist.post.sweeptable import TABLE_NAME, case_path, is_finished, sweep_table
from iceresist.post.sweeptable import stored_meta as _stored_meta
from iceresist.ship.presets import CASES, FIDELITIES, case_scene, get_case

log = logging.getLogger(__name__)

#: The lock file of a sweep folder (:func:`folder_lock`).
LOCK_NAME = ".sweep.lock"

#: Scene overrides of the CI-sized sweep (a 0.3 m channel crossed in 0.75 s): the machinery, not the physics.
TINY_OVERRIDES = {"ice": {"channel_length_m": 0.3}, "run": {"end_time_s": 0.75}, "contact": {"sample_interval_s": 0.002},
                  "ship": {"steady_window_m": [4.1, 4.3], "sphere_band_m": 0.03, "sphere_spacing_m": 0.05}}

#: Wall-clock seconds between the checkpoints of a running case (a tier-2 quick case runs for hours here).
CHECKPOINT_WALL_S = DEFAULT_CHECKPOINT_WALL_S  # the same interval as `iceresist run`

#: Scene overrides of the CI-sized tier-2 case: a 0.48 m hull (B-063 proportions at about 1:7, 30 deg bow)
#: stem-on to four cubes in a 64 x 16 x 16-cell tank of 41/3 mm cells, 0.06 s: the machinery, not the physics.
TINY_TIER2_OVERRIDES = {
    "domain": {"cells": [64, 16, 16], "dx_m": 0.041 / 3},
    "free_surface": {"water_depth_m": 0.14},
    "fluid": {"nu_m2_s": 1.0e-5},
    "numerics": {"mach": 0.1, "precision": "float32"},
    "ship": {"length_m": 0.48, "beam_m": 0.08, "draught_m": 0.06, "parallel_length_m": 0.2, "start_x_m": 0.42,
             "sphere_spacing_m": 0.02, "sphere_band_m": 0.03, "steady_window_m": [0.43, 0.45]},
    "ice": {"concentration": None, "count": 4, "channel_length_m": 0.1, "channel_start_x_m": 0.42},
    "contact": {"sample_interval_s": 0.004},
    "run": {"end_time_s": 0.06},
}


def checkpoint_path(out_dir, case: str) -> Path:
    return Path(out_dir) / "cases" / f"{case}.checkpoint.h5"


def _resumable(partial: Path, checkpoint: Path, scene_text: str) -> dict | None:
    """The meta of ``partial`` when a killed run of the same scene can continue from ``checkpoint``, else None.

    A checkpoint that cannot be read (truncated by a full disk, a kill during a copy) cannot be continued and
    would fail every rerun: it is moved aside (kept, ``*.unreadable-N``) with a warning, and the case starts
    again from the beginning."""
    meta = _stored_meta(partial) if checkpoint.is_file() else None
    if meta is None or meta.get("scene_toml") != scene_text:
        return None
    from iceresist.io.checkpoint import read_checkpoint

    try:
        read_checkpoint(checkpoint)
    except InputError as exc:
        kept = set_aside(checkpoint)
        log.warning("%s; the case starts again from the beginning (the checkpoint is kept as %s)", exc, kept.name)
        return None
    return meta


def set_aside(path: Path) -> Path:
    """Rename ``path`` to the first free ``<name>.unreadable-N``; returns the new path."""
    n = 1
    while path.with_name(f"{path.name}.unreadable-{n}").exists():
        n += 1
    new = path.with_name(f"{path.name}.unreadable-{n}")
    path.replace(new)
    return new


def keep_foreign_file(path: Path) -> None:
    """A file under a case's result name that is not a case result (random bytes, another program's HDF5) would be
    replaced by the case's run: move it aside first, with a warning, so nothing the user put there is lost."""
    if not path.exists():
        return
    meta = _stored_meta(path)
    if meta is not None and "case" in meta:
        return
    kept = set_aside(path)
    log.warning("%s: not a case result of iceresist; kept as %s, and the case runs", path, kept.name)


def check_same_scene(path: Path, scene_text: str) -> None:
    """Refuse a finished case file whose scene is not ``scene_text`` (the preset has changed since it ran), so
    that one table never mixes two versions of a preset. Nothing is written or removed."""
    old = str((_stored_meta(path) or {}).get("scene_toml", ""))
    if old == scene_text:
        return
    a, b = old.splitlines(), scene_text.splitlines()
    i = next((k for k, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
    was = a[i].strip() if i < len(a) else "(end of file)"
    now = b[i].strip() if i < len(b) else "(end of file)"
    raise InputError(f"{path}: finished with another scene than this preset gives now (line {i + 1}: {was!r} "
                     f"then, {now!r} now); use another --output folder, or move the file away to run the case "
                     f"again")


def resolve_cases(cases) -> list[str]:
    """Case names in matrix order; ``None`` or ``"all"`` = every case."""
    if cases is None or cases == "all" or cases == ["all"]:
        return list(CASES)
    if isinstance(cases, str):
        cases = [c.strip() for c in cases.split(",") if c.strip()]
    if not cases:
        raise InputError(f"--cases: no case named; give 'all' or case names such as {next(iter(CASES))}")
    names = [get_case(c).name for c in cases]
    return [c for c in CASES if c in names]


def read_sweep_info(path: Path) -> dict:
    """The ``sweep.json`` of a sweep folder; one that is not a JSON object names the file and the fix."""
    try:
        info = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a sweep description ({type(exc).__name__}); move it away or use another "
                         f"--output folder") from None
    if not isinstance(info, dict):
        raise InputError(f"{path}: not a sweep description (not a JSON object); move it away or use another "
                         f"--output folder")
    return info


def run_case(case: str, fidelity: str, tier: int, out_dir, *, backend: str = "auto", progress: bool = False,
             overrides: dict | None = None, callbacks: dict | None = None, checkpoint_schedule=None) -> Path:
    """Run one case to ``DIR/cases/<case>.h5`` through the driver (:func:`iceresist.driver.run_model`), via a
    partial file renamed at the end, continuing a killed run of it from its checkpoint. ``checkpoint_schedule``:
    when to checkpoint (default every ``CHECKPOINT_WALL_S`` of wall time)."""
    from iceresist.driver import Outputs, Stop, run_model
    from iceresist.models import RefinedTier2Model, Tier1Model, Tier2Model
    from iceresist.simulation import IterationInterval, WallTimeInterval

    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    t_build = time.perf_counter()
    scene = case_scene(case, fidelity, tier, **(overrides or {}))
    final = case_path(out_dir, case)
    partial = final.with_name(f"{case}.partial.h5")
    chk = checkpoint_path(out_dir, case)
    final.parent.mkdir(parents=True, exist_ok=True)
    earlier = _resumable(partial, chk, scene.source_text)
    if tier == 1:
        model = Tier1Model(scene, backend=backend)
    else:
        model = (Tier2Model if scene.refinement is None else RefinedTier2Model)(scene, backend=backend)
    c = get_case(case)

    def on_new(rf, model):
        g = rf.h5.require_group("bodies")
        g["initial_positions_m"] = model.ice_state()["positions_m"]
        for key, value in model.floes_record().items():
            g[key] = value
        g["hull_vertices_m"] = model.geometry.vertices()

    def on_completed(rf, model, sim):
        st = model.ice_state()
        g = rf.h5["bodies"]
        g["final_positions_m"] = st["positions_m"]
        g["final_quaternions"] = st["quaternions"]
        rf.write_meta(dem_substeps=int(model.dem.substeps_taken), lbm_steps=int(model.lbm_steps),
                      final_x_bow_m=model.x_bow_m)

    log.info("case %s (%s, tier %d): %d cubes, %d spheres, %.3g s simulated", case, fidelity, tier,
             model.layout.count, model.dem.n_spheres, scene.run.end_time_s)
    if earlier is not None:
        log.info("case %s: continuing from its checkpoint at record %d", case,
                 int(earlier.get("checkpoint_iteration", -1)))
    outputs = Outputs(timeseries=IterationInterval(1), checkpoint_final=False,
                      checkpoint=checkpoint_schedule or WallTimeInterval(CHECKPOINT_WALL_S))
    result = run_model(model, scene, partial, chk, stop=Stop(time_s=scene.run.end_time_s), outputs=outputs,
                       pickup=earlier is not None, progress=progress, callbacks=callbacks,
                       meta={"case": case, "fidelity": fidelity, "tier": tier, "bow": c.bow,
                             "concentration_nominal": c.concentration, "knots": c.knots},
                       on_new=on_new, on_completed=on_completed, build_s=time.perf_counter() - t_build,
                       leave_progress=False)
    sim, dog = result.sim, result.watchdog
    if dog.report is not None:
        raise InputError(f"case {case}: stopped by the watchdog: {dog.report.message} "
                         f"(diagnostic in {partial.with_suffix('.watchdog.json').name})")
    if sim.diverged:
        raise InputError(f"case {case}: the DEM run diverged ({sim.stop_reason}); lower contact.dem_safety")
    if not sim.completed:  # a callback stopped it before its end: the partial file and checkpoint stay
        raise InputError(f"case {case}: stopped before its end time ({sim.stop_reason}); run the sweep again "
                         f"to continue it from its checkpoint")
    partial.replace(final)
    chk.unlink(missing_ok=True)
    return final


def run_sweep(fidelity: str, tier: int, out_dir, cases=None, *, backend: str = "auto", progress: bool = False,
              overrides: dict | None = None, callbacks: dict | None = None,
              checkpoint_schedule=None) -> pd.DataFrame:
    """Run every case not yet finished in ``out_dir`` (an interrupted one continues from its checkpoint) and
    write ``sweep.csv``; returns the table."""
    if fidelity not in FIDELITIES:
        raise InputError(f"--preset: unknown preset {fidelity!r}; use one of {', '.join(FIDELITIES)}")
    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    names = resolve_cases(cases)
    comm = parallel.world()
    if comm is not None:
        return _run_sweep_ranks(comm, fidelity, tier, out_dir, names, backend=backend, overrides=overrides,
                                callbacks=callbacks, checkpoint_schedule=checkpoint_schedule)
    out = check_output_dir(out_dir, "--output")
    resolve_target(backend, "--backend")
    out.mkdir(parents=True, exist_ok=True)
    lock = folder_lock(out)
    try:
        return _run_sweep_locked(fidelity, tier, out, names, backend=backend, progress=progress,
                                 overrides=overrides, callbacks=callbacks, checkpoint_schedule=checkpoint_schedule)
    finally:
        lock.release()


def _run_sweep_ranks(comm, fidelity: str, tier: int, out_dir, names: list, *, backend, overrides, callbacks,
                     checkpoint_schedule) -> pd.DataFrame | None:
    """:func:`run_sweep` under ``mpirun``: whole cases spread over the ranks (each case on one process, the cases
    not yet finished dealt out in turn). Rank 0 checks the folder, takes its lock, writes ``sweep.json`` and, when
    every rank is done, ``sweep.csv``; it returns the table, the other ranks None. A case that fails on bad input
    stops the sweep with its message (after the other ranks' cases end)."""
    out = Path(out_dir)
    lock, error, finished = None, None, None
    if comm.rank == 0:
        try:
            out = check_output_dir(out_dir, "--output")
            resolve_target(backend, "--backend")
            out.mkdir(parents=True, exist_ok=True)
            lock = folder_lock(out)
            finished = _prepare_sweep(fidelity, tier, out, names, overrides)
        except InputError as exc:
            error = str(exc)
            if lock is not None:
                lock.release()
    error, finished = comm.bcast((error, finished), root=0)
    if error is not None:
        raise InputError(error)
    todo = [c for c in names if c not in finished]
    mine = todo[comm.rank::comm.size]
    log.info("rank %d of %d: cases %s", comm.rank, comm.size, ", ".join(mine) or "none")
    failed = None
    for case in mine:
        try:
            run_case(case, fidelity, tier, out, backend=backend, progress=False, overrides=overrides,
                     callbacks=callbacks, checkpoint_schedule=checkpoint_schedule)
        except InputError as exc:
            failed = f"case {case}: {exc}"
            break
    failures = [f for f in comm.allgather(failed) if f is not None]
    table = None
    if comm.rank == 0:
        try:
            if not failures:
                table = _write_table(out)
        finally:
            lock.release()
    if failures:
        raise InputError(failures[0])
    return table


def folder_lock(out: Path):
    """The acquired exclusive lock of a sweep folder (``.sweep.lock``; the caller releases it, and the system does
    when the process dies): a second sweep into the same folder is refused in one line instead of both writing
    the same case files."""
    from filelock import FileLock, Timeout

    lock = FileLock(out / LOCK_NAME, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise InputError(f"--output: another sweep is running in {out} (lock {out / LOCK_NAME}); wait for it to "
                         f"finish or use another --output folder") from None
    return lock


def _run_sweep_locked(fidelity: str, tier: int, out: Path, names: list, *, backend, progress, overrides, callbacks,
                      checkpoint_schedule) -> pd.DataFrame:
    """:func:`run_sweep` inside the folder's lock."""
    finished = _prepare_sweep(fidelity, tier, out, names, overrides)
    bar = _cases_bar(names, progress)
    for case in names:
        if bar is not None:
            bar.set_description_str(f"{fidelity} tier {tier}: {case}")
        if case in finished:
            log.info("case %s: finished earlier, skipped", case)
        else:
            run_case(case, fidelity, tier, out, backend=backend, progress=progress, overrides=overrides,
                     callbacks=callbacks, checkpoint_schedule=checkpoint_schedule)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return _write_table(out)


def _write_table(out: Path) -> pd.DataFrame:
    table = sweep_table(out)
    table.to_csv(out / TABLE_NAME, index=False, float_format="%.10g")  # the one place sweep.csv is written
    return table


def _prepare_sweep(fidelity: str, tier: int, out: Path, names: list, overrides) -> list:
    """Inside the folder's lock, before any case runs: the folder's ``sweep.json`` checked against this sweep and
    rewritten, files of other sweeps set aside, the finished cases' scenes checked; returns the finished cases."""
    info = {"preset": fidelity, "tier": tier, "cases": names, "overrides": overrides or {}}
    info_path = out / "sweep.json"
    if info_path.is_file():
        old = read_sweep_info(info_path)
        if (old.get("preset"), old.get("tier"), old.get("overrides", {})) != (fidelity, tier, overrides or {}):
            raise InputError(f"{out}: holds a sweep with preset {old.get('preset')!r}, tier {old.get('tier')}: "
                             f"use another --output folder")
        info["cases"] = [c for c in CASES if c in set(old.get("cases", [])) | set(names)]
    for case in names:
        keep_foreign_file(case_path(out, case))
    finished = [c for c in CASES if is_finished(case_path(out, c))]  # running one case finishes no other
    for case in finished:  # every case the table would read, before anything runs or is written
        check_same_scene(case_path(out, case), case_scene(case, fidelity, tier, **(overrides or {})).source_text)
    info_path.write_text(json.dumps(info, indent=1))
    return finished


def _cases_bar(names, progress: bool):
    """A progress bar over the cases of a sweep (on a terminal; each case's own bar runs beneath it)."""
    if not (progress and sys.stderr.isatty()):
        return None
    from tqdm import tqdm

    return tqdm(total=len(names), unit="case", dynamic_ncols=True, file=sys.stderr)


# -- command line ------------------------------------------------------------------------------------------
def add_sweep_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``iceresist sweep``; sets ``func=cmd_sweep``."""
    p.add_argument("--preset", default="quick", help=f"fidelity: {' | '.join(FIDELITIES)} (default quick)")
    p.add_argument("--tier", type=int, default=1, help="1 = DEM with water models, 2 = coupled LBM-DEM")
    p.add_argument("--cases", default="all", help=f"comma-separated case names or 'all' ({', '.join(CASES)})")
    p.add_argument("--output", metavar="DIR", help="sweep folder (default runs/sweep-<preset>-t<tier>)")
    p.add_argument("--backend", choices=("auto", "cpu", "cuda"), default="auto")
    p.add_argument("--threads", type=int, help="CPU threads of the DEM kernels (numba)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--amr", action="store_true", help="tier 2 on the preset's refined levels: the hull, the ice and "
                   "the surface on the finest level (docs/SHIP.md)")
    m = p.add_argument_group("your own hull (Bow A cases; the hull replaces B-063)")
    m.add_argument("--mesh", metavar="HULL.stl", help="closed hull surface, STL or OBJ, at the preset's model "
                   "scale (draught 0.44 m), or a built-in mesh (b063)")
    m.add_argument("--mesh-unit", default="m", help="unit of the mesh's coordinates: m, cm, mm, ft, in (default m)")
    m.add_argument("--mesh-bow", default="+x", help="the mesh's axis toward the bow (default +x; write --mesh-bow=-x)")
    m.add_argument("--mesh-up", default="+z", help="the mesh's upward axis (default +z)")
    p.set_defaults(func=cmd_sweep)
    return p


def set_threads(n: int | None):
    from iceresist.backends.jit import set_threads as set_backend_threads

    set_backend_threads(n, "--threads")


def mesh_overrides(args) -> tuple[dict, str]:
    """The ``[ship]`` keys of ``--mesh`` (checked here, before anything is written) and the cases to run: with a
    mesh, ``all`` means every Bow A case."""
    if not getattr(args, "mesh", None):
        return {}, args.cases
    from iceresist.scene.schema import Ship
    from fsicr.hullmesh import MeshKeys
    from iceresist.ship.meshhull import MeshHull, resolve_mesh_path

    path = resolve_mesh_path(args.mesh)
    path = str(Path(path).resolve()) if Path(path).is_file() else path
    values = {"hull": "mesh", "mesh_file": path, "mesh_unit": args.mesh_unit, "mesh_bow": args.mesh_bow,
              "mesh_up": args.mesh_up}
    for key, value in values.items():
        allowed = Ship.model_fields[key].annotation
        if key != "mesh_file" and value not in getattr(allowed, "__args__", (value,)):
            raise InputError(f"--{key.replace('_', '-')}: {value!r} is not one of "
                             f"{', '.join(allowed.__args__)}")
    cases = args.cases
    if str(cases).strip() == "all":
        cases = ",".join(c for c in CASES if get_case(c).bow == "A")
    bow_b = [c for c in resolve_cases(cases) if get_case(c).bow != "A"]
    if bow_b:
        raise InputError(f"--cases: {', '.join(bow_b)} name Bow B of B-063; with --mesh the mesh is the hull, so run "
                         f"the A cases (e.g. --cases A-c68-v1.0)")
    draught = float(case_scene(resolve_cases(cases)[0], args.preset, args.tier).ship.draught_m)
    MeshHull.from_file(path, draught, unit=args.mesh_unit, bow=args.mesh_bow, up=args.mesh_up,
                       keys=MeshKeys(draught=f"--mesh (the preset's draught {draught:g} m)"))
    return {"ship": values}, cases


def cmd_sweep(args) -> int:
    from iceresist.ship.cases import amr_overrides

    overrides, cases = mesh_overrides(args)
    suffix = f"-{Path(args.mesh).stem}" if overrides else ""
    if args.amr:
        if args.tier != 2:
            raise InputError("--amr: refined levels are a tier-2 tank; add --tier 2")
        for section, values in amr_overrides(args.preset).items():
            overrides.setdefault(section, {}).update(values)
        suffix += "-amr"
    out = args.output or f"runs/sweep-{args.preset}-t{args.tier}{suffix}"
    set_threads(args.threads)
    table = run_sweep(args.preset, args.tier, out, cases, backend=args.backend,
                      progress=not args.no_progress, overrides=overrides or None)
    if table is None:       # an MPI rank other than 0
        return 0
    cols = ["case", "mean_force_N", "ci95_N", "R_sim_kN", "R_CH_FSICR_kN", "ratio_sim_FSICR", "wall_time_s"]
    log.info("sweep table %s/sweep.csv:\n%s", out, table[cols].to_string(index=False, float_format="%.4g"))
    return 0
