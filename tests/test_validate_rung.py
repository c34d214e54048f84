"""A validation rung runs through the one driver: its result file is where the ladder says, holds the scene, the
case, the time series with the case's probes and the final fields, and reduces to the same error as before."""

from __future__ import annotations

import numpy as np
import pytest

from iceresist.driver import Outputs, Stop, run_model
from iceresist.io.hdf5 import RunFile
from iceresist.models import FluidModel
from iceresist.simulation import IterationInterval
from iceresist.validate.cases import poiseuille as P
from iceresist.validate.rung import result_path, slug


def test_rung_labels_make_file_names():
    assert slug("16 cells/width") == "16-cells-width"
    assert slug("a = 8 cells") == "a-8-cells"
    assert result_path("out", "dam_break", "a = 8 cells").as_posix() == "out/runs/dam_break/a-8-cells.h5"


def test_poiseuille_rung_writes_its_result_file_and_meets_the_parabola(tmp_path):
    """8 cells across: relative L2 distance from the analytic parabola 4.27e-3 (docs/VALIDATION.md, 'Error
    against run time'); the run is a result file of the driver like any `iceresist run`."""
    params = P.ladder(True)[0]
    r = P.run(params, out_dir=tmp_path)
    assert r.error == pytest.approx(4.268e-3, rel=2e-3)
    path = tmp_path / "runs" / "poiseuille" / "8-cells-width.h5"
    assert r.extra["result_file"] == str(path)
    with RunFile(path) as rf:
        meta, ts = rf.meta, rf.timeseries()
        its = rf.snapshot_iterations()
    assert meta["validation_case"] == "poiseuille" and meta["finished"]
    assert "body_force_N_m3" in meta["scene_toml"]
    assert ts["iteration"][0] == 0 and ts["iteration"][-1] == P.steps_for(8) == r.steps
    assert its == [P.steps_for(8)]
    assert 0.0 < meta["first_step_s"] < meta["step_time_s"]
    assert r.wall_s > 0 and np.isfinite(r.mlups)


def test_probes_are_time_series_columns_beside_the_diagnostics(tmp_path):
    sc = P.scene(P.ladder(True)[0])
    model = FluidModel(sc)
    calls = []

    def probe(m):
        calls.append(m.iteration)
        return 2.0 * m.iteration

    run_model(model, sc, tmp_path / "r.h5", stop=Stop(iteration=6), progress=False,
              outputs=Outputs(timeseries=IterationInterval(3), checkpoint=None, checkpoint_final=False,
                              probes={"twice_iteration": probe}))
    with RunFile(tmp_path / "r.h5") as rf:
        ts = rf.timeseries()
    np.testing.assert_array_equal(ts["iteration"], [0, 3, 6])
    np.testing.assert_array_equal(ts["twice_iteration"], [0.0, 6.0, 12.0])
    assert "mass_kg" in ts and calls == [0, 3, 6]
