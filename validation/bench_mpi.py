"""MPI benchmark: strong scaling of the fused LBM step from one rank to several on one machine
(:mod:`iceresist.parallel`), a periodic box of ``--n`` cells per side, cumulant, CPU; with ``--case ship`` the
coupled tier-2 step of the quick A-c68-v1.0 case instead (3.19e6 cells, the hull, 785 ice cubes, the free
surface; ``--n`` ignored); with ``--case amr`` a periodic box of ``--n`` level-0 cells per side whose middle half
along each axis is level 1 (the refined fluid, :mod:`iceresist.parallel.levels`; a step is one level-0 step, MLUPS
counts level 1's two sub-steps); with ``--case ship-amr`` the quick A-c68-v1.0 case on its refined levels
(``iceresist sweep --amr``'s tank, the coupled step on the finest level; ``--n`` ignored).

Each configuration runs in its own ``mpirun`` (``--ranks``, default 1 and 2 ranks of one thread each, and one rank
of as many threads as ranks for comparison): after one untimed step (the kernels load), ``--steps`` steps are
timed; per configuration the seconds per step, MLUPS, the speed-up over one rank of one thread, the bytes the
ranks send per step (halo exchange, all ranks together) and the share of the step spent in the exchange
(rank 0). Where the LBM solver exchanges its halo (``lbm`` and ``amr``, the coarser levels of ``ship-amr``), a run
of several ranks times its steps with the interior updated while the messages travel and without, alternating,
and gives both (``seconds_per_step_no_overlap``).

    python -m validation.bench mpi [--case ship|amr|ship-amr] [--n 64] [--steps 20] [--precision float32]
                                   [--ranks 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser):
    parser.add_argument("--ranks", type=int, default=2, help="the largest rank count (default 2)")
    parser.add_argument("--case", choices=("lbm", "ship", "amr", "ship-amr"), default="lbm",
                        help="the fused LBM in a periodic box (default), the coupled quick tier-2 step, a box "
                             "refined in its middle (two levels) or the quick tier-2 case on its refined levels")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)


def worker(n: int, steps: int, precision: str) -> dict | None:
    """One timed run in this MPI job (or one process); rank 0's figures, None on the others."""
    from iceresist import parallel
    from iceresist.grid import BlockForest
    from iceresist.lbm.solver import LBMSolver

    comm = parallel.world()
    forest = BlockForest.uniform((n, n, n))
    decomp = None
    local = forest
    if comm is not None:
        from iceresist.parallel.decomposition import Decomposition

        decomp = Decomposition(forest, comm)
        local = decomp.local
    solver = LBMSolver(local, tau=0.6, precision=precision)
    if decomp is not None:
        solver.active_blocks = decomp.nowned
        solver.halo = decomp.solver_halo()
    solver.initialize(1.0, (0.02, 0.01, 0.0))
    solver.step(1)
    return _timed(solver.step, comm, decomp, forest, steps, precision, [solver])


AMR_SCENE = """
[scene]
name = "amr_bench"
units = "lattice"

[domain]
cells = [{n}, {n}, {n}]

[fluid]
operator = "cumulant"
initial_velocity_m_s = [0.02, 0.01, 0.0]

[numerics]
tau = 0.6
precision = "{precision}"

[run]
steps = 1

[refinement]
levels = 1

[[refinement.boxes]]
lo_m = [{lo}, {lo}, {lo}]
hi_m = [{hi}, {hi}, {hi}]
level = 1
"""


def amr_worker(n: int, steps: int, precision: str) -> dict | None:
    """Level-0 steps of the refined box in this MPI job (or one process), after one untimed step; rank 0's figures,
    None on the others."""
    from iceresist import parallel
    from iceresist.models.fluid import FluidModel
    from iceresist.scene.load import parse_scene

    comm = parallel.world()
    scene = parse_scene(AMR_SCENE.format(n=n, lo=n / 4, hi=3 * n / 4, precision=precision), "amr_bench.toml")
    model = FluidModel(scene, backend="cpu", comm=comm)
    return _levels_timed(model, model.lattice_updates_per_step, comm, steps, precision)


def ship_amr_worker(steps: int, precision: str) -> dict | None:
    """Level-0 steps of the quick A-c68-v1.0 case on its refined levels (``iceresist sweep --amr``'s tank: every
    level's sub-steps, the coupling, the surface and the DEM on the finest) in this MPI job (or one process), after
    one untimed step; rank 0's figures, None on the others. No regrid inside the timed steps."""
    from iceresist import parallel
    from iceresist.models import Tier2Model
    from iceresist.ship.cases import amr_overrides
    from iceresist.scene.case_scenes import case_scene

    comm = parallel.world()
    model = Tier2Model(case_scene("A-c68-v1.0", "quick", 2, **amr_overrides("quick")), backend="cpu",
                       precision=precision, comm=comm)
    return _levels_timed(model, model.lattice_updates_per_step // model.lbm_steps_per_record, comm, steps, precision)


def _levels_timed(model, updates: int, comm, steps: int, precision: str) -> dict | None:
    """``model.lbm.step`` (level-0 steps of a model on levels, ``updates`` cell updates each) timed after one
    untimed step, with the halo leaves rank 0 holds."""
    from types import SimpleNamespace

    model.lbm.step(1)
    size = SimpleNamespace(cells=updates, nblocks=int(model.octree.nleaves))
    out = _timed(model.lbm.step, comm, model.decomp, size, steps, precision, model.lbm.solvers.values())
    if out is not None and model.decomp is not None:
        d = model.decomp
        out["halo_blocks_rank0"] = int(sum(v.nleaves for v in d.views if v is not None) - sum(d.nown.values()))
    return out


def _timed(step, comm, decomp, forest, steps: int, precision: str, solvers=()) -> dict | None:
    """``step(steps)`` timed between barriers after the first (untimed) step: rank 0's figures, None on the
    others. Where ``solvers`` exchange their halo through the solver (:class:`~iceresist.parallel.decomposition
    .SolverHalo`), the steps run twice with the interior updated while the messages travel and twice without,
    alternating, and the figures of both are given (the best of each pair)."""
    import numpy as np

    halos = [s.halo for s in solvers if getattr(s, "halo", None) is not None]
    runs = {}
    for overlap in ((True, False, True, False) if halos else (True,)):
        for h in halos:
            h.overlap = overlap
        if comm is not None:
            comm.Barrier()
            decomp.exchanges, decomp.bytes_sent, decomp.exchange_s = 0, 0, 0.0
        t0 = time.perf_counter()
        step(steps)
        if comm is not None:
            comm.Barrier()
        seconds = (time.perf_counter() - t0) / steps
        share = 0.0 if decomp is None else decomp.exchange_s / steps / seconds
        if overlap not in runs or seconds < runs[overlap][0]:
            runs[overlap] = (seconds, share)
    for h in halos:
        h.overlap = True
    sent = 0 if decomp is None else decomp.sum(decomp.bytes_sent) / steps
    if comm is not None and comm.rank != 0:
        return None
    seconds, share = runs[True]
    out = {"cells": int(forest.cells), "seconds_per_step": seconds, "mlups": forest.cells / seconds / 1e6,
           "bytes_sent_per_step": float(sent), "exchange_share": share,
           "halo_blocks_rank0": 0 if decomp is None else int(len(getattr(decomp, "halo", ()))),
           "blocks": int(forest.nblocks), "float": str(np.dtype(precision))}
    if False in runs:
        out["seconds_per_step_no_overlap"], out["exchange_share_no_overlap"] = runs[False]
        out["blocks_inner_rank0"] = sum(h.ninner for h in halos)
        out["blocks_sent_rank0"] = sum(h.nsent for h in halos)
    return out


def ship_worker(steps: int, precision: str) -> dict | None:
    """The coupled tier-2 step of the quick A-c68-v1.0 case in this MPI job (or one process), after one untimed
    LBM step; rank 0's figures, None on the others."""
    from iceresist import parallel
    from iceresist.models import Tier2Model
    from iceresist.scene.case_scenes import case_scene

    comm = parallel.world()
    model = Tier2Model(case_scene("A-c68-v1.0", "quick", 2), backend="cpu", precision=precision, comm=comm)
    return _levels_timed(model, model.lattice_updates_per_step // model.lbm_steps_per_record, comm, steps, precision)


def _launch(ranks: int, threads: int, args, precision: str) -> dict:
    exe = Path(sys.executable)
    cmd = [sys.executable, "-m", "validation.bench_mpi", "--worker", "--case", args.case, "--n", str(args.n),
           "--steps", str(args.steps), "--precision", precision]
    if ranks > 1:
        cmd = [str(exe.parent / "mpirun"), "-n", str(ranks)] + cmd
    env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
    if ranks > 1 and not Path(cmd[0]).is_file():
        raise SystemExit("mpi benchmark: no mpirun beside the Python interpreter; install the `mpi` extra")
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800,
                         cwd=Path(__file__).resolve().parents[1])
    rows = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    if res.returncode != 0 or not rows:
        raise SystemExit(f"mpi benchmark: {' '.join(cmd)} failed:\n{res.stderr[-2000:]}")
    return rows[0]


def run(args) -> list[dict]:
    rows = []
    for precision in args.precision:
        base = None
        configs = [(1, 1)] + [(r, 1) for r in range(2, args.ranks + 1)] + [(1, args.ranks)]
        for ranks, threads in configs:
            r = _launch(ranks, threads, args, precision)
            base = base or r["seconds_per_step"]
            name = {"ship": "quick tier-2 step (A-c68-v1.0)", "amr": f"two levels n={args.n}",
                    "ship-amr": "quick tier-2 on levels (A-c68-v1.0 --amr)"}.get(args.case, f"lbm n={args.n}")
            rows.append({"name": name, "ranks": ranks, "threads_per_rank": threads,
                         "precision": precision, "cells": r["cells"], "steps": args.steps,
                         "seconds_per_step": r["seconds_per_step"], "mlups": r["mlups"],
                         "speedup": base / r["seconds_per_step"],
                         "MB_sent_per_step": r["bytes_sent_per_step"] / 1e6,
                         "exchange_share": r["exchange_share"], "halo_blocks_rank0": r["halo_blocks_rank0"]})
            if "seconds_per_step_no_overlap" in r:
                rows[-1].update(seconds_per_step_no_overlap=r["seconds_per_step_no_overlap"],
                                exchange_share_no_overlap=r["exchange_share_no_overlap"],
                                blocks_inner_rank0=r["blocks_inner_rank0"], blocks_sent_rank0=r["blocks_sent_rank0"])
    return rows


def _main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--worker", action="store_true")
    p.add_argument("--n", type=int, default=64)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--precision", default="float32")
    p.add_argument("--case", default="lbm")
    a = p.parse_args(argv)
    if a.case == "ship":
        out = ship_worker(a.steps, a.precision)
    elif a.case == "amr":
        out = amr_worker(a.n, a.steps, a.precision)
    elif a.case == "ship-amr":
        out = ship_amr_worker(a.steps, a.precision)
    else:
        out = worker(a.n, a.steps, a.precision)
    if out is not None:
        print(json.dumps(out))


if __name__ == "__main__":
    _main()
