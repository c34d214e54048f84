"""Cost of a tier-2 ship case (coupled LBM-DEM) at a chosen resolution, and the projected time to finish it:
``python -m validation.bench ship --preset paper --backend cuda --fit-gib 70 --records 3``.

The case's tank (``iceresist.scene.case_scenes.TIER2``) is kept in metres and cut into ``--across N`` cells over its
width (dx = width / N; every cell count rounded up to a multiple of the 8-cell block). ``--fit-gib G`` first
builds the case at ``--probe-across`` cells, reads what its arrays hold (the model's ``allocation``: LBM
populations, phase field and coupling per cell, the DEM fixed) and picks the finest N, a multiple of 8, whose
arrays fill at most G GiB: the finest uniform grid that fits a device of that memory.

Each measured row: cells and shape, dx, the build time (kernel compilation included), one record of warm-up,
then ``--records`` records timed (``model.step``: LBM steps, coupling and DEM, no output and no watchdog),
seconds per record, MLUPS, the records the case needs (its ``run.end_time_s`` over the record interval) and
the projected hours to finish it at the measured rate. ``--records 0`` prints the ``--fit-gib`` row alone
(a machine without the memory can say what a device with it would hold). The preset's precision (float32) is used; the common
``--precision`` flag is ignored.

``--amr``: the preset's tank on refined levels (``[tier2.<preset>.amr]`` of ``iceresist/ship/cases.toml``). A first
row counts its levels without building them (:meth:`~iceresist.models.tier2.Tier2Model.plan`): leaf
and ghost cells per level, cells per cube at the finest, against the paper's 160 M start, the arrays' GiB (and
whether they fit each ``--fit-gib``), the case's cell updates and, at ``--rate-mlups R``, its hours at R MLUPS;
then ``--records`` builds and times it as above: ``python -m validation.bench ship --preset paper --amr --records 0
--fit-gib 70 --rate-mlups 514`` (2 min on a 2-core x86 VM, 5 GB). A regridding case adds the regrids that fell in the
timed records (how many rebuilt the levels, their seconds, how many waited: ``refinement.regrid_slack``), the
seconds per record and projected hours of the stepping alone (``s_per_record_stepping``, ``projected_h_stepping``)
and ``rebuild_s``, the cost of one regrid that changes the blocks (the levels rebuilt, timed onto the blocks they
have). Every row on levels has ``fine_equivalent_mlups``, the cell updates of the uniform finest grid over the tank
in the stepping's time (the rate the paper's mesh would need without AMR); ``--by-label`` adds one more record timed
launcher by launcher, a row per label and ``level_exchange_share`` (transfers, block copies and the ghost refill).

``--compare-pure`` (what the coupling costs; target: the coupled step at most 3x the pure one): in the same process,
the coupled LBM step of the case timed part by part (every kernel launch under its label,
:func:`iceresist.backends.launch.profiling`; what is left is host NumPy and Python between launches), then the
pure fused cumulant LBM step (:class:`~iceresist.lbm.solver.LBMSolver`, no free surface, no bodies) on a box of
the same cells, and the ratio of the two: ``python -m validation.bench ship --preset quick --compare-pure``. Then
the launches of one coupled step with the host's time to issue them, and a whole record with its diagnostics.
"""

from __future__ import annotations

import math
import time

GIB = 1024 ** 3


def add_arguments(parser):
    parser.add_argument("--preset", default="paper", help="fidelity: paper | quick (default paper)")
    parser.add_argument("--case", default="A-c68-v1.0", help="case name (default A-c68-v1.0)")
    parser.add_argument("--across", type=int, action="append",
                        help="cells across the tank's width (repeatable; default: the preset's)")
    parser.add_argument("--fit-gib", type=float, action="append",
                        help="also run the finest grid whose arrays fit this many GiB (repeatable)")
    parser.add_argument("--probe-across", type=int, default=64,
                        help="cells across of the build that measures the bytes per cell for --fit-gib")
    parser.add_argument("--records", type=int, default=3,
                        help="timed records after one of warm-up (0: only the --fit-gib row, nothing timed)")
    parser.add_argument("--compare-pure", action="store_true",
                        help="time the coupled step part by part beside the pure fused LBM step on as many cells")
    parser.add_argument("--by-label", action="store_true",
                        help="with --compare-pure: one row per launcher label, not the parts of docs/PERFORMANCE.md; "
                             "with --amr: one more record timed by launcher label (and the level exchange's share)")
    parser.add_argument("--amr", action="store_true",
                        help="the preset's tank on refined levels (its [tier2.<preset>.amr]): its cells per level "
                             "counted without building it, then (--records) the measured rate and the projected "
                             "time of the case")
    parser.add_argument("--rate-mlups", type=float,
                        help="with --amr: also project the case's time at this rate of cell updates (MLUPS)")


def scaled_scene(case: str, preset: str, across: int, **overrides):
    """The tier-2 scene of ``case`` at ``preset`` with the tank cut into ``across`` cells over its width."""
    from iceresist.errors import InputError
    from iceresist.scene.case_scenes import TIER2, case_scene

    if across < 8 or across % 8:
        raise InputError(f"--across: a positive multiple of 8 cells (got {across})")
    t2 = TIER2[preset]
    width_m = t2["cells"][1] * t2["dx_m"]
    dx = width_m / across
    cells = [max(8, int(math.ceil(n * t2["dx_m"] / dx / 8 - 1e-9)) * 8) for n in t2["cells"]]
    cells[1] = across
    domain = {**overrides.pop("domain", {}), "cells": cells, "dx_m": dx}
    return case_scene(case, preset, 2, domain=domain, **overrides)


def bytes_per_cell(allocation: dict, cells: int) -> tuple[float, int]:
    """(bytes per cell, fixed bytes) of a tier-2 model's ``allocation()``: the LBM, phase field and coupling
    scale with the cells, the DEM does not."""
    per = (allocation["lbm"] + allocation["phase_field"] + allocation["coupling"]) / cells
    return per, int(allocation["dem"])


def finest_fit(per_cell: float, fixed: int, budget_bytes: float, cells_of) -> int:
    """The largest ``across`` (a multiple of 8) with ``per_cell * cells_of(across) + fixed <= budget_bytes``;
    0 when not even 8 fits. ``cells_of(n)``: the cells of the grid n cells across (grows with n)."""
    n = 0
    while per_cell * cells_of(n + 8) + fixed <= budget_bytes:
        n += 8
    return n


#: The launcher labels of the exchange between levels: the transfers at the interfaces, the copies of blocks between
#: a level's buffers and the refill of the finest level's ghost blocks for the phase field.
LEVEL_EXCHANGE = ("level_transfer", "copy_blocks", "ghost_phase")


def measure(scene, backend: str, records: int, by_label: bool = False) -> list[dict]:
    """Build the tier-2 model of ``scene``, step one record of warm-up and ``records`` timed ones: one row. On
    levels also the fine-equivalent rate (the cell updates of the uniform finest grid over the tank in the same
    time) and, with ``by_label``, one more record timed launcher by launcher
    (:func:`iceresist.backends.launch.profiling`): a row per label and the level exchange's share
    (:data:`LEVEL_EXCHANGE`) in the first row."""
    from iceresist.models.tier2 import Tier2Model

    t0 = time.perf_counter()
    model = Tier2Model(scene, backend=backend)
    build_s = time.perf_counter() - t0
    model.step(1)
    model.target.synchronize()
    rebuilds = _timed_rebuilds(model) if scene.refinement is not None else None
    t0 = time.perf_counter()
    model.step(records)
    model.target.synchronize()
    seconds = time.perf_counter() - t0
    per_record = seconds / records
    total = int(math.ceil(scene.run.end_time_s / model.dt_s - 1e-9))
    lbm = records * model.lbm_steps_per_record
    row = {"name": f"ship {scene.scene.name}", "backend": model.target.name, "precision": model.precision,
           "cells": model.cells, "shape": "x".join(str(n) for n in model.shape_cells),
           "dx_mm": 1e3 * model.units.dx_m, "steps": lbm, "seconds": seconds,
           "mlups": records * model.lattice_updates_per_step / seconds / 1e6, "s_per_record": per_record,
           "records_total": total, "projected_h": total * per_record / 3600.0,
           "allocated_GiB": model.allocated_bytes() / GIB, "build_s": build_s,
           "finite": bool(model.is_finite())}
    if scene.refinement is not None:   # cells of every level, the finest's resolution; updates per level-0 step
        stepping = seconds - sum(rebuilds)
        finest = max(model.cells_per_level)
        fine_cells = math.prod(model.shape_cells) * 8 ** finest
        row.update(cells_per_level=model.cells_per_level, cells_per_cube=model.cells_per_cube,
                   updates_per_step=model.lattice_updates_per_step // model.lbm_steps_per_record,
                   regrids_in_records=len(rebuilds), regrid_s_in_records=sum(rebuilds),
                   regrids_put_off=model.regrids_put_off,
                   # the stepping alone: the regrids that fell in so few records say little of a whole case's
                   s_per_record_stepping=stepping / records,
                   projected_h_stepping=total * stepping / records / 3600.0,
                   fine_equivalent_mlups=fine_cells * lbm * 2 ** finest / stepping / 1e6)
        if model.regrid_every:
            # what every regrid that changes the blocks costs: the levels rebuilt (here onto the blocks they have)
            model.target.synchronize()
            t0 = time.perf_counter()
            model._rebuild(model.octree, model.level_bytes)
            model.target.synchronize()
            row["rebuild_s"] = time.perf_counter() - t0
    if not by_label:
        return [row]
    from iceresist.backends.launch import profiling

    n0 = len(rebuilds or ())     # rebuild_s's rebuild is in the list already
    with profiling(model.target) as prof:
        t0 = time.perf_counter()
        model.step(1)
        model.target.synchronize()
        profiled = time.perf_counter() - t0
    if rebuilds is not None and len(rebuilds) > n0:
        profiled -= sum(rebuilds[n0:])          # a regrid in the profiled record: its launches are not the step's
    rows = [{"name": f"label {label}", "backend": row["backend"], "s_per_record": sec,
             "share": sec / profiled, "launches_per_step": n / model.lbm_steps_per_record}
            for label, (sec, n) in sorted(prof.items(), key=lambda kv: -kv[1][0])]
    row["profiled_s_per_record"] = profiled
    row["level_exchange_share"] = sum(prof[k][0] for k in LEVEL_EXCHANGE if k in prof) / profiled
    return [row] + rows


def _timed_rebuilds(model) -> list:
    """The seconds of each rebuild of the levels ``model`` makes from now on (a list that fills as it runs)."""
    seconds, rebuild = [], model._rebuild

    def timed(*args, **kw):
        model.target.synchronize()
        t0 = time.perf_counter()
        rebuild(*args, **kw)
        model.target.synchronize()
        seconds.append(time.perf_counter() - t0)

    model._rebuild = timed
    return seconds


#: Grid points the paper's AMR starts with (section 3: "about 160 million", 15 % of a uniform mesh).
PAPER_START_CELLS = 160e6


def amr_plan(scene, fit_gib, rate_mlups: float | None) -> dict:
    """The refined tank of ``scene`` counted without building it (:meth:`Tier2Model.plan`): leaf and ghost
    cells per level, the finest resolution, the arrays' GiB (whether they fit each of ``fit_gib``), the cell updates
    of the case and, at ``rate_mlups``, its projected hours."""
    from iceresist.models.tier2 import Tier2Model

    t0 = time.perf_counter()
    p = Tier2Model.plan(scene)
    cells = sum(p["cells_per_level"].values())
    gib = sum(p["level_bytes"].values()) / GIB
    updates = p["updates_per_step"] * p["level0_steps"]
    row = {"name": f"plan {scene.scene.name}", "cells": cells, "cells_per_level": p["cells_per_level"],
           "ghost_cells_per_level": p["ghost_cells_per_level"], "cells_per_cube": p["cells_per_cube"],
           "cells_vs_paper": cells / PAPER_START_CELLS, "arrays_GiB": gib,
           **{f"fits_{g:g}_GiB": gib <= g for g in fit_gib},
           "updates_per_step": p["updates_per_step"], "level0_steps": p["level0_steps"], "updates_total": updates,
           "plan_s": time.perf_counter() - t0}
    if rate_mlups:
        row[f"projected_h_at_{rate_mlups:g}_mlups"] = updates / (rate_mlups * 1e6) / 3600.0
    return row


#: The parts of a coupled step in the words of docs/PERFORMANCE.md, by launcher label.
PARTS = {
    "links": "link pass (q, eq. 16, eq. 17; the phi mirror with a free surface)",
    "f_update": "free-surface fused f update",
    "h_stream": "phase field h stream and phi (eq. 5)",
    "h_collide": "phase field h collision (eqs. 6-9)",
    "reflag": "reflag",
    "extension": "velocity extension",
    "velocity": "velocity",
    "mark": "redistribute / refill / mark", "refill_fs": "redistribute / refill / mark",
    "redistribute_fs": "redistribute / refill / mark",
    "h_init": "phase field frozen bulk (roles, settle, ghost refill)",
    "bulk_roles": "phase field frozen bulk (roles, settle, ghost refill)",
    "bulk_settle": "phase field frozen bulk (roles, settle, ghost refill)",
}


def part_of(label: str) -> str:
    """The part of the coupled step a launcher label belongs to (DEM kernels together, the rest by name)."""
    if label.startswith("dem_"):
        return "DEM kernels"
    return PARTS.get(label, label)


def pure_step_seconds(shape_cells, tau: float, operator: str, precision: str, target, min_seconds: float = 2.0):
    """Seconds per step of the pure fused LBM (periodic box of ``shape_cells``), after one warm-up step, timed
    over at least ``min_seconds``."""
    from iceresist.grid import BlockForest
    from iceresist.lbm.solver import LBMSolver

    solver = LBMSolver(BlockForest.uniform(tuple(shape_cells)), tau=tau, operator=operator, precision=precision,
                       target=target)
    solver.initialize()
    solver.step(1)
    solver.synchronize()
    steps, seconds = 0, 0.0
    t0 = time.perf_counter()
    while seconds < min_seconds or steps < 3:
        solver.step(1)
        solver.synchronize()
        steps += 1
        seconds = time.perf_counter() - t0
    return seconds / steps


def compare_pure(scene, backend: str, records: int, by_label: bool = False) -> list[dict]:
    """Rows: each part of the coupled LBM step (seconds per step and share; ``by_label``: each launcher label), the
    rest (host NumPy, Python), the whole coupled step, the pure fused LBM step on as many cells, and their ratio."""
    from iceresist.backends.launch import profiling
    from iceresist.models.tier2 import Tier2Model

    model = Tier2Model(scene, backend=backend)
    model.step(1)  # warm-up: compiles, and the first record's start transient
    fluid = model.fluid.fluid
    fluid.synchronize()
    with profiling(model.target) as prof:
        t0 = time.perf_counter()
        model.step(records)
        fluid.synchronize()
        total = time.perf_counter() - t0
    steps = records * model.lbm_steps_per_record
    profiled_total = total
    unreplayed = None
    if model.target.is_cuda:
        # profiling synchronises the device after every launch: the whole step is timed again without it, kernel
        # by kernel and replayed as CUDA graphs (iceresist.backends.graphs; a record first to capture them)
        replay, model.replay.enabled = model.replay.enabled, False
        unreplayed = _timed_steps(model, records)
        model.replay.enabled = replay
        model.step(1)
        total = _timed_steps(model, records)
    common = {"backend": model.target.name, "precision": model.precision, "cells": model.cells, "steps": steps}
    parts: dict = {}
    for label, (sec, n) in prof.items():
        p = parts.setdefault(label if by_label else part_of(label), [0.0, 0, []])
        p[0] += sec
        p[1] += n
        p[2].append(label)
    rows = [{"name": f"part: {name}", **common, "s_per_step": sec / steps, "share": sec / profiled_total,
             "launches_per_step": n / steps, "labels": " ".join(sorted(labels))}
            for name, (sec, n, labels) in sorted(parts.items(), key=lambda kv: -kv[1][0])]
    rest = profiled_total - sum(p[0] for p in parts.values())
    rows.append({"name": "part: host NumPy and Python between launches", **common, "s_per_step": rest / steps,
                 "share": rest / profiled_total})
    if model.target.is_cuda:
        rows.append({"name": "coupled step, profiled (a synchronisation after each launch)", **common,
                     "seconds": profiled_total, "s_per_step": profiled_total / steps})
    coupled = total / steps
    if unreplayed is not None:
        rows.append({"name": "coupled step, kernel by kernel (no CUDA graphs)", **common, "seconds": unreplayed,
                     "s_per_step": unreplayed / steps, "mlups": model.cells * steps / unreplayed / 1e6})
    rows.append({"name": "coupled step", **common, "seconds": total, "s_per_step": coupled, "share": 1.0,
                 "mlups": model.cells / coupled / 1e6, "graph_replays": model.replay.hits,
                 "graph_captures": model.replay.captures, "steps_launched_one_by_one": model.replay.direct})
    pure = pure_step_seconds(model.shape_cells, fluid.tau, fluid.operator, model.precision, model.target)
    rows.append({"name": "pure fused LBM step", **common, "s_per_step": pure, "mlups": model.cells / pure / 1e6,
                 "shape": "x".join(str(n) for n in model.shape_cells)})
    rows.append({"name": "ratio coupled / pure", **common, "ratio": coupled / pure})
    rows.extend(launch_rows(model, common, coupled))
    return rows


def _timed_steps(model, records: int) -> float:
    """Seconds of ``records`` records of the model's coupled steps, the device drained before and after."""
    fluid = model.fluid.fluid
    fluid.synchronize()
    t0 = time.perf_counter()
    model.step(records)
    fluid.synchronize()
    return time.perf_counter() - t0


def launch_rows(model, common: dict, coupled_s: float, steps: int = 5) -> list[dict]:
    """Rows: the launches of one coupled step (:func:`iceresist.backends.launch.tallying`) with the host's time to
    issue it (the Python and the launches, no wait for the device: on a GPU the step's floor when the device is
    quicker), and a whole record as a run makes it (its coupled steps, ``diagnostics``, the watchdog's probe, the
    finite check) against its coupled steps alone."""
    from iceresist.backends.launch import tallying

    fluid = model.fluid.fluid
    fluid.synchronize()
    with tallying() as tally:
        t0 = time.perf_counter()
        for _ in range(steps):
            model.coupled_step()
        host = (time.perf_counter() - t0) / steps
    fluid.synchronize()
    t0 = time.perf_counter()
    for _ in range(2 * steps):     # replayed (where graphs are on): the host's time per step then
        model.replay.run(model.coupled_step)
    host_replayed = (time.perf_counter() - t0) / (2 * steps)
    fluid.synchronize()

    def record_as_a_run_makes_it():
        model.step(1)
        model.diagnostics()
        model.watchdog_probe()
        model.is_finite()
        fluid.synchronize()

    record_as_a_run_makes_it()      # warm-up: the record's own kernels compile at their first call
    t0 = time.perf_counter()
    record_as_a_run_makes_it()
    record = time.perf_counter() - t0
    n = model.lbm_steps_per_record
    return [{"name": "launches per coupled step", **common, "launches_per_step": tally.total / steps,
             "syncs_per_step": tally.syncs / steps, "substeps": model.dem.last_substeps,
             "host_s_per_step": host, "host_share": host / coupled_s,
             "host_s_per_step_replayed": host_replayed},
            {"name": "record with its diagnostics", **common, "lbm_steps": n, "s_per_record": record,
             "s_diagnostics": record - n * coupled_s, "share_diagnostics": 1.0 - n * coupled_s / record}]


def run(args):
    from iceresist.errors import InputError
    from iceresist.scene.case_scenes import FIDELITIES, TIER2, case_scene
    from iceresist.models.tier2 import Tier2Model

    if args.preset not in FIDELITIES:
        raise InputError(f"--preset: unknown preset {args.preset!r}; use one of {', '.join(FIDELITIES)}")
    if args.records < 0:
        raise InputError(f"--records: 0 (the --fit-gib row only) or more (got {args.records})")
    rows, acrosses = [], list(args.across or [])
    if args.rate_mlups is not None and not (args.amr and args.rate_mlups > 0):
        raise InputError(f"--rate-mlups: a rate > 0 with --amr, e.g. --rate-mlups 514 (got {args.rate_mlups}"
                         f"{'' if args.amr else ' without --amr'})")
    if args.fit_gib and not args.amr:
        probe = scaled_scene(args.case, args.preset, args.probe_across)
        model = Tier2Model(probe, backend=args.backend)
        per, fixed = bytes_per_cell(model.allocation(), model.cells)
        del model

        def cells_of(n):
            return math.prod(scaled_scene(args.case, args.preset, n).shape_cells()) if n else 0

        width_m = TIER2[args.preset]["cells"][1] * TIER2[args.preset]["dx_m"]
        for gib in args.fit_gib:
            n = finest_fit(per, fixed, gib * GIB, cells_of)
            rows.append({"name": f"fit {gib:g} GiB", "backend": args.backend, "bytes_per_cell": per,
                         "fixed_GiB": fixed / GIB, "across": n, "cells": cells_of(n),
                         "dx_mm": 1e3 * width_m / n if n else 0.0})
            if n:
                acrosses.append(n)
    if not acrosses and not args.fit_gib:
        acrosses = [TIER2[args.preset]["cells"][1]]
    if args.amr:        # the preset's refined tank as it is (no --across or --compare-pure)
        if args.across or args.compare_pure:
            raise InputError("--amr: times the preset's refined tank as the preset gives it; leave out --across "
                             "and --compare-pure")
        return _amr_rows(case_scene(args.case, args.preset, 2, amr=True), args)
    for n in acrosses if args.records else []:
        scene = scaled_scene(args.case, args.preset, n)
        if args.compare_pure:
            rows.extend(compare_pure(scene, args.backend, args.records, by_label=args.by_label))
        else:
            rows.extend(measure(scene, args.backend, args.records))
    return rows


def _amr_rows(scene, args):
    """The rows of ``--amr`` as they come: the plan (printed before the build, which on the paper's levels takes
    minutes), then the measured ones."""
    yield amr_plan(scene, args.fit_gib or [], args.rate_mlups)
    if args.records:
        yield from measure(scene, args.backend, args.records, by_label=args.by_label)
