"""What the commands print besides results: -v, compile progress, tier-1 quiet, one MPI rank speaking, the closing
line (iceresist.console, iceresist.backends.compilelog, iceresist.driver.closing_line)."""

from __future__ import annotations

import logging
import time
from types import SimpleNamespace

import pytest

from iceresist.backends import compilelog
from iceresist.console import OtherRank, configure_logging


class _Count(logging.Handler):
    def __init__(self):
        super().__init__()
        self.records = []

    def emit(self, record):
        self.records.append(record)


@pytest.fixture
def counted():
    """The root logger's handlers replaced by one that keeps every record it is handed; levels restored after."""
    root = logging.getLogger()
    names = ("", "iceresist", "reports", "fsicr", "validation", "numba")
    saved = (root.handlers[:], {n: logging.getLogger(n).level for n in names})
    h = _Count()
    root.handlers = [h]
    yield h
    root.handlers = saved[0]
    for n, level in saved[1].items():
        logging.getLogger(n).setLevel(level)


def test_verbose_raises_our_loggers_only_and_numba_compiles_silently(counted):
    from iceresist.backends.conf import cpu_jit

    configure_logging(verbose=True)
    assert logging.getLogger("iceresist.models").getEffectiveLevel() == logging.DEBUG
    assert logging.getLogger("numba.core.byteflow").getEffectiveLevel() >= logging.WARNING

    def add_one(x):
        return x + 1

    assert cpu_jit(add_one)(1) == 2     # a compile, whose DEBUG lines numba logs: 36 records for this one alone
    assert not [r for r in counted.records if r.name.startswith("numba")]
    configure_logging(verbose=True, numba_debug=True)
    assert logging.getLogger("numba.core.byteflow").getEffectiveLevel() == logging.DEBUG


def test_a_compile_is_announced_by_name_and_count(counted):
    from iceresist.backends.conf import cpu_jit

    configure_logging()
    t_before = time.perf_counter()
    before = compilelog.compiled_since(0.0)[0]

    def kinetic_energy_probe(x):
        return 0.5 * x * x

    def unused_kernel(x):
        return x

    kern = cpu_jit(kinetic_energy_probe)
    unused = cpu_jit(unused_kernel)     # noqa: F841 - made, never called: counted while it lives
    assert kern(2.0) == 2.0
    lines = [r.getMessage() for r in counted.records if r.name == compilelog.__name__]
    mine = [ln for ln in lines if "kinetic_energy_probe" in ln]
    assert len(mine) == 1 and f"compiling kernel {before + 1} of the " in mine[0], lines
    total = int(mine[0].split(" of the ")[1].split(" made so far")[0])
    assert total >= before + 2      # the kernel made but not yet called is counted as still to compile
    n, seconds = compilelog.compiled_since(t_before)
    assert n == 1 and seconds > 0 and compilelog.compiled_since(0.0)[0] == before + 1
    assert kern(3.0) == 4.5 and compilelog.compiled_since(t_before)[0] == 1      # compiled once


def test_a_rank_other_than_0_keeps_its_own_warnings_only():
    f = OtherRank(3)

    def rec(name, msg):
        return logging.LogRecord(name, logging.WARNING, __file__, 1, msg, (), None)

    assert not f.filter(rec("iceresist.units", "tau - 1/2 = 8e-06 is below 1e-04"))
    assert not f.filter(rec("iceresist.backends.compilelog", "compiling kernel 1 of 9: f_update"))
    own = rec("iceresist.backends.cache", "kernel cache /x not writable")
    assert f.filter(own) and own.getMessage() == "rank 3: kernel cache /x not writable"
    assert f.filter(own) and own.getMessage() == "rank 3: kernel cache /x not writable"       # marked once


def test_a_tier1_scene_says_nothing_of_a_grid_it_does_not_build(tmp_path):
    import subprocess
    import sys

    (tmp_path / "t1.toml").write_text('[case]\nname = "A-c68-v1.0"\n')
    out = subprocess.run([sys.executable, "-m", "iceresist", "run", "t1.toml", "--steps", "0", "--no-progress"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    err = out.stderr
    assert out.returncode == 0, err
    assert "tau" not in err and "rounded" not in err and "cells of" not in err, err
    assert "WARNING" not in err, err
    last = err.strip().splitlines()[-1]
    assert "wall time" in last and "s setting up" in last and "s stepping" in last, last


def test_the_closing_line_names_wall_time_set_up_and_stepping():
    from iceresist.driver import closing_line

    sim = SimpleNamespace(stop_reason="stop iteration 5 reached", steps_done=5, wall_time_s=400.0, step_time_s=378.0,
                          first_step_s=370.0, first_steps=1, mlups=6.79)
    text = closing_line(sim, SimpleNamespace(cells=8192), build_s=354.0)
    assert "wall time 754.0 s: 354.0 s setting up, 378.0 s stepping (370.0 s of it in the first step" in text
    assert text.endswith("6.79 MLUPS after the first step")
    sim.first_steps = 5
    assert closing_line(sim, SimpleNamespace(cells=8192)).endswith("MLUPS with the first step")
    assert "MLUPS" not in closing_line(sim, SimpleNamespace(cells=0))        # tier 1 has no lattice
    # a leg counts its own compiles: none since now (a sweep's later case, its kernels compiled by the first)
    assert "kernels loaded from the cache" in closing_line(sim, SimpleNamespace(cells=0), since=time.perf_counter())


def test_the_time_to_go_leaves_the_compile_out(caplog):
    from iceresist.simulation import Simulation

    sim = Simulation.__new__(Simulation)
    sim.model = SimpleNamespace(iteration=20, time_s=2.0, cells=0)
    sim.first_steps, sim.first_step_s = 10, 700.0
    sim.steps_done, sim.step_time_s = 20, 760.0
    with caplog.at_level(logging.INFO, logger="iceresist.simulation"):
        sim._log_progress(20, 120, 760.0)       # 10 steps after the compile in 60 s: 100 more take 10 min
        sim._log_progress(10, 120, 700.0)
    assert "about 10 min to go" in caplog.records[0].getMessage()
    assert "compile or load the kernels" in caplog.records[1].getMessage()
