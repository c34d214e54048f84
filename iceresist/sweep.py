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
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from pydantic import ValidationError

from fsicr.hullmesh import MeshKeys
from iceresist import parallel
from iceresist.backends.jit import resolve_target, set_threads as set_backend_threads
from iceresist.driver import DEFAULT_CHECKPOINT_WALL_S, Outputs, Stop, run_model
from iceresist.errors import InputError
from iceresist.io.checkpoint import read_checkpoint
from iceresist.io.paths import check_output_dir
from iceresist.models import Tier1Model, Tier2Model
from iceresist.post.sweeptable import TABLE_NAME, case_path, is_finished, stored_meta as _stored_meta, sweep_table
from iceresist.scene.case_scenes import CASES, FIDELITIES, case_scene, get_case
from iceresist.ship.cases import amr_overrides
from iceresist.ship.matrix import HullSpec, MatrixCase, hull_at, matrix_from_flags, read_matrix
from iceresist.ship.meshhull import resolve_mesh_path
from iceresist.simulation import IterationInterval, WallTimeInterval

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

#: The smallest ship on refined levels: a 0.24 m hull and one cube in a 32 x 8 x 16-cell tank of 41/3 mm cells, the
#: surface, the hull and the cube on level 1 (48 leaf blocks): few enough blocks for the CUDA simulator and the GPU
#: build check (tier 2 on levels on the device).
TINY_TIER2_AMR_OVERRIDES = {
    **{k: dict(v) for k, v in TINY_TIER2_OVERRIDES.items()},
    "domain": {"cells": [32, 8, 16], "dx_m": 0.041 / 3},
    "free_surface": {"water_depth_m": 0.16},
    "ship": {**TINY_TIER2_OVERRIDES["ship"], "length_m": 0.24, "beam_m": 0.04, "draught_m": 0.02,
             "parallel_length_m": 0.1, "start_x_m": 0.21, "steady_window_m": [0.215, 0.22]},
    "ice": {**TINY_TIER2_OVERRIDES["ice"], "count": 1, "channel_length_m": 0.05, "channel_start_x_m": 0.21},
    "contact": {"sample_interval_s": 0.00466},
    "refinement": {"levels": 1, "surface_band_m": 0.04, "body_band_m": 0.02, "regrid_every_steps": 4},
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


def resolve_cases(cases, plan: dict | None = None) -> list[str]:
    """Case names in matrix order (``plan``'s, default the paper's); ``None`` or ``"all"`` = every case."""
    known = list(plan) if plan is not None else list(CASES)
    if cases is None or cases == "all" or cases == ["all"]:
        return known
    if isinstance(cases, str):
        cases = [c.strip() for c in cases.split(",") if c.strip()]
    if not cases:
        raise InputError(f"--cases: no case named; give 'all' or case names such as {known[0]}")
    names = [case_spec(c, plan).name for c in cases]
    return [c for c in known if c in names]


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


def case_spec(case: str, plan: dict | None = None) -> MatrixCase:
    """The :class:`~iceresist.ship.matrix.MatrixCase` of a case name: from ``plan`` (a user's matrix, or the paper's
    cases on a mesh) or the paper's case on B-063."""
    if plan is not None:
        if case not in plan:
            raise InputError(f"--cases: {case!r} is not a case of this sweep; its cases: {', '.join(plan)}")
        return plan[case]
    return MatrixCase(get_case(case))


def sweep_scene(spec: MatrixCase, fidelity: str, tier: int, amr: bool = False, overrides: dict | None = None):
    """The validated scene of one case of a sweep (:func:`~iceresist.scene.case_scenes.case_scene`)."""
    return case_scene(spec.case, fidelity, tier, amr=amr, hull=spec.hull, hull_keys=spec.hull_keys,
                      **(overrides or {}))


def run_case(case: str, fidelity: str, tier: int, out_dir, *, backend: str = "auto", progress: bool = False,
             overrides: dict | None = None, callbacks: dict | None = None, checkpoint_schedule=None,
             amr: bool = False, plan: dict | None = None, meta: dict | None = None,
             reuse_finished: bool = False) -> Path:
    """Run one case to ``DIR/cases/<case>.h5`` through the driver (:func:`iceresist.driver.run_model`), via a
    partial file renamed at the end, continuing a killed run of it from its checkpoint. ``checkpoint_schedule``:
    when to checkpoint (default every ``CHECKPOINT_WALL_S`` of wall time); ``plan``: the sweep's cases by name
    (default the paper's on B-063); ``meta``: more for the case file's meta (the hull's power inputs);
    ``reuse_finished``: a finished case file there is returned as it is, without running (refused in one line
    where it finished with another scene: :func:`check_same_scene`)."""
    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    t_build = time.perf_counter()
    spec = case_spec(case, plan)
    scene = sweep_scene(spec, fidelity, tier, amr, overrides)
    final = case_path(out_dir, case)
    if reuse_finished and is_finished(final):
        check_same_scene(final, scene.source_text)
        log.info("case %s: finished in %s, read back", case, final)
        return final
    partial = final.with_name(f"{case}.partial.h5")
    chk = checkpoint_path(out_dir, case)
    final.parent.mkdir(parents=True, exist_ok=True)
    earlier = _resumable(partial, chk, scene.source_text)
    if tier == 1:
        model = Tier1Model(scene, backend=backend)
    else:
        model = Tier2Model(scene, backend=backend)
    c = spec.case

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
                       meta={"case": case, "fidelity": fidelity, "tier": tier, **c.meta(), **(meta or {})},
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
              checkpoint_schedule=None, amr: bool = False, plan: dict | None = None,
              about: dict | None = None) -> pd.DataFrame:
    """Run every case not yet finished in ``out_dir`` (an interrupted one continues from its checkpoint) and
    write ``sweep.csv``; returns the table. ``plan``: the sweep's cases by name (a user's matrix,
    :meth:`iceresist.ship.matrix.Matrix.cases`; default the paper's on B-063), ``about``: what ``sweep.json`` and
    every case file record of it beside the preset (the hull, the matrix, the power inputs)."""
    if fidelity not in FIDELITIES:
        raise InputError(f"--preset: unknown preset {fidelity!r}; use one of {', '.join(FIDELITIES)}")
    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    names = resolve_cases(cases, plan)
    job = SweepJob(fidelity, tier, amr, overrides or {}, plan, about or {})
    comm = parallel.world()
    if comm is not None:
        return _run_sweep_ranks(comm, job, out_dir, names, backend=backend, callbacks=callbacks,
                                checkpoint_schedule=checkpoint_schedule)
    out = check_output_dir(out_dir, "--output")
    resolve_target(backend, "--backend")
    out.mkdir(parents=True, exist_ok=True)
    lock = folder_lock(out)
    try:
        return _run_sweep_locked(job, out, names, backend=backend, progress=progress, callbacks=callbacks,
                                 checkpoint_schedule=checkpoint_schedule)
    finally:
        lock.release()


def _run_sweep_ranks(comm, job: "SweepJob", out_dir, names: list, *, backend, callbacks,
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
            finished = _prepare_sweep(job, out, names)
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
            job.run(case, out, backend=backend, progress=False, callbacks=callbacks,
                    checkpoint_schedule=checkpoint_schedule)
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


def _run_sweep_locked(job: "SweepJob", out: Path, names: list, *, backend, progress, callbacks,
                      checkpoint_schedule) -> pd.DataFrame:
    """:func:`run_sweep` inside the folder's lock."""
    fidelity, tier = job.fidelity, job.tier
    finished = _prepare_sweep(job, out, names)
    bar = _cases_bar(names, progress)
    for case in names:
        if bar is not None:
            bar.set_description_str(f"{fidelity} tier {tier}: {case}")
        if case in finished:
            log.info("case %s: finished earlier, skipped", case)
        else:
            job.run(case, out, backend=backend, progress=progress, callbacks=callbacks,
                    checkpoint_schedule=checkpoint_schedule)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return _write_table(out)


def _write_table(out: Path) -> pd.DataFrame:
    table = sweep_table(out)
    table.to_csv(out / TABLE_NAME, index=False, float_format="%.10g")  # the one place sweep.csv is written
    return table


def _prepare_sweep(job: "SweepJob", out: Path, names: list) -> list:
    """Inside the folder's lock, before any case runs: the folder's ``sweep.json`` checked against this sweep and
    rewritten, files of other sweeps set aside, the finished cases' scenes checked; returns the finished cases."""
    info = {"preset": job.fidelity, "tier": job.tier, "cases": names, "overrides": job.overrides,
            **({"amr": True} if job.amr else {}), **job.about}
    info_path = out / "sweep.json"
    if info_path.is_file():
        old = read_sweep_info(info_path)
        if any(old.get(k, {} if k == "overrides" else None) != info.get(k)
               for k in ("preset", "tier", "overrides", "amr", *job.about)):
            raise InputError(f"{out}: holds a sweep with preset {old.get('preset')!r}, tier {old.get('tier')}"
                             f"{_hull_words(old)}: use another --output folder")
        before = [c for c in old.get("cases", []) if isinstance(c, str)]
        info["cases"] = before + [c for c in names if c not in before]
    for case in names:
        keep_foreign_file(case_path(out, case))
    order = job.order(info["cases"])
    finished = [c for c in order if is_finished(case_path(out, c))]  # running one case finishes no other
    for case in finished:  # every case the table would read, before anything runs or is written
        if job.plan is None or case in job.plan:
            check_same_scene(case_path(out, case), job.scene(case).source_text)
    info["cases"] = order
    info_path.write_text(json.dumps(info, indent=1))
    return finished


def _hull_words(info: dict) -> str:
    hull = info.get("hull") or {}
    return f", hull {Path(str(hull.get('mesh'))).name}" if hull.get("mesh") else ""


@dataclass(frozen=True)
class SweepJob:
    """What every case of one sweep shares: preset, tier, refined levels, scene overrides, the cases by name
    (None: the paper's on B-063) and what the sweep records of itself (``about``)."""

    fidelity: str
    tier: int
    amr: bool
    overrides: dict
    plan: dict | None
    about: dict

    def order(self, names) -> list:
        """``names`` in the sweep's order: the plan's, or the paper's matrix."""
        known = list(self.plan) if self.plan is not None else list(CASES)
        names = set(names)
        return [c for c in known if c in names] + sorted(names - set(known))

    def scene(self, case: str):
        return sweep_scene(case_spec(case, self.plan), self.fidelity, self.tier, self.amr, self.overrides)

    def run(self, case: str, out: Path, **kw) -> Path:
        return run_case(case, self.fidelity, self.tier, out, overrides=self.overrides, amr=self.amr, plan=self.plan,
                        meta=self.about.get("case_meta"), **kw)


def _cases_bar(names, progress: bool):
    """A progress bar over the cases of a sweep (on a terminal; each case's own bar runs beneath it)."""
    if not (progress and sys.stderr.isatty()):
        return None
    from tqdm import tqdm

    return tqdm(total=len(names), unit="case", dynamic_ncols=True, file=sys.stderr)


# -- command line ------------------------------------------------------------------------------------------
#: The matrix flags of ``iceresist sweep`` and the matrix axes they set.
MATRIX_FLAGS = {"concentration": "concentration", "knots": "speed_knots", "scale": "scale", "ice_size": "ice_size_m",
                "ice_thickness": "ice_thickness_m", "channel_width": "channel_width_m", "ahead": "ahead"}


def add_sweep_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``iceresist sweep``; sets ``func=cmd_sweep``."""
    p.add_argument("--preset", help=f"fidelity: {' | '.join(FIDELITIES)} (default quick)")
    p.add_argument("--tier", type=int, help="1 = DEM with water models (default), 2 = coupled LBM-DEM")
    p.add_argument("--cases", default="all", help=f"comma-separated case names or 'all' (the paper's: "
                   f"{', '.join(CASES)}; a matrix's: c68-v5kn, ...)")
    p.add_argument("--output", metavar="DIR", help="sweep folder (default runs/sweep-<preset>-t<tier>, "
                   "runs/matrix-<hull>-<preset>-t<tier> for a matrix)")
    p.add_argument("--backend", choices=("auto", "cpu", "cuda"), default="auto")
    p.add_argument("--threads", type=int, help="CPU threads of the DEM kernels (numba)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--amr", action="store_true", help="tier 2 on the preset's refined levels: the hull, the ice and "
                   "the surface on the finest level (docs/SHIP.md)")
    m = p.add_argument_group("your own hull (the tank, channel and window are sized from it; docs/OWN_SHIP.md)")
    m.add_argument("--mesh", metavar="HULL.stl", help="closed hull surface, STL or OBJ, or a built-in mesh (b063); "
                   "alone, it runs the paper's Bow A cases")
    m.add_argument("--mesh-unit", default="m", help="unit of the mesh's coordinates: m, cm, mm, ft, in (default m)")
    m.add_argument("--mesh-bow", default="+x", help="the mesh's axis toward the bow (default +x; write --mesh-bow=-x)")
    m.add_argument("--mesh-up", default="+z", help="the mesh's upward axis (default +z)")
    m.add_argument("--mesh-scale", type=float, metavar="S", help="the scale the mesh is drawn at: 1 full scale, 25 a "
                   "1:25 model (default 1; 25 for b063 and for --mesh alone)")
    m.add_argument("--draught", type=float, metavar="T", help="draught at the mesh's scale (m; default 0.44 for b063)")
    m.add_argument("--propeller-diameter", type=float, metavar="D", help="full-scale propeller diameter (m): the table "
                   "then gives the FSICR required engine output from R_CH and from the simulated resistance")
    m.add_argument("--ice-class", default="IA", help="FSICR class of R_CH and the power: IA Super, IA, IB, IC")
    x = p.add_argument_group("your own test matrix (full-scale values; comma-separated lists are axes; or --matrix)")
    x.add_argument("--matrix", metavar="FILE.toml", help="a matrix file: [hull] and [matrix] (docs/OWN_SHIP.md)")
    x.add_argument("--concentration", metavar="LIST", help="ice concentrations, fractions (default 0.68)")
    x.add_argument("--knots", metavar="LIST", help="full-scale ship speeds (knots; default 5)")
    x.add_argument("--scale", metavar="LIST", help="model scales lambda of 1:lambda (default 25)")
    x.add_argument("--ice-size", metavar="LIST", help="full-scale ice piece edge (m; default 1.025)")
    x.add_argument("--ice-thickness", metavar="LIST", help="full-scale ice thickness (m; default: the edge)")
    x.add_argument("--channel-width", metavar="LIST", help="full-scale channel width (m; default across the tank)")
    x.add_argument("--ahead", metavar="LIST", help="which end goes ahead: bow, stern or bow,stern (default bow)")
    p.set_defaults(func=cmd_sweep)
    return p


def set_threads(n: int | None):
    set_backend_threads(n, "--threads")


def _list(flag: str, text: str | None, kind=float):
    if text is None:
        return None
    try:
        values = [kind(v.strip()) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--{flag.replace('_', '-')}: {text!r} is not a comma-separated list of numbers; e.g. "
                         f"--{flag.replace('_', '-')} 0.5,0.68") from None
    if not values:
        raise InputError(f"--{flag.replace('_', '-')}: empty; give at least one value")
    return values


def hull_spec(args):
    """The ``[hull]`` of the mesh flags (checked: one line naming the flag)."""
    values = {"mesh": args.mesh or "b063", "mesh_unit": args.mesh_unit, "mesh_bow": args.mesh_bow,
              "mesh_up": args.mesh_up, "mesh_scale": args.mesh_scale, "draught_m": args.draught,
              "propeller_diameter_m": args.propeller_diameter, "ice_class": args.ice_class}
    try:
        return HullSpec.model_validate({k: v for k, v in values.items() if v is not None})
    except ValidationError as exc:
        err = exc.errors()[0]
        flag = {"mesh_unit": "--mesh-unit", "mesh_bow": "--mesh-bow", "mesh_up": "--mesh-up",
                "mesh_scale": "--mesh-scale", "draught_m": "--draught", "propeller_diameter_m": "--propeller-diameter",
                "ice_class": "--ice-class"}.get(str(err["loc"][0]), "--mesh")
        if err["type"] == "literal_error":
            raise InputError(f"{flag}: {str(err['input'])[:40]!r} is not one of {err['ctx']['expected']}") from None
        raise InputError(f"{flag}: {err['msg'].removeprefix('Value error, ')} (got {str(err['input'])[:40]!r})") from None


def sweep_plan(args):
    """(preset, tier, plan, about) of the command line: a matrix (``--matrix`` or the matrix flags), the paper's Bow A
    cases on ``--mesh``, or (plan None) the paper's cases on B-063. Every mesh is read and checked here, before
    anything is written."""
    flags = {axis: _list(flag, getattr(args, flag), str if flag == "ahead" else float)
             for flag, axis in MATRIX_FLAGS.items()}
    given = [f"--{f.replace('_', '-')}" for f, a in MATRIX_FLAGS.items() if flags[a] is not None]
    if args.matrix:
        if given or args.mesh:
            raise InputError(f"--matrix: the file gives the hull and the matrix; drop {', '.join(given) or '--mesh'} "
                             f"(or give them all as flags without --matrix)")
        matrix = read_matrix(args.matrix)
        for flag, value in (("--preset", args.preset), ("--tier", args.tier)):
            ours = getattr(matrix.axes, flag[2:])
            if value is not None and value != ours:
                raise InputError(f"{flag}: {value} but the matrix file says {ours}; set it in the file's [matrix]")
        if args.amr and not matrix.axes.amr:
            raise InputError("--amr: set amr = true in the matrix file's [matrix]")
    elif given:
        names = {axis: f"--{flag.replace('_', '-')}" for flag, axis in MATRIX_FLAGS.items()}
        matrix = matrix_from_flags(hull_spec(args), names, preset=args.preset, tier=args.tier, amr=args.amr or None,
                                   **{k: v for k, v in flags.items() if v is not None}, **_paper_defaults(flags))
    else:
        return _mesh_plan(args)
    a = matrix.axes
    plan = matrix.cases()
    about = {**matrix.describe(), "case_meta": {"hull_name": matrix.hull_name, **power_inputs(matrix.hull)}}
    return a.preset, a.tier, a.amr, plan, about, f"runs/matrix-{Path(matrix.hull.mesh).stem}-{a.preset}-t{a.tier}"


def _paper_defaults(flags: dict) -> dict:
    """A matrix of flags with no concentration or no speed: the paper's 68 % and 5 knots."""
    return {k: v for k, v in (("concentration", [0.68]), ("speed_knots", [5.0])) if flags[k] is None}


def power_inputs(hull) -> dict:
    """What the FSICR required engine output needs of the hull (a case file's meta; none without a propeller)."""
    out = {"ice_class": hull.ice_class}
    if hull.propeller_diameter_m is not None:
        out.update(Dp_m=hull.propeller_diameter_m, n_propellers=hull.propellers, propulsion=hull.propulsion)
    return out


def _mesh_plan(args):
    """The paper's Bow A cases on ``--mesh`` (drawn at the preset's 1:25 unless --mesh-scale says otherwise), or the
    paper's cases on B-063 (no --mesh)."""
    preset = args.preset or "quick"
    tier = 1 if args.tier is None else args.tier
    if not args.mesh:
        return preset, tier, args.amr, None, {}, f"runs/sweep-{preset}-t{tier}"
    spec = hull_spec(args)
    cases = args.cases
    if str(cases).strip() == "all":
        cases = ",".join(c for c in CASES if get_case(c).bow == "A")
    bow_b = [c for c in resolve_cases(cases) if get_case(c).bow != "A"]
    if bow_b:
        raise InputError(f"--cases: {', '.join(bow_b)} name Bow B of B-063; with --mesh the mesh is the hull, so run "
                         f"the A cases (e.g. --cases A-c68-v1.0)")
    drawn = spec.mesh_scale if spec.mesh_scale is not None else 25.0  # the preset's model scale
    spec = spec.model_copy(update={"mesh_scale": drawn, "draught_m": spec.draught_m or 0.44 * 25.0 / drawn})
    keys, hull = hull_at(spec, _absolute(spec.mesh), 25.0, keys=MeshKeys(draught="--draught"))
    plan = {c: MatrixCase(get_case(c), keys, hull) for c in resolve_cases(cases)}
    about = {"hull": {**spec.model_dump(), "mesh": keys["mesh_file"]},
             "case_meta": {"hull_name": Path(spec.mesh).stem, **power_inputs(spec)}}
    return preset, tier, args.amr, plan, about, f"runs/sweep-{preset}-t{tier}-{Path(spec.mesh).stem}"


def _absolute(path: str) -> str:
    p = resolve_mesh_path(path)
    return str(Path(p).resolve()) if Path(p).is_file() else p


def cmd_sweep(args) -> int:
    preset, tier, amr, plan, about, default_out = sweep_plan(args)
    if amr and tier != 2:
        raise InputError("--amr: refined levels are a tier-2 tank; add --tier 2")
    if amr:
        amr_overrides(preset)  # refuses a preset without refined levels, naming those with them
    out = args.output or default_out + ("-amr" if amr else "")
    set_threads(args.threads)
    table = run_sweep(preset, tier, out, args.cases, backend=args.backend, progress=not args.no_progress, amr=amr,
                      plan=plan, about=about)
    if table is None:       # an MPI rank other than 0
        return 0
    cols = [c for c in ("case", "mean_force_N", "ci95_N", "R_sim_kN", "R_CH_FSICR_kN", "ratio_sim_FSICR",
                        "P_sim_kW", "P_FSICR_kW", "wall_time_s") if c in table.columns]
    log.info("sweep table %s/sweep.csv:\n%s", out, table[cols].to_string(index=False, float_format="%.4g"))
    return 0
