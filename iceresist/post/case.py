"""Analysis of one case file of a sweep (``DIR/cases/<case>.h5``): the steady-window mean with its batch-means
interval, full scale by the cubic law, FSICR R_CH beside it, the ice-free width of the channel, the floes under
the hull and, for tier 2, the tank's start wave.

Reads the files the engine wrote (:class:`iceresist.io.hdf5.RunFile`); never runs a simulation and never writes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import fsicr
from fsicr import formulas
from fsicr.hullmesh import HOW
from fsicr.ship import DESCRIPTIONS
from iceresist.errors import InputError
from iceresist.io.hdf5 import RunFile
from iceresist.post.resistance import ice_resistance_from_timeseries, resistance_from_contact_force, window_halves
from iceresist.post.scaling import PAPER_SCALE, force_to_full_scale
from iceresist.post.statistics import MIN_BATCH_LENGTH_TAU, pooled_batch_means
from iceresist.post.window import select_window
from iceresist.ship.hull import HullGeometry
from iceresist.ship.icefield import floe_corners
from iceresist.ship.meshhull import HullRecord
from iceresist.ship.tank import start_wave

#: Scale ratio of the paper (lambda).
SCALE = PAPER_SCALE

#: Batches used where the window is too short for the automatic choice (the table says so).
FALLBACK_BATCHES = 5


def load_case(path) -> dict:
    """``{"meta", "ts", "bodies", "model"}`` of one case file: meta attributes, time series, ice start and end
    positions, and the model description."""
    with RunFile(path, "r") as rf:
        meta = rf.meta
        model = rf.meta_object("model")
        ts = rf.timeseries()
        bodies = {k: rf.h5["bodies"][k][...] for k in rf.h5["bodies"].keys()}
    return {"meta": meta, "ts": ts, "bodies": bodies, "model": model}


def mesh_r_ch_kN(hull, scale: float = SCALE, ice_class: str = "IA") -> float:
    """FSICR R_CH (kN) of a mesh hull at full scale (1:``scale``), from the inputs measured on it."""
    return fsicr.r_ch(fsicr.Ship(name="mesh hull", **hull.fsicr_inputs(scale)), ice_class).r_ch_N / 1e3


def engine_power_kW(resistance_kN: float, meta: dict) -> float:
    """FSICR required engine output (kW) for a full-scale ice resistance, P = Ke (R/1000)^1.5 / Dp (FSICR 3.2.2;
    R in N), with the propeller of the case's meta; NaN without one (no class minimum: this is the output that
    resistance needs)."""
    if "Dp_m" not in meta:
        return float("nan")
    ke = formulas.ke(int(meta["n_propellers"]), str(meta["propulsion"]))
    return float(formulas.engine_power(max(resistance_kN, 0.0) * 1e3, ke, float(meta["Dp_m"])))


def fsicr_r_ch_kN() -> dict:
    """FSICR R_CH (kN) of the paper's table-1 ships (fsicr/ships), class IA."""
    from importlib import resources

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
    """One table row from a finished case file (see :func:`iceresist.post.sweeptable.sweep_table` for the
    columns). What limits the row's interval or its steadiness check is said in its ``note`` column (empty when
    nothing does), not logged."""
    case = load_case(path)
    meta, model, ts, bodies = case["meta"], case["model"], case["ts"], case["bodies"]
    t, fx, x = ts["time_s"][1:], ts["Fx_N"][1:], ts["x_bow_m"][1:]  # row 0 is the state before the first step
    window = tuple(model["steady_window_m"])
    notes = []
    sm, short = window_mean(t, fx, x, window)
    ci_note = "batch means"
    if short is not None:  # a window shorter than 10 batches of 5 tau_int: fewer batches, said in the table
        ci_note = f"{FALLBACK_BATCHES} batches (window short against tau_int)"
        notes.append(f"{short}; using {FALLBACK_BATCHES} batches")
    if sm.interval_too_narrow:
        notes.append(f"batches of {sm.batch_length} samples are shorter than {MIN_BATCH_LENGTH_TAU:.0f} tau_int = "
                     f"{MIN_BATCH_LENGTH_TAU * sm.tau_int_samples:.3g} samples; the interval is likely too narrow")
    try:  # is the window steady? (the halves of a short window may hold too few samples)
        halves = window_halves(t, fx, x, window_m=window, motion_direction=+1)
        half_ratio, steady = halves.ratio, halves.steady
    except InputError as exc:
        notes.append(f"no steadiness check of the window: {exc}")
        half_ratio, steady = float("nan"), None
    geom = hull_of_model(model)
    x_bow = float(meta["final_x_bow_m"])
    x_lo = model["channel_start_x_m"]
    x_hi = x_bow - geom.end_length_m
    final = bodies["final_positions_m"]
    scale = float(meta.get("scale", SCALE))
    ice_class = str(meta.get("ice_class", "IA"))
    if model["hull"].get("kind") != "mesh":
        r_ch = fsicr_r_ch_kN()[meta["bow"]]
    else:
        r_ch = mesh_r_ch_kN(geom, scale, ice_class)
    R_kN = float(force_to_full_scale(sm.mean_N, scale)) / 1e3
    return {
        "case": meta["case"], "hull": str(meta.get("hull_name", "B-063")), "bow": meta["bow"],
        "concentration": float(model["concentration"]),
        "concentration_nominal": float(meta.get("concentration_nominal", model["concentration"])),
        "knots": float(meta["knots"]), "speed_m_s": float(model["speed_m_s"]), "tier": int(meta["tier"]),
        "scale": scale, "full_scale_knots": float(meta.get("full_scale_knots", float(meta["knots"]) * scale ** 0.5)),
        "fidelity": meta["fidelity"], "cubes": int(model["ice_cubes"]),
        "mean_force_N": sm.mean_N, "ci95_N": sm.ci_half_width_N, "std_N": sm.std_N,
        "window_x0_m": model["steady_window_m"][0], "window_x1_m": model["steady_window_m"][1],
        "window_samples": sm.n_samples, "tau_int_s": sm.tau_int_s, "ci_method": ci_note, "n_batches": int(sm.n_batches),
        # second-half over first-half mean of the window, and whether they agree (iceresist.post.window_halves)
        "half_ratio": half_ratio, "window_steady": steady,
        "R_sim_kN": R_kN, "R_sim_ci95_kN": float(force_to_full_scale(sm.ci_half_width_N, scale)) / 1e3,
        "R_CH_FSICR_kN": r_ch, "ratio_sim_FSICR": R_kN / r_ch, "ice_class": ice_class,
        "P_sim_kW": engine_power_kW(R_kN, meta), "P_FSICR_kW": engine_power_kW(r_ch, meta),
        "ice_free_width_m": ice_free_width_m(final, (x_lo, x_hi), model["centre_y_m"], model["cube_m"],
                                             model["channel_width_m"]),
        "floes_under_hull": floes_under_hull(final, geom.waterline_polygon(), x_bow, model["centre_y_m"],
                                             model["water_level_m"], model["cube_m"]),
        "resolution_m": float(model["resolution_m"]), "cells": int(model["cells"]),
        # tier 2: the ice's edge over the finest cell, and the refinement levels above level 0 (0: a uniform grid)
        "cells_per_cube": float(model.get("cells_per_cube", float("nan"))), "levels": int(model.get("levels", 0)),
        # whether a resolution ladder of the case says its mean force is grid-converged (tier 2; tier 1 has no grid)
        "converged": "no ladder run" if int(meta["tier"]) == 2 else "",
        "spheres": int(model["spheres"]), "steps": int(meta["steps"]), "dem_substeps": int(meta["dem_substeps"]),
        "simulated_s": float(meta["time_s"]), "wall_time_s": float(meta["wall_time_s"]),
        "backend": model["backend"], "file": f"cases/{Path(path).name}",
        # tier 2: the ship's depth Froude number over Schijf's limit of the tank (iceresist.ship.tank)
        "tank_froude_fraction": float(model.get("tank", {}).get("fraction_of_limit", float("nan"))),
        "start_wave_fraction": start_wave_fraction(model, geom),
        "note": "; ".join(notes),
    }


def analyse_ensemble(paths) -> dict:
    """One case run from independent ice arrangements (finished case files of the same scene but the ice's seed):
    :func:`analyse_case` of each (``runs``) and the mean ice force over the steady windows of all of them with
    the interval of their pooled batch means (:func:`iceresist.post.statistics.pooled_batch_means`: each window
    cut into batches of at least five of its correlation times, the batches of every run pooled): ``mean_force_N``,
    ``ci95_N``, ``n_batches``, ``run_means_N`` (each run's mean over its batches), ``tau_int_s`` (the runs'
    mean), ``window_samples`` (all runs'), ``ci_method``."""
    rows, windows, taus = [], [], []
    for path in paths:
        row = analyse_case(path)        # its tau_int is that of the same window (steady_mean)
        case = load_case(path)
        ts, model = case["ts"], case["model"]
        t, fx, x = ts["time_s"][1:], ts["Fx_N"][1:], ts["x_bow_m"][1:]
        w = select_window(t, resistance_from_contact_force(fx, +1), window_m=tuple(model["steady_window_m"]),
                          x_ship_m=x, signal_name="Fx_N")
        rows.append(row)
        windows.append(w.values)
        taus.append(row["tau_int_s"] / w.dt_s)
    pm = pooled_batch_means(windows, taus)
    how = (f"pooled batch means of {len(rows)} ice arrangements ({pm.n_batches} batches of >= "
           f"{MIN_BATCH_LENGTH_TAU:.0f} tau_int)")
    if pm.too_few_batches:
        how += "; fewer than 10 batches: the interval's own spread is poorly known"
    return {"mean_force_N": pm.mean, "ci95_N": pm.ci_half_width, "n_batches": pm.n_batches,
            "run_means_N": list(pm.record_means), "batches_per_run": list(pm.batches),
            "tau_int_s": float(np.mean([r["tau_int_s"] for r in rows])),
            "window_samples": int(sum(len(w) for w in windows)), "ci_method": how, "runs": rows}


def window_mean(t_s, Fx_N, x_bow_m, window_m) -> tuple:
    """The steady-window mean of a ship's record (:func:`~iceresist.post.resistance.ice_resistance_from_timeseries`)
    and None, or, where the window is shorter than the automatic batches need, the mean over
    :data:`FALLBACK_BATCHES` batches and why. A window the record cannot average raises InputError."""
    try:
        return ice_resistance_from_timeseries(t_s, Fx_N, x_bow_m, window_m=window_m, motion_direction=+1), None
    except InputError as exc:
        return ice_resistance_from_timeseries(t_s, Fx_N, x_bow_m, window_m=window_m, motion_direction=+1,
                                              n_batches=FALLBACK_BATCHES, warn_short_batches=False), str(exc)


def window_summary(path) -> str | None:
    """One sentence on a ship run's result file: its mean ice resistance over the steady window with the 95 %
    interval (model scale, and full scale at the run's scale), or why there is none; None for a scene without a ship."""
    with RunFile(path, "r") as rf:
        model, meta, ts = rf.meta_object("model"), rf.meta, rf.timeseries()
    if not isinstance(model, dict) or "steady_window_m" not in model or "Fx_N" not in ts:
        return None
    x0, x1 = (float(v) for v in model["steady_window_m"])
    t, fx, x = ts["time_s"][1:], ts["Fx_N"][1:], ts["x_bow_m"][1:]
    if not len(x):  # nothing stepped (--steps 0): nothing to say
        return None
    if float(x[-1]) < x1 - 1e-6:
        return (f"no mean ice resistance: the stem reached x = {float(x[-1]):.3f} m, "
                f"short of the steady window's end at {x1:.3f} m (run to the end, or --pickup)")
    try:
        sm, short = window_mean(t, fx, x, (x0, x1))
    except InputError as exc:  # a window the record cannot average (outside the track, too few samples)
        return f"no mean ice resistance: {exc}"
    how = "" if short is None else f", {FALLBACK_BATCHES} batches: the window is short against the force's " \
                                   f"correlation time"
    scale = float(meta.get("scale", SCALE))
    return (f"mean ice resistance over the steady window (stem x = {x0:.3f} to {x1:.3f} m): {sm.mean_N:.3g} +- "
            f"{sm.ci_half_width_N:.2g} N at model scale, {sm.mean_N * scale ** 3 / 1e3:.3g} kN at 1:{scale:g} "
            f"(95 % interval{how})")


def hull_of_model(model: dict):
    """The :class:`~iceresist.ship.hull.HullGeometry` of a case file's model description, or for a mesh hull its
    :class:`~iceresist.ship.meshhull.HullRecord`."""
    h = model["hull"]
    if h.get("kind") == "mesh":
        return HullRecord(h)
    return HullGeometry(length_overall_m=h["length_overall_m"], beam_m=h["beam_m"], draught_m=h["draught_m"],
                        parallel_length_m=h["parallel_length_m"], waterline_angle_deg=h["waterline_angle_deg"],
                        bow_rake_deg=h["bow_rake_deg"], stern_rake_deg=h["stern_rake_deg"])


def case_start_wave(model: dict, geom) -> tuple | None:
    """Tier 2: (:class:`~iceresist.ship.tank.StartWave`, steady window in s after the start) from a case file's
    model description, the tank's width from its blockage, so files written before the start wave was
    described read the same; None for tier 1 (no tank flow) or a ship at rest."""
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


def floe_outlines(model: dict, bodies: dict, positions: np.ndarray, quaternions=None):
    """Plan outlines (n, 4, 2) of the floes at ``positions``, turned by the quaternions' yaw (or the recorded start
    yaw), and their thicknesses (n,): each floe's own size where the file records it, else the cube edge."""
    n = len(positions)
    size = np.asarray(bodies.get("floe_sizes_m", np.full(n, model["cube_m"])), dtype=float)
    thick = np.asarray(bodies.get("floe_thickness_m", np.full(n, model["cube_m"])), dtype=float)
    if quaternions is not None:
        w, x, y, z = np.asarray(quaternions, dtype=float).T
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    else:
        yaw = np.asarray(bodies.get("floe_yaw_rad", np.zeros(n)), dtype=float)
    return floe_corners(np.asarray(positions, dtype=float)[:, :2], size, yaw), thick


def mesh_hull_inputs(hull: dict, scale: float) -> list[dict] | None:
    """Rows (input, full scale, how it is measured) of the FSICR inputs measured on a mesh hull, from a case
    file's hull description; None for the parametric hull."""
    if hull.get("kind") != "mesh":
        return None
    return [{"input": DESCRIPTIONS[k], "full scale": f"{v:.4g}", "measured as": HOW.get(k, "the draught x scale")}
            for k, v in HullRecord(hull).fsicr_inputs(scale).items()]
