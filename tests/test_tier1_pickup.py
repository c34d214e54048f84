"""A tier-1 ship run continued from its checkpoint (``iceresist run --pickup``) gives the uninterrupted result."""

import numpy as np
import pytest

from iceresist import cli
from iceresist.io import RunFile
from iceresist.scene.case_scenes import case_scene
from iceresist.sweep import TINY_OVERRIDES
from iceresist.models.tier1 import Tier1Model


def scene_file(tmp_path, tier=1, overrides=TINY_OVERRIDES, checkpoint_every=10):
    """A CI-sized A-c68 scene on the CPU backend, recorded every step, written as TOML; (path, scene name)."""
    numerics = {**overrides.get("numerics", {}), "backend": "cpu"}
    scene = case_scene("A-c68-v1.0", "quick", tier, **{**overrides, "numerics": numerics},
                       output={"timeseries_every_steps": 1, "checkpoint_every_steps": checkpoint_every, "fields": []})
    path = tmp_path / f"tier{tier}.toml"
    path.write_text(scene.source_text)
    return path, scene.scene.name


def run_cli(*argv):
    return cli.main(["run", *map(str, argv), "--no-progress"])


def test_tier1_pickup_continues_bit_for_bit(tmp_path):
    path, name = scene_file(tmp_path)
    # the hull (0.05 m before the channel) pushes ice at iterations 76-81 and 100-106: the restart at 103 cuts a contact
    assert run_cli(path, "--output", tmp_path / "split", "--steps", "103") == 0
    assert run_cli(path, "--output", tmp_path / "split", "--steps", "150", "--pickup") == 0
    assert run_cli(path, "--output", tmp_path / "straight", "--steps", "150") == 0
    with RunFile(tmp_path / "split" / f"{name}.h5") as a, RunFile(tmp_path / "straight" / f"{name}.h5") as b:
        ta, tb = a.timeseries(), b.timeseries()
        assert a.meta["iteration"] == 150 and a.meta["steps"] == 150
    np.testing.assert_array_equal(ta["iteration"], np.arange(151))
    # at the restart the hull pushes ice: hull-ice and ice-ice contacts carry tangential history across it
    assert tb["contacts"][103] > 0 and tb["Fx_N"][103] != 0
    for key in ("Fx_N", "Fy_N", "Fz_N", "x_bow_m", "contacts", "ice_kinetic_energy_J"):
        np.testing.assert_array_equal(ta[key], tb[key], err_msg=key)


def test_checkpoint_without_dem_state_is_refused():
    from iceresist.errors import InputError

    model = Tier1Model(case_scene("A-c68-v1.0", "quick", 1, **TINY_OVERRIDES), backend="cpu")
    with pytest.raises(InputError, match="no DEM state"):
        model.load_state({"iteration": np.int64(3)})
