"""``iceresist sweep``: the paper's ship cases at one fidelity and tier, one HDF5 per case and a sweep table.

Layout of a sweep folder::

    DIR/sweep.json            preset, tier, cases asked for (written first)
    DIR/cases/<case>.h5       one finished run: meta, timeseries (Fx_N, x_bow_m, ...), bodies (ice start/end)
    DIR/sweep.csv             one row per finished case (pandas), rebuilt from the case files

A case is written to ``<case>.partial.h5`` and renamed when it has finished, so a killed sweep leaves no
half-finished result under the final name. A running case also writes its whole state to
``<case>.checkpoint.h5`` every ``CHECKPOINT_WALL_S`` of wall time (deleted when the case finishes). Started
again, the sweep skips every finished case, continues an unfinished one from its checkpoint (when the
partial file holds the same scene; otherwise it runs the case from its start) and rebuilds the table from the
files, so it ends with the table an uninterrupted sweep gives: bit for bit in the tests (tier 1, and the
CI-sized tier 2), statistically for a long tier-2 case (docs/SHIP.md, "Reproducibility"). A finished case whose
scene is not what the preset gives now (the preset has changed since) stops the sweep with a one-line error
before anything runs, so one table never mixes two versions of a preset.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd

from iceresist.errors import InputError
from iceresist.run import DEFAULT_CHECKPOINT_WALL_S
from iceresist.ship.presets import CASES, FIDELITIES, case_scene, get_case
from iceresist.simulation import Checkpointer

log = logging.getLogger(__name__)

#: Scale ratio of the paper (lambda).
SCALE = 25.0
#: Scene overrides of the CI-sized sweep (a 0.3 m channel crossed in 0.75 s): the machinery, not the physics.
TINY_OVERRIDES = {"ice": {"channel_length_m": 0.3}, "run": {"end_time_s": 0.75}, "contact": {"sample_interval_s": 0.002},
                  "ship": {"steady_window_m": [4.1, 4.3], "sphere_band_m": 0.03, "sphere_spacing_m": 0.05}}

#: Wall-clock seconds between the checkpoints of a running case (a tier-2 quick case runs for hours here).
CHECKPOINT_WALL_S = DEFAULT_CHECKPOINT_WALL_S  # the same interval as `iceresist run`

#: Batches used where the window is too short for the automatic choice (the table says so).
FALLBACK_BATCHES = 5

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


def case_path(out_dir, case: str) -> Path:
    return Path(out_dir) / "cases" / f"{case}.h5"


def checkpoint_path(out_dir, case: str) -> Path:
    return Path(out_dir) / "cases" / f"{case}.checkpoint.h5"


def _stored_meta(path: Path) -> dict | None:
    """The meta attributes of a case file, or None when there is no readable one."""
    if not path.is_file():
        return None
    from iceresist.io.hdf5 import RunFile

    try:
        with RunFile(path, "r") as rf:
            return rf.meta
    except (OSError, KeyError):
        return None


def _resumable(partial: Path, checkpoint: Path, scene_text: str) -> dict | None:
    """The meta of ``partial`` when a killed run of the same scene can continue from ``checkpoint``, else None."""
    meta = _stored_meta(partial) if checkpoint.is_file() else None
    return meta if meta is not None and meta.get("scene_toml") == scene_text else None


def is_finished(path: Path) -> bool:
    """A case file under its final name that records a completed run."""
    meta = _stored_meta(path)
    return bool(meta is not None and meta.get("finished", False))


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
        cases = [c for c in cases.split(",") if c]
    names = [get_case(c).name for c in cases]
    return [c for c in CASES if c in names]


def run_case(case: str, fidelity: str, tier: int, out_dir, *, backend: str = "auto", progress: bool = False,
             overrides: dict | None = None, callbacks: dict | None = None, checkpoint_schedule=None) -> Path:
    """Run one case to ``DIR/cases/<case>.h5`` (via a partial file renamed at the end), continuing a killed run
    of it from its checkpoint. ``checkpoint_schedule``: when to checkpoint (default every ``CHECKPOINT_WALL_S``
    of wall time)."""
    from iceresist.io.hdf5 import RunFile
    from iceresist.io.meta import leg_meta, run_meta
    from iceresist.simulation import Callback, IterationInterval, Simulation, TimeSeriesWriter, WallTimeInterval
    from iceresist.tier1 import Tier1Model
    from iceresist.tier2 import Tier2Model

    if tier not in (1, 2):
        raise InputError(f"--tier: must be 1 or 2 (got {tier})")
    t_build = time.perf_counter()
    scene = case_scene(case, fidelity, tier, **(overrides or {}))
    final = case_path(out_dir, case)
    partial = final.with_name(f"{case}.partial.h5")
    chk = checkpoint_path(out_dir, case)
    final.parent.mkdir(parents=True, exist_ok=True)
    earlier = _resumable(partial, chk, scene.source_text)
    if earlier is None and chk.exists():
        chk.unlink()  # the checkpoint of another scene, or of a partial file that is gone
    model = (Tier1Model if tier == 1 else Tier2Model)(scene, backend=backend)
    build_s = time.perf_counter() - t_build
    wall_before_s = float(earlier.get("checkpoint_wall_s", 0.0)) if earlier is not None else 0.0
    desc = model.describe()
    with RunFile(partial, "a" if earlier is not None else "w", write_xdmf=False) as rf:
        if earlier is None:
            rf.write_meta(**run_meta(scene_text=scene.source_text, backend=desc["backend"],
                                     precision=model.precision, cells=model.cells),
                          scene_name=scene.scene.name, case=case, fidelity=fidelity, tier=tier,
                          bow=get_case(case).bow, concentration_nominal=get_case(case).concentration,
                          knots=get_case(case).knots, model=desc, finished=False)
            g = rf.h5.require_group("bodies")
            g["initial_positions_m"] = model.ice_state()["positions_m"]
            g["hull_vertices_m"] = model.geometry.vertices()
        else:
            g = rf.h5["bodies"]
        legs = leg_meta(earlier, int(earlier.get("checkpoint_iteration", 0)) if earlier else 0, desc["backend"])
        rf.write_meta(**legs)
        sim = Simulation(model, stop_time_s=scene.run.end_time_s, progress=progress)
        sim.output_writers["timeseries"] = TimeSeriesWriter(rf, IterationInterval(1))
        sim.output_writers["checkpointer"] = Checkpointer(
            chk, checkpoint_schedule or WallTimeInterval(CHECKPOINT_WALL_S), write_final=False, runfile=rf,
            wall_before_s=wall_before_s, t0=t_build)
        from iceresist import watchdog

        dog = watchdog.install(sim, runfile=rf, json_path=partial.with_suffix(".watchdog.json"))
        for name, (func, every) in (callbacks or {}).items():
            sim.callbacks[name] = Callback(func, IterationInterval(every))
        log.info("case %s (%s, tier %d): %d cubes, %d spheres, %.3g s simulated", case, fidelity, tier,
                 model.layout.count, model.dem.n_spheres, scene.run.end_time_s)
        if earlier is not None:
            log.info("case %s: continuing from its checkpoint at record %d (leg %d)", case,
                     int(earlier.get("checkpoint_iteration", -1)), legs["legs"])
        sim.run(pickup=chk if earlier is not None else False)
        if dog.report is not None:
            raise InputError(f"case {case}: stopped by the watchdog: {dog.report.message} "
                             f"(diagnostic in {partial.with_suffix('.watchdog.json').name})")
        if sim.diverged:
            raise InputError(f"case {case}: the DEM run diverged ({sim.stop_reason}); lower contact.dem_safety")
        if not sim.completed:  # a callback stopped it before its end: the partial file and checkpoint stay
            raise InputError(f"case {case}: stopped before its end time ({sim.stop_reason}); run the sweep again "
                             f"to continue it from its checkpoint")
        st = model.ice_state()
        g["final_positions_m"] = st["positions_m"]
        g["final_quaternions"] = st["quaternions"]
        rf.write_meta(finished=True, iteration=model.iteration, time_s=model.time_s, steps=int(model.iteration),
                      dem_substeps=int(model.dem.substeps_taken),
                      wall_time_s=wall_before_s + sim.wall_time_s + build_s,
                      build_time_s=build_s, step_time_s=sim.step_time_s,
                      lbm_steps=int(getattr(model, "lbm_steps", 0)), mlups=sim.mlups,
                      final_x_bow_m=model.x_bow_m, stop_reason=sim.stop_reason,
                      finished_utc=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
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
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    info = {"preset": fidelity, "tier": tier, "cases": names, "overrides": overrides or {}}
    info_path = out / "sweep.json"
    if info_path.is_file():
        old = json.loads(info_path.read_text())
        if (old.get("preset"), old.get("tier"), old.get("overrides", {})) != (fidelity, tier, overrides or {}):
            raise InputError(f"{out}: holds a sweep with preset {old.get('preset')!r}, tier {old.get('tier')}: "
                             f"use another --output folder")
        info["cases"] = [c for c in CASES if c in set(old.get("cases", [])) | set(names)]
    finished = [c for c in CASES if is_finished(case_path(out, c))]  # running one case finishes no other
    for case in finished:  # every case the table would read, before anything runs or is written
        check_same_scene(case_path(out, case), case_scene(case, fidelity, tier, **(overrides or {})).source_text)
    info_path.write_text(json.dumps(info, indent=1))
    for case in names:
        if case in finished:
            log.info("case %s: finished earlier, skipped", case)
            continue
        run_case(case, fidelity, tier, out, backend=backend, progress=progress, overrides=overrides,
                 callbacks=callbacks, checkpoint_schedule=checkpoint_schedule)
    table = sweep_table(out)
    return table


# -- post-processing of the case files ----------------------------------------------------------------------
def _fsicr_r_ch_kN() -> dict:
    """FSICR R_CH (kN) of the paper's table-1 ships (fsicr/ships), class IA."""
    from importlib import resources

    import fsicr

    out = {}
    for bow in "AB":
        ship = fsicr.load_ship(str(resources.files("fsicr") / "ships" / f"b063_bow_{bow.lower()}.toml"))[0]
        out[bow] = fsicr.r_ch(ship, "IA").r_ch_N / 1e3
    return out


def ice_free_width_m(positions, x_range, centre_y_m, cube_m, channel_width_m, slice_m=0.1,
                     level_quantile=0.9) -> float:
    """Median over x-slices of the width of the lane around the centreline free of floating ice (m).

    A cube floats when its centre lies less than one cube edge below the top of the slice's ice, read as the
    ``level_quantile`` of the slice's cube centres. The ice's own level, not the still water level: in tier 2
    the water beside and behind the hull is drawn down, and the cubes float centimetres below the still level.
    """
    p = np.asarray(positions, dtype=float)
    widths = []
    x0, x1 = x_range
    if not x1 > x0:
        return float("nan")
    slice_m = min(slice_m, x1 - x0)
    half_w = channel_width_m / 2
    for a in np.arange(x0, x1 - 1e-9, slice_m):
        in_slice = p[(p[:, 0] >= a) & (p[:, 0] < a + slice_m)]
        if in_slice.size:
            top_m = np.quantile(in_slice[:, 2], level_quantile)
            in_slice = in_slice[in_slice[:, 2] > top_m - cube_m]
        y = in_slice[:, 1] - centre_y_m
        port = y[y > 0] - cube_m / 2
        stbd = -y[y <= 0] - cube_m / 2
        w = (port.min() if port.size else half_w) + (stbd.min() if stbd.size else half_w)
        widths.append(max(0.0, w))
    return float(np.median(widths)) if widths else float("nan")


def floes_under_hull(positions, waterline_xy, x_bow_m, centre_y_m, level_m, cube_m) -> int:
    """Cubes below the surface (top under water) within the hull's waterline outline."""
    from matplotlib.path import Path as MplPath

    p = np.asarray(positions, dtype=float)
    outline = np.asarray(waterline_xy) + np.array([x_bow_m, centre_y_m])
    inside = MplPath(outline).contains_points(p[:, :2])
    submerged = p[:, 2] + cube_m / 2 < level_m
    return int((inside & submerged).sum())


def analyse_case(path) -> dict:
    """One table row from a finished case file (see :func:`sweep_table` for the columns)."""
    from iceresist.io.hdf5 import RunFile
    from iceresist.post import force_to_full_scale, ice_resistance_from_timeseries, window_halves

    with RunFile(path, "r") as rf:
        meta = rf.meta
        model = rf.meta_object("model")
        ts = rf.timeseries()
        bodies = {k: rf.h5["bodies"][k][...] for k in rf.h5["bodies"].keys()}
    t, fx, x = ts["time_s"][1:], ts["Fx_N"][1:], ts["x_bow_m"][1:]  # row 0 is the state before the first step
    window = tuple(model["steady_window_m"])
    try:
        sm = ice_resistance_from_timeseries(t, fx, x, window_m=window, motion_direction=+1)
        ci_note = "batch means"
    except InputError as exc:  # a window shorter than 10 batches of 5 tau_int: fewer batches, said in the table
        log.warning("%s: %s; using %d batches", meta["case"], exc, FALLBACK_BATCHES)
        sm = ice_resistance_from_timeseries(t, fx, x, window_m=window, motion_direction=+1,
                                            n_batches=FALLBACK_BATCHES)
        ci_note = f"{FALLBACK_BATCHES} batches (window short against tau_int)"
    try:  # is the window steady? (the halves of a short window may hold too few samples)
        halves = window_halves(t, fx, x, window_m=window, motion_direction=+1)
        half_ratio, steady = halves.ratio, halves.steady
    except InputError as exc:
        log.warning("%s: no steadiness check of the window: %s", meta["case"], exc)
        half_ratio, steady = float("nan"), None
    geom = hull_of_model(model)
    x_bow = float(meta["final_x_bow_m"])
    x_lo = model["channel_start_x_m"]
    x_hi = x_bow - geom.end_length_m
    final = bodies["final_positions_m"]
    r_ch = _fsicr_r_ch_kN()[meta["bow"]]
    R_kN = float(force_to_full_scale(sm.mean_N, SCALE)) / 1e3
    return {
        "case": meta["case"], "bow": meta["bow"], "concentration": float(model["concentration"]),
        "knots": float(meta["knots"]), "speed_m_s": float(model["speed_m_s"]), "tier": int(meta["tier"]),
        "fidelity": meta["fidelity"], "cubes": int(model["ice_cubes"]),
        "mean_force_N": sm.mean_N, "ci95_N": sm.ci_half_width_N, "std_N": sm.std_N,
        "window_x0_m": model["steady_window_m"][0], "window_x1_m": model["steady_window_m"][1],
        "window_samples": sm.n_samples, "tau_int_s": sm.tau_int_s, "ci_method": ci_note,
        # second-half over first-half mean of the window, and whether they agree (iceresist.post.window_halves)
        "half_ratio": half_ratio, "window_steady": steady,
        "R_sim_kN": R_kN, "R_sim_ci95_kN": float(force_to_full_scale(sm.ci_half_width_N, SCALE)) / 1e3,
        "R_CH_FSICR_kN": r_ch, "ratio_sim_FSICR": R_kN / r_ch,
        "ice_free_width_m": ice_free_width_m(final, (x_lo, x_hi), model["centre_y_m"], model["cube_m"],
                                             model["channel_width_m"]),
        "floes_under_hull": floes_under_hull(final, geom.waterline_polygon(), x_bow, model["centre_y_m"],
                                             model["water_level_m"], model["cube_m"]),
        "resolution_m": float(model["resolution_m"]), "cells": int(model["cells"]),
        "spheres": int(model["spheres"]), "steps": int(meta["steps"]), "dem_substeps": int(meta["dem_substeps"]),
        "simulated_s": float(meta["time_s"]), "wall_time_s": float(meta["wall_time_s"]),
        "backend": model["backend"], "file": f"cases/{Path(path).name}",
        # tier 2: the ship's depth Froude number over Schijf's limit of the tank (iceresist.ship.tank)
        "tank_froude_fraction": float(model.get("tank", {}).get("fraction_of_limit", float("nan"))),
        "start_wave_fraction": start_wave_fraction(model, geom),
    }


def hull_of_model(model: dict):
    """The :class:`~iceresist.ship.hull.HullGeometry` of a case file's model description."""
    from iceresist.ship.hull import HullGeometry

    h = model["hull"]
    return HullGeometry(length_overall_m=h["length_overall_m"], beam_m=h["beam_m"], draught_m=h["draught_m"],
                        parallel_length_m=h["parallel_length_m"], waterline_angle_deg=h["waterline_angle_deg"],
                        bow_rake_deg=h["bow_rake_deg"], stern_rake_deg=h["stern_rake_deg"])


def case_start_wave(model: dict, geom) -> tuple | None:
    """Tier 2: (:class:`~iceresist.ship.tank.StartWave`, steady window in s after the start) from a case file's
    model description, the tank's width from its blockage, so files written before the start wave was
    described read the same; None for tier 1 (no tank flow) or a ship at rest."""
    from iceresist.ship.tank import start_wave

    tank = model.get("tank")
    speed = float(model["speed_m_s"])
    if not tank or speed <= 0:
        return None
    depth = float(model["water_level_m"])
    width = geom.midship_area_m2 / (float(tank["blockage"]) * depth)
    wave = start_wave(geom.midship_area_m2, width, depth, speed, geom.prismatic_length_m)
    x0 = float(model["start_x_m"])
    return wave, tuple((x - x0) / speed for x in model["steady_window_m"])


def start_wave_fraction(model: dict, geom) -> float:
    """Tier 2: the part of the steady window before the stern's start wave reaches the bow
    (:func:`iceresist.ship.tank.start_wave`, :func:`case_start_wave`); NaN for tier 1."""
    sw = case_start_wave(model, geom)
    return float("nan") if sw is None else sw[0].window_fraction(*sw[1])


def sweep_table(out_dir) -> pd.DataFrame:
    """The table of every finished case in ``out_dir`` (matrix order), also written to ``sweep.csv``."""
    out = Path(out_dir)
    rows = [analyse_case(case_path(out, c)) for c in CASES if is_finished(case_path(out, c))]
    table = pd.DataFrame(rows)
    table.to_csv(out / "sweep.csv", index=False, float_format="%.10g")
    return table


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
    p.set_defaults(func=cmd_sweep)
    return p


def set_threads(n: int | None):
    from iceresist.backends.jit import set_threads as set_backend_threads

    set_backend_threads(n, "--threads")


def cmd_sweep(args) -> int:
    out = args.output or f"runs/sweep-{args.preset}-t{args.tier}"
    set_threads(args.threads)
    table = run_sweep(args.preset, args.tier, out, args.cases, backend=args.backend,
                      progress=not args.no_progress)
    cols = ["case", "mean_force_N", "ci95_N", "R_sim_kN", "R_CH_FSICR_kN", "ratio_sim_FSICR", "wall_time_s"]
    log.info("sweep table %s/sweep.csv:\n%s", out, table[cols].to_string(index=False, float_format="%.4g"))
    return 0


def demo(out_dir="runs/demo", *, json_output: bool = False, backend: str = "auto", progress: bool = True,
         cases=None, overrides: dict | None = None) -> int:
    """``iceresist demo``: the FSICR comparison of the paper's table 2, the quick tier-1 sweep of every case
    and its report (about 7 minutes on a 2-core x86 VM). ``cases`` and ``overrides`` shrink it (tests).

    With ``json_output`` one JSON object is printed: ``{"fsicr": ..., "sweep": [...], "report": {...}}``.
    """
    import json

    from fsicr.cli import main as fsicr_main
    from fsicr.compare import compare_table2
    from reports.report import write_report

    rc = 0 if json_output else fsicr_main(["compare"])
    table = run_sweep("quick", 1, out_dir, cases, backend=backend, progress=progress and not json_output,
                      overrides=overrides)
    html, pdf = write_report(out_dir)
    cols = ["case", "mean_force_N", "R_sim_kN", "R_CH_FSICR_kN", "ratio_sim_FSICR"]
    if json_output:
        print(json.dumps({"command": "demo", "fsicr": compare_table2(),
                          "sweep": json.loads(table[cols].to_json(orient="records")),
                          "report": {"html": str(html), "pdf": str(pdf)}}))
    else:
        print("\nQuick tier-1 sweep (DEM with water models), model scale -> full scale by the cubic law")
        print(table[cols].to_string(index=False, float_format="%.4g"))
        print(f"report: {html}\n        {pdf}")
    return rc
