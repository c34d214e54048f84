"""The launch budget of a coupled tier-2 step on CUDA (docs/PERFORMANCE.md, "Launches per coupled step").

On a GPU a small kernel costs its launch (a few microseconds of host time through numba's dispatcher, more with
each array argument), so the coupled step's pace is set by how many launches it makes, and any read or
synchronisation inside a step stalls the host until the device drains. :func:`count` tallies, for a built and
warmed-up tier-2 model:

* one coupled LBM step: its launches by kernel name (:func:`iceresist.backends.launch.tallying`), the DEM
  sub-steps it took, synchronisations and copies between host and device (:mod:`iceresist.backends.transfers`);
* one record as a run makes it (the record's coupled steps, ``diagnostics``, the watchdog's probe, the finite
  check): its reads with their bytes, uploads and synchronisations.

:func:`traced` builds the CI-sized tier-2 case on the ``cuda`` target within the GPU build check's tracing (no GPU
needed, nothing runs: launches are recorded), so ``tests/test_launch_budget.py`` holds the budget in CI. Run it
in a process of its own with ``NUMBA_ENABLE_CUDASIM=0``: ``python -m iceresist.validate.launch_budget``.
"""

from __future__ import annotations

import json

from iceresist.backends import transfers
from iceresist.backends.buildcheck import tracing
from iceresist.backends.launch import tallying
from iceresist.models import build_model
from iceresist.validate.gpu_build import check_scenes

#: Launches of one coupled step of the tier-2 case: ``fixed`` (grid passes, surface, coupling), ``regather`` (the
#: body forces summed again with the step's fluid loads) and ``per_substep`` (one DEM sub-step: drift, place, two
#: for the sort, contact, gather). The target of docs/PERFORMANCE.md is 20 for one sub-step.
BUDGET = {"fixed": 23, "regather": 1, "per_substep": 6}


def budget(substeps: int) -> int:
    """Most launches a coupled step of ``substeps`` DEM sub-steps may make (:data:`BUDGET`)."""
    return BUDGET["fixed"] + BUDGET["regather"] + BUDGET["per_substep"] * int(substeps)


def count(model) -> dict:
    """``{"step": ..., "record": ...}`` for a built tier-2 ``model`` that has made one record (see the module
    docstring); each part holds ``launches`` (total), ``by_kernel``, ``syncs``, ``downloads``,
    ``download_bytes``, ``largest_download_bytes``, ``uploads``, ``implicit`` (host arrays handed to a launch)."""
    def part(tally, copies) -> dict:
        return {"launches": tally.total, "by_kernel": dict(tally.launches.most_common()), "syncs": tally.syncs,
                "downloads": copies.counts["download"], "download_bytes": copies.nbytes["download"],
                "largest_download_bytes": copies.largest["download"], "uploads": copies.counts["upload"],
                "implicit": copies.counts["implicit"], "sites": str(copies)}

    with tallying() as t, transfers.counting() as c:
        model.coupled_step()
    step = {**part(t, c), "substeps": model.dem.last_substeps, "budget": budget(model.dem.last_substeps)}
    with tallying() as t, transfers.counting() as c:
        model.step(1)
        model.diagnostics()
        model.watchdog_probe()
        model.is_finite()
    record = {**part(t, c), "lbm_steps": model.lbm_steps_per_record, "cells": int(model.cells)}
    return {"step": step, "record": record}


def traced(label: str = "tier2-float32") -> dict:
    """:func:`count` of the CI-sized tier-2 case ``label`` of :func:`~iceresist.validate.gpu_build.check_scenes`
    on the ``cuda`` target, traced (no GPU: launches recorded, not run)."""
    with tracing():
        model = build_model(check_scenes()[label], backend="cuda")
        model.step(1)            # a first record as a run makes it: what is made once is made here
        model.diagnostics()
        model.watchdog_probe()   # the first probe is a full one, as in a run
        model.is_finite()
        return count(model)


if __name__ == "__main__":
    print(json.dumps(traced()))
