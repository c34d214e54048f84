"""The launch budget of a coupled tier-2 step on CUDA (docs/PERFORMANCE.md, "Launches per coupled step"): the
CI-sized case traced on the ``cuda`` target in a process of its own (no GPU needed: launches are recorded, not
run), :mod:`iceresist.validate.launch_budget`."""

import json
import os
import subprocess
import sys

import pytest

from iceresist.validate.launch_budget import BUDGET, budget


@pytest.fixture(scope="module")
def counted():
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    res = subprocess.run([sys.executable, "-m", "iceresist.validate.launch_budget"], capture_output=True, text=True,
                         env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_a_coupled_step_stays_within_its_launch_budget(counted):
    step = counted["step"]
    assert step["substeps"] >= 1
    assert step["launches"] <= budget(step["substeps"]), step["by_kernel"]
    # the DEM sort is two launches after the spheres' placing counted them, its scan one thread block (no serial
    # scan on one thread, no launch to zero the counts)
    sort = {k: step["by_kernel"].get(k, 0) for k in ("dem_place", "scan_buckets", "scatter")}
    assert set(sort.values()) == {step["substeps"]}, sort
    assert not {"zero", "count_k"} & set(step["by_kernel"]), step["by_kernel"]
    # contacts are evaluated once per sub-step: the step's new fluid loads only sum the body forces again
    assert step["by_kernel"]["dem_contact"] == step["substeps"], step["by_kernel"]
    assert step["by_kernel"]["dem_gather"] == step["substeps"] + BUDGET["regather"], step["by_kernel"]


def test_a_coupled_step_neither_reads_nor_waits(counted):
    step = counted["step"]
    assert step["syncs"] == 0
    assert step["downloads"] == step["uploads"] == step["implicit"] == 0, step["sites"]


def test_a_record_copies_nothing_to_the_device_and_reads_no_field(counted):
    record = counted["record"]
    assert record["uploads"] == record["implicit"] == 0, record["sites"]
    assert record["syncs"] == 0
    # scalars and per-block, per-body, per-sphere or per-column rows only: no read of a byte per cell or more
    assert 0 < record["largest_download_bytes"] < record["cells"], record["sites"]
