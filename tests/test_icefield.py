"""Ice fields (iceresist/ship/icefield.py): floes of a size distribution packed without overlap to a target
concentration, seeded; in the models (one shape and yaw per floe), the result file and the report; the pack-ice
preset."""

import copy
import math

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.models import build_model
from iceresist.scene.load import load_scene
from iceresist.ship.icefield import floe_corners, ice_field, overlapping_pairs
from iceresist.scene.case_scenes import case_scene
from iceresist.sweep import TINY_OVERRIDES, TINY_TIER2_OVERRIDES

CASE = "A-c68-v1.0"
PAPER_CHANNEL = {"width_m": 1.39, "length_m": 5.56}
SIZES = {"uniform": {"size_m": 0.041, "size_min_m": 0.025, "size_max_m": 0.06},
         "lognormal": {"size_m": 0.041, "size_sigma": 0.35}}


@pytest.mark.parametrize("distribution", ["uniform", "lognormal"])
@pytest.mark.parametrize("concentration", [0.5, 0.68, 0.88])
def test_a_field_reaches_its_concentration_with_no_floe_overlapping(distribution, concentration):
    f = ice_field(**PAPER_CHANNEL, concentration=concentration, distribution=distribution, seed=7,
                  **SIZES[distribution])
    assert f.concentration == pytest.approx(concentration, rel=0.01)
    corners = f.corners_xy()
    assert overlapping_pairs(corners) == []
    assert corners[..., 0].min() >= 0.0 and corners[..., 0].max() <= 5.56
    assert corners[..., 1].min() >= -0.695 and corners[..., 1].max() <= 0.695
    lo, hi = f.info["size_min_m"], f.info["size_max_m"]
    assert f.sizes_m.min() >= lo - 1e-12 and f.sizes_m.max() <= hi * 1.01  # the last floe's trim: under 1 %
    assert f.count > 1000


def test_the_overlap_check_sees_an_overlap():
    """The separating-axis check is not blind: two turned squares whose corners cross overlap, apart they do not."""
    c = np.array([[0.0, 0.0], [0.95, 0.0]])
    touching = floe_corners(c, np.array([1.0, 1.0]), np.array([0.0, math.radians(30)]))
    assert overlapping_pairs(touching) == [(0, 1)]
    apart = floe_corners(c * 1.5, np.array([1.0, 1.0]), np.array([0.0, math.radians(30)]))
    assert overlapping_pairs(apart) == []


def test_the_field_is_seeded_and_the_yaw_follows_the_room():
    kw = dict(**PAPER_CHANNEL, distribution="lognormal", **SIZES["lognormal"])
    a, b = ice_field(concentration=0.5, seed=3, **kw), ice_field(concentration=0.5, seed=3, **kw)
    assert np.array_equal(a.centres_m, b.centres_m) and np.array_equal(a.yaw_rad, b.yaw_rad)
    assert not np.array_equal(a.sizes_m, ice_field(concentration=0.5, seed=4, **kw).sizes_m)
    loose, dense = np.degrees(np.abs(a.yaw_rad)), np.degrees(np.abs(ice_field(concentration=0.88, seed=3, **kw).yaw_rad))
    assert np.percentile(loose, 90) > 20.0 and np.percentile(dense, 90) < 5.0
    assert (ice_field(concentration=0.5, seed=3, yaw="none", **kw).yaw_rad == 0).all()


def test_lognormal_edges_have_the_median_asked_for():
    f = ice_field(**PAPER_CHANNEL, concentration=0.68, distribution="lognormal", size_m=0.041, size_sigma=0.3,
                  size_min_m=0.001, size_max_m=1.0, seed=1)
    assert np.median(f.sizes_m) == pytest.approx(0.041, rel=0.03)
    assert np.std(np.log(f.sizes_m)) == pytest.approx(0.3, rel=0.05)


@pytest.mark.parametrize("kw, needle", [
    ({"concentration": 0.97, "distribution": "uniform", "size_m": 0.04, "size_min_m": 0.02, "size_max_m": 0.08},
     "ice.concentration: 0.97 cannot be packed"),
    ({"concentration": 0.5, "distribution": "uniform", "size_m": 0.04, "size_min_m": 0.05, "size_max_m": 0.03},
     "ice.size_min_m"),
    ({"concentration": 0.5, "distribution": "uniform", "size_m": 0.04, "size_min_m": 0.02, "size_max_m": 2.0},
     "ice.size_max_m: 2.0 m floes do not fit across"),
])
def test_a_field_that_cannot_be_packed_is_refused_naming_the_key(kw, needle):
    with pytest.raises(InputError, match=needle):
        ice_field(**PAPER_CHANNEL, **kw)


def _field_overrides(base, **ice):
    o = copy.deepcopy(base)
    o["ice"] = {**o.get("ice", {}), "count": None, "concentration": 0.6, "size_distribution": "lognormal",
                "size_m": 0.041, "size_min_m": 0.025, "size_max_m": 0.07, "thickness_m": 0.03, **ice}
    return o


def test_tier1_gives_each_floe_its_size_and_yaw_and_starts_without_contacts():
    model = build_model(case_scene(CASE, "quick", 1, **_field_overrides(TINY_OVERRIDES)), backend="cpu")
    lay = model.layout
    assert len(model.floe_shapes) == lay.count == model.dem.n_bodies - 1
    masses = np.array([s.mass_kg for s in model.floe_shapes])
    assert masses == pytest.approx(950.0 * lay.sizes_m ** 2 * 0.03, rel=1e-12)
    q = model.ice_state()["quaternions"]
    yaw = np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]), 1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))
    assert np.abs(np.angle(np.exp(1j * 4 * (yaw - lay.yaw_rad)))).max() < 1e-9  # a square: modulo 90 deg
    d = model.describe_ship()["ice_field"]
    assert d["floes"] == lay.count and d["concentration"] == pytest.approx(0.6, rel=0.01)
    model.step(1)
    assert model.diagnostics()["contacts"] == 0  # hull and channel apart, floes apart: nothing touches


def test_tier2_runs_a_field(tmp_path):
    o = _field_overrides(TINY_TIER2_OVERRIDES, concentration=0.5, size_min_m=0.03, size_max_m=0.05,
                         thickness_m=0.03)
    model = build_model(case_scene(CASE, "quick", 2, **o), backend="cpu")
    sizes = np.array([g.half_extent_m()[0] * 2 for g in model.geoms[1:]])
    assert sizes == pytest.approx(model.layout.sizes_m, rel=1e-12)
    model.step(2)
    assert np.isfinite(model.diagnostics()["Fx_fluid_N"])


def test_the_report_draws_the_initial_field(tmp_path):
    from iceresist.sweep import run_sweep
    from reports.report import write_report

    run_sweep("quick", 1, tmp_path, CASE, backend="cpu", overrides=_field_overrides(TINY_OVERRIDES))
    html = write_report(tmp_path)[0].read_text()
    assert 'alt="initial ice field"' in html


def test_the_pack_ice_preset_builds_its_field_and_steps():
    model = build_model(load_scene("pack_ice"), backend="cpu")
    assert model.layout.concentration == pytest.approx(0.8, rel=0.01)
    assert overlapping_pairs(model.layout.corners_xy()) == []
    model.step(2)
    assert np.isfinite(model.diagnostics()["Fx_N"])
