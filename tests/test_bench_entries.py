"""Every ``python -m validation.bench NAME`` entry runs end to end on a tiny case with the dispatcher's defaults
(both precisions where the flag is left out) and prints one JSON object per measurement."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from validation import bench

SLOW = pytest.mark.slow
TINY = [
    pytest.param("lbm", ["--n", "8", "--steps", "2"], id="lbm"),
    pytest.param("dem", ["--n", "8", "--steps", "2"], id="dem"),
    # coupling and freesurface: 792 s and 489 s in a cold CI run (the kernels of both precisions compiled for a
    # two-step case); test_coupling, test_bodies and test_freesurface_fluid run the same kernels in CI
    pytest.param("coupling", ["--n", "16", "--bodies", "2", "--steps", "2"], id="coupling", marks=SLOW),
    pytest.param("freesurface", ["--n", "8", "--steps", "2"], id="freesurface", marks=SLOW),
    pytest.param("amr", ["--n", "16", "--steps", "2", "--precision", "float64"], id="amr"),
    pytest.param("mpi", ["--n", "16", "--steps", "2", "--precision", "float64"], id="mpi", marks=pytest.mark.skipif(
        not (Path(sys.executable).parent / "mpirun").is_file(), reason="the `mpi` extra is not installed")),
    pytest.param("ship", ["--preset", "quick", "--records", "1"], id="ship", marks=SLOW),
    pytest.param("gpu_build", [], id="gpu_build", marks=SLOW),
]


@pytest.mark.parametrize("name, argv", TINY)
def test_each_benchmark_runs_on_a_tiny_case(name, argv, capsys):
    if name == "gpu_build":   # compiles for a real device: a process without the CUDA simulator
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
        done = subprocess.run([sys.executable, "-m", "validation.bench", name, *argv, "--json"], env=env,
                              capture_output=True, text=True, cwd=Path(__file__).resolve().parents[1], timeout=1800)
        status, out = done.returncode, done.stdout
    else:
        status = bench.main([name, *argv, "--backend", "cpu", "--json"])
        out = capsys.readouterr().out
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert status in (0, None) and rows
    if name in ("lbm", "dem", "coupling"):                     # the precision flag left out: both precisions
        assert {r["precision"] for r in rows} == {"float32", "float64"}
    for r in rows:
        assert r.get("seconds", 1.0) > 0


def test_dem_benchmark_takes_the_documented_precision_flag(capsys):
    """The form the docs give (one --precision) and the dispatcher's list of them both run (a list reached
    DEMSystem and raised TypeError)."""
    assert bench.main(["dem", "--n", "4", "--steps", "1", "--precision", "float64", "--json"]) in (0, None)
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["precision"] for r in rows] == ["float64"]


def test_an_interrupted_benchmark_keeps_the_rows_it_measured(monkeypatch, capsys):
    """A benchmark cut off at a deadline (SIGINT, as validation/gpu_campaign.sh sends it) after its first row: that
    row printed as it came, one line that says so, exit status 130, no traceback. Planted: the interrupt left
    uncaught (a traceback, the row lost) fails."""
    import types

    def run(args):
        yield {"name": "plan", "cells": 8}
        raise KeyboardInterrupt

    fake = types.SimpleNamespace(add_arguments=lambda parser: None, run=run)
    monkeypatch.setattr(bench, "_module", lambda name: fake)
    assert bench.main(["fake", "--json"]) == 130
    out, err = capsys.readouterr()
    assert [json.loads(line) for line in out.splitlines()] == [{"name": "plan", "cells": 8}]
    assert err.strip() == "validation.bench fake: interrupted after 1 row"
