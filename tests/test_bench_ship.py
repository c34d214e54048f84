"""The tier-2 ship benchmark (``python -m validation.bench ship``): the grids it cuts, the finest grid that fits a
memory budget, and one measured row on the CI-sized case whose projection is its own rate times its records."""

import math

import pytest

from iceresist.errors import InputError
from iceresist.scene.case_scenes import TIER2, case_scene
from iceresist.sweep import TINY_TIER2_OVERRIDES
from validation.bench_ship import bytes_per_cell, finest_fit, measure, scaled_scene

CASE = "A-c68-v1.0"


def test_scaled_scene_keeps_the_tank_in_metres():
    """At the preset's own width in cells both presets give their own grid back; at half of it, half the cells
    on every axis (rounded up to the 8-cell block) and twice the cell size."""
    for preset in ("quick", "paper"):
        t2 = TIER2[preset]
        assert tuple(scaled_scene(CASE, preset, t2["cells"][1]).shape_cells()) == tuple(t2["cells"])
    half = scaled_scene(CASE, "paper", 256)
    assert tuple(half.shape_cells()) == (2056, 256, 256)   # 4104 / 2 = 2052 -> 2056
    assert half.domain.dx_m == pytest.approx(2 * TIER2["paper"]["dx_m"], rel=1e-12)
    with pytest.raises(InputError, match="--across"):
        scaled_scene(CASE, "quick", 100)


def test_finest_fit_is_the_last_grid_under_the_budget():
    def cells_of(n):
        return math.prod(scaled_scene(CASE, "paper", n).shape_cells()) if n else 0

    per, fixed = 300.0, 2 ** 30
    exact = per * cells_of(256) + fixed
    assert finest_fit(per, fixed, exact, cells_of) == 256
    assert finest_fit(per, fixed, exact - 1, cells_of) == 248
    assert finest_fit(per, fixed, fixed, cells_of) == 0
    # the paper's 512 cells across (1.08e9 cells) at 300 B per cell needs about 300 GiB
    assert finest_fit(per, fixed, 300 * 2 ** 30, cells_of) < 512 <= finest_fit(per, fixed, 320 * 2 ** 30, cells_of)


@pytest.mark.slow   # 599 s in a cold CI run (a first tier-2 compile in its process); compare-pure below stays
def test_measure_projects_its_own_rate_on_the_ci_sized_case():
    scene = case_scene(CASE, "quick", 2, **TINY_TIER2_OVERRIDES)
    (row,) = measure(scene, "cpu", 2)
    assert row["cells"] == 64 * 16 * 16 and row["finite"]
    assert row["records_total"] == math.ceil(scene.run.end_time_s / (row["steps"] / 2 * scene.units().dt_s) - 1e-9)
    assert row["projected_h"] == pytest.approx(row["records_total"] * row["s_per_record"] / 3600, rel=1e-12)
    assert row["mlups"] == pytest.approx(row["cells"] * row["steps"] / row["seconds"] / 1e6, rel=1e-12)


def test_measure_on_levels_gives_the_fine_equivalent_rate_and_the_level_exchange_by_label():
    """``--amr --by-label`` on the CI-sized ship over coarse deep water (two levels): the fine-equivalent rate is the
    uniform finest grid's updates (the level-0 cells x 8, two fine steps a level-0 step) over the stepping's
    seconds, one more record is timed by launcher label, and the level exchange's share is that of the transfers,
    the block copies and the ghost refill. Planted: the finest level's steps per level-0 step left out of the rate
    (a factor 2) fails."""
    from test_refined_tier2 import _deep

    from validation.bench_ship import LEVEL_EXCHANGE

    o = _deep(True)
    o["ship"]["start_x_m"] = o["ice"]["channel_start_x_m"] = 0.44
    scene = case_scene(CASE, "quick", 2, **o)
    row, *labels = measure(scene, "cpu", 1, by_label=True)
    stepping = row["s_per_record_stepping"]        # one timed record
    assert row["fine_equivalent_mlups"] == pytest.approx(64 * 16 * 24 * 8 * 2 * row["steps"] / stepping / 1e6,
                                                         rel=1e-12)
    shares = {r["name"].removeprefix("label "): r["share"] for r in labels}
    assert set(LEVEL_EXCHANGE) <= set(shares) and {"f_update", "links"} <= set(shares)
    assert row["level_exchange_share"] == pytest.approx(sum(shares[k] for k in LEVEL_EXCHANGE), rel=1e-12)
    assert 0 < row["level_exchange_share"] < sum(shares.values()) <= 1.0


def test_bytes_per_cell_count_the_grid_and_the_coupling_and_leave_the_dem_fixed():
    per, fixed = bytes_per_cell({"lbm": 1000, "phase_field": 500, "coupling": 100, "dem": 7}, 10)
    assert (per, fixed) == (160.0, 7)


def test_compare_pure_splits_the_coupled_step_into_its_kernels():
    """``--compare-pure`` on the CI-sized case: the parts and the rest add up to the coupled step, every part of
    a tier-2 step is timed under its own label, and the ratio is the coupled step over the pure LBM step."""
    from validation.bench_ship import compare_pure

    scene = case_scene(CASE, "quick", 2, **TINY_TIER2_OVERRIDES)
    rows = {r["name"]: r for r in compare_pure(scene, "cpu", 1)}
    coupled, pure = rows["coupled step"], rows["pure fused LBM step"]
    parts = [r for n, r in rows.items() if n.startswith("part: ")]
    assert sum(r["s_per_step"] for r in parts) == pytest.approx(coupled["s_per_step"], rel=1e-9)
    labels = {lab for r in parts for lab in r.get("labels", "").split()}
    assert {"f_update", "h_stream", "h_collide", "reflag", "extension", "links", "mark",
            "dem_contact", "dem_drift"} <= labels
    assert "velocity" not in labels         # on the CPU the f update writes the velocity
    fu = rows["part: free-surface fused f update"]
    assert fu["launches_per_step"] == 1.0 and 0 < fu["share"] < 1
    assert rows["ratio coupled / pure"]["ratio"] == pytest.approx(coupled["s_per_step"] / pure["s_per_step"])
    assert pure["cells"] == coupled["cells"] == 64 * 16 * 16
    by_label = {r["name"] for r in compare_pure(scene, "cpu", 1, by_label=True)}
    assert {"part: links", "part: mark", "part: dem_contact", "part: dem_sort", "part: f_update"} <= by_label


def test_amr_counts_the_quick_tank_on_levels_without_building_it(capsys):
    """``--amr --records 0``: one row of the refined tank counted without building it (7 s): the leaf cells of the
    built model (``test_the_quick_preset_on_levels_builds_its_levels_and_steps``), the arrays' GiB and whether
    they fit, and the case's updates projected at ``--rate-mlups``."""
    import json

    from validation import bench

    argv = ["ship", "--preset", "quick", "--amr", "--records", "0", "--fit-gib", "3", "--fit-gib", "4",
            "--rate-mlups", "9", "--json"]
    assert bench.main(argv) in (0, None)
    (row,) = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    assert row["cells_per_level"] == {"0": 2068480, "1": 6455296} and row["cells"] == 2068480 + 6455296
    assert row["cells_per_cube"] == pytest.approx(6.135, abs=1e-3)
    assert row["arrays_GiB"] == pytest.approx(3.30, abs=0.01)
    assert (row["fits_3_GiB"], row["fits_4_GiB"]) == (False, True)
    assert row["updates_per_step"] == 2068480 + 2 * 6455296
    assert row["projected_h_at_9_mlups"] == pytest.approx(row["updates_total"] / 9e6 / 3600, rel=1e-12)


@pytest.mark.parametrize("argv, needle", [
    (["--preset", "quick", "--amr", "--rate-mlups", "0"], "--rate-mlups: a rate > 0 with --amr"),
    (["--preset", "quick", "--rate-mlups", "9"], "--rate-mlups: a rate > 0 with --amr, e.g. --rate-mlups 514 "
                                                  "(got 9.0 without --amr)"),
    (["--preset", "quick", "--amr", "--across", "64"], "--amr: times the preset's refined tank"),
])
def test_bad_amr_bench_flags_exit_2_with_one_line(argv, needle, capsys):
    from validation import bench

    assert bench.main(["ship", *argv, "--records", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
