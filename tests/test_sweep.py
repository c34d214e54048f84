"""Sweep machinery on a CI-sized channel: case files, table, hand calculation, interrupt and resume, refusals."""

import json

import h5py
import numpy as np
import pandas as pd
import pytest

from iceresist.errors import InputError
from iceresist.simulation import IterationInterval
from iceresist.post.case import ice_free_width_m
from iceresist.post.sweeptable import case_path, is_finished, sweep_table
from iceresist.sweep import TINY_OVERRIDES, checkpoint_path, run_case, run_sweep

CASES = ["A-c68-v1.0", "B-c68-v1.0"]
VARYING = ["wall_time_s"]


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    table = run_sweep("quick", 1, out, CASES, backend="cpu", overrides=TINY_OVERRIDES)
    return out, table


def test_table_has_every_case(tiny_sweep):
    out, table = tiny_sweep
    assert list(table.case) == CASES
    assert (out / "sweep.csv").is_file()
    back = pd.read_csv(out / "sweep.csv")
    assert np.allclose(back.R_sim_kN, table.R_sim_kN, rtol=1e-9)
    assert (table.cubes == 28 * 6).all() and (table.tier == 1).all()
    assert np.isfinite(table.mean_force_N).all() and (table.mean_force_N > 0).all()


def test_post_processing_equals_hand_calculation(tiny_sweep):
    out, table = tiny_sweep
    for case in CASES:
        with h5py.File(case_path(out, case), "r") as h5:
            x = h5["timeseries/x_bow_m"][1:]
            fx = h5["timeseries/Fx_N"][1:]
        x0, x1 = TINY_OVERRIDES["ship"]["steady_window_m"]
        sel = (x >= x0) & (x <= x1)
        row = table[table.case == case].iloc[0]
        n_used = int(row.window_samples)
        assert sel.sum() == n_used
        # batch means drops the first n mod n_batches samples of the window; the plain mean is within 1 % here
        assert row.mean_force_N == pytest.approx(-fx[sel].mean(), rel=0.03)
        assert row.R_sim_kN == pytest.approx(row.mean_force_N * 25**3 / 1e3, rel=1e-12)
        # the steadiness check: plain means of the two halves of the window (batch means drop a few samples)
        mid = 0.5 * (x0 + x1)
        first, second = -fx[sel & (x <= mid)].mean(), -fx[sel & (x >= mid)].mean()
        assert row.half_ratio == pytest.approx(second / first, rel=0.05)
        # the record is the mean of the sub-step forces: x advances by speed * record interval
        assert np.allclose(np.diff(x), 0.514 * 0.002 * 1.0, rtol=0.3)


def test_steadiness_steps_equal_hand_means(tiny_sweep):
    """``iceresist steadiness`` on a real case file: steps of half the window from its start, each mean the plain
    mean of -Fx over the step read straight from the HDF5 time series (batch means drop a few samples)."""
    from iceresist.post.steadiness import steadiness_table

    out, _ = tiny_sweep
    x0, x1 = TINY_OVERRIDES["ship"]["steady_window_m"]
    path = case_path(out, CASES[0])
    table = steadiness_table([path], step_m=0.5 * (x1 - x0))
    with h5py.File(path, "r") as h5:
        x, fx = h5["timeseries/x_bow_m"][1:], h5["timeseries/Fx_N"][1:]
        channel_x0 = json.loads(h5["meta"].attrs["model"])["channel_start_x_m"]
    assert len(table) >= 2 and table.in_window.iloc[:2].all()
    for row in table.itertuples():
        lo, hi = row.travel_from_m + channel_x0, row.travel_to_m + channel_x0
        sel = (x >= lo) & (x <= hi)
        assert row.samples == sel.sum()
        assert row.mean_N == pytest.approx(-fx[sel].mean(), rel=0.05)


def test_interrupted_sweep_resumes_to_the_same_table(tiny_sweep, tmp_path):
    """Killed at record 50 of the second case with checkpoints every 20 records: started again, the sweep skips
    the first case, continues the second from record 40 (dropping the records 41-49 the killed leg wrote) and
    ends with the uninterrupted table bit for bit."""
    _, reference = tiny_sweep

    def kill(sim):
        if sim.model.scene.scene.name.endswith(CASES[1]) and sim.model.iteration >= 50:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep("quick", 1, tmp_path, CASES, backend="cpu", overrides=TINY_OVERRIDES,
                  callbacks={"kill": (kill, 10)}, checkpoint_schedule=IterationInterval(20))
    assert case_path(tmp_path, CASES[0]).is_file()
    assert not checkpoint_path(tmp_path, CASES[0]).exists()  # a finished case keeps no checkpoint
    assert not case_path(tmp_path, CASES[1]).is_file()
    partial = case_path(tmp_path, CASES[1]).with_name(f"{CASES[1]}.partial.h5")
    with h5py.File(partial, "r") as h5:
        assert h5["timeseries/iteration"][-1] == 49  # the kill comes before the writers of record 50
        assert h5["meta"].attrs["checkpoint_iteration"] == 40
    assert checkpoint_path(tmp_path, CASES[1]).is_file()
    mtime = case_path(tmp_path, CASES[0]).stat().st_mtime_ns
    resumed = run_sweep("quick", 1, tmp_path, CASES, backend="cpu", overrides=TINY_OVERRIDES)
    assert case_path(tmp_path, CASES[0]).stat().st_mtime_ns == mtime  # the finished case was skipped
    with h5py.File(case_path(tmp_path, CASES[1]), "r") as h5:
        assert h5["meta"].attrs["legs"] == 2
        legs = json.loads(h5["meta"].attrs["legs_json"])
        assert [(g["leg"], g["from_iteration"], g["backend"]) for g in legs] == [(1, 0, "cpu"), (2, 40, "cpu")]
        np.testing.assert_array_equal(h5["timeseries/iteration"][:], np.arange(len(h5["timeseries/iteration"])))
    assert not checkpoint_path(tmp_path, CASES[1]).exists()
    pd.testing.assert_frame_equal(resumed.drop(columns=VARYING), reference.drop(columns=VARYING), check_exact=True)


def test_case_stopped_by_a_callback_is_not_finished(tmp_path):
    """A callback that stops the run at record 30 (before the end time) leaves the case unfinished: a one-line
    error, no file under the final name, the partial file says finished = False; the next run finishes it."""
    case = CASES[0]

    def halt(sim):
        if sim.model.iteration >= 30 and not (tmp_path / "resumed").exists():
            sim.stop("halted by a test callback")

    with pytest.raises(InputError, match=f"case {case}: stopped before its end time .halted by a test callback."):
        run_case(case, "quick", 1, tmp_path, backend="cpu", overrides=TINY_OVERRIDES,
                 callbacks={"halt": (halt, 10)}, checkpoint_schedule=IterationInterval(20))
    assert not is_finished(case_path(tmp_path, case)) and not case_path(tmp_path, case).exists()
    with h5py.File(case_path(tmp_path, case).with_name(f"{case}.partial.h5"), "r") as h5:
        assert not h5["meta"].attrs["finished"] and h5["timeseries/iteration"][-1] == 30
    (tmp_path / "resumed").touch()
    path = run_case(case, "quick", 1, tmp_path, backend="cpu", overrides=TINY_OVERRIDES,
                    callbacks={"halt": (halt, 10)})
    assert is_finished(path)
    with h5py.File(path, "r") as h5:
        assert h5["meta"].attrs["legs"] == 2


def test_a_truncated_checkpoint_restarts_the_case_and_is_kept(tiny_sweep, tmp_path, caplog):
    """Killed after its checkpoint at record 20, the checkpoint cut to half its bytes: the rerun warns, keeps the
    checkpoint as *.unreadable-1 and runs the case from the start to the uninterrupted table."""
    _, reference = tiny_sweep
    case = CASES[0]

    def kill(sim):
        if sim.model.iteration >= 30:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep("quick", 1, tmp_path, [case], backend="cpu", overrides=TINY_OVERRIDES,
                  callbacks={"kill": (kill, 10)}, checkpoint_schedule=IterationInterval(20))
    chk = checkpoint_path(tmp_path, case)
    data = chk.read_bytes()
    chk.write_bytes(data[: len(data) // 2])
    with caplog.at_level("WARNING"):
        table = run_sweep("quick", 1, tmp_path, [case], backend="cpu", overrides=TINY_OVERRIDES)
    assert "the case starts again from the beginning" in caplog.text
    assert chk.with_name(chk.name + ".unreadable-1").read_bytes() == data[: len(data) // 2]
    with h5py.File(case_path(tmp_path, case), "r") as h5:
        assert h5["meta"].attrs["legs"] == 1
    pd.testing.assert_frame_equal(table.drop(columns=VARYING), reference.drop(columns=VARYING).iloc[:1],
                                  check_exact=True)


def test_a_foreign_file_in_a_case_place_is_kept_and_a_broken_result_named(tmp_path, caplog):
    from iceresist.sweep import keep_foreign_file

    path = case_path(tmp_path, CASES[0])
    path.parent.mkdir(parents=True)
    path.write_bytes(b"\x89HDF not really" * 10)
    with caplog.at_level("WARNING"):
        keep_foreign_file(path)
    assert not path.exists() and "not a case result of iceresist" in caplog.text
    assert path.with_name(path.name + ".unreadable-1").read_bytes() == b"\x89HDF not really" * 10
    with h5py.File(path, "w") as h5:                       # marked finished, holds nothing
        h5.create_group("meta").attrs.update({"finished": True, "case": CASES[0]})
    with pytest.raises(InputError, match="marked finished but not a readable case result.*move it away"):
        sweep_table(tmp_path)


def test_a_second_sweep_into_a_locked_folder_is_refused(tmp_path):
    from iceresist.sweep import folder_lock

    tmp_path.joinpath("s").mkdir()
    lock = folder_lock(tmp_path / "s")
    try:
        with pytest.raises(InputError, match="--output: another sweep is running in"):
            run_sweep("quick", 1, tmp_path / "s", [CASES[0]], backend="cpu", overrides=TINY_OVERRIDES)
    finally:
        lock.release()
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [".sweep.lock"]


def test_checkpoint_of_another_scene_is_not_continued(tmp_path):
    """A partial case whose scene has changed since (here: the channel length) runs again from its start."""
    case = CASES[0]

    def kill(sim):
        if sim.model.iteration >= 30:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_case(case, "quick", 1, tmp_path, backend="cpu", overrides=TINY_OVERRIDES,
                 callbacks={"kill": (kill, 10)}, checkpoint_schedule=IterationInterval(20))
    assert checkpoint_path(tmp_path, case).is_file()
    other = {**TINY_OVERRIDES, "run": {"end_time_s": 0.1}}
    path = run_case(case, "quick", 1, tmp_path, backend="cpu", overrides=other)
    with h5py.File(path, "r") as h5:
        assert h5["meta"].attrs["legs"] == 1
        assert h5["meta"].attrs["time_s"] == pytest.approx(0.1, abs=0.003)
    assert not checkpoint_path(tmp_path, case).exists()


def test_ice_free_width_reads_the_ice_level_not_the_still_level():
    """Ice drawn down 3-9 cm below the still level (as in tier 2), cubes pressed under the lane, a few rafted:
    the width is that of the lane between the floating cubes (2 x (0.40 - 0.0205) m)."""
    cube, centre, still = 0.041, 0.695, 0.9
    rows = []
    for i, x in enumerate(np.arange(3.425, 4.2, 0.05)):
        level = still - 0.03 - 0.06 * (x - 3.4) / 0.8 - 0.0185  # the floating cubes' centres, lower towards the bow
        for k, y in enumerate(np.concatenate([-np.arange(0.40, 0.676, 0.05), np.arange(0.40, 0.676, 0.05)])):
            rows.append((x, centre + y, level + (cube if (i + k) % 13 == 0 else 0.0)))  # 1 in 13 rafted
        rows += [(x, centre + y, level - 0.25) for y in (-0.1, 0.0, 0.1)]  # pressed under the hull
    p = np.array(rows)
    expected = 2 * (0.40 - cube / 2)
    assert ice_free_width_m(p, (3.4, 4.2), centre, cube, 1.39) == pytest.approx(expected, abs=1e-9)
    # the still-level reading this replaces: no cube centre within one edge of 0.9 m, so the whole channel
    assert (p[:, 2] <= still - cube).mean() > 0.9
    # an empty slice reads the whole channel
    assert ice_free_width_m(p, (5.0, 5.1), centre, cube, 1.39) == pytest.approx(1.39)


def test_finished_case_of_another_preset_version_is_refused(tiny_sweep, tmp_path):
    """A finished case whose scene is not what the preset gives now (here its stored water depth edited to
    0.9 m) stops the sweep before anything runs: one line naming the file and the first differing line, the case
    file unchanged, no sweep.json written."""
    import shutil

    out, _ = tiny_sweep
    (tmp_path / "cases").mkdir()
    path = case_path(tmp_path, CASES[0])
    shutil.copy(case_path(out, CASES[0]), path)
    with h5py.File(path, "r+") as h5:
        text = str(h5["meta"].attrs["scene_toml"])
        depth = next(line for line in text.splitlines() if line.startswith("water_depth_m"))
        h5["meta"].attrs["scene_toml"] = text.replace(depth, "water_depth_m = 0.9")
    before = path.read_bytes()
    with pytest.raises(InputError) as e:
        run_sweep("quick", 1, tmp_path, CASES, backend="cpu", overrides=TINY_OVERRIDES)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{path}: finished with another scene than this preset gives now")
    assert f"'water_depth_m = 0.9' then, '{depth}' now" in msg and "another --output folder" in msg
    assert path.read_bytes() == before and not (tmp_path / "sweep.json").exists()
    assert not case_path(tmp_path, CASES[1]).with_name(f"{CASES[1]}.partial.h5").exists()


def test_refusals(tmp_path):
    with pytest.raises(InputError, match="unknown case"):
        run_sweep("quick", 1, tmp_path, ["A-c99-v1.0"])
    with pytest.raises(InputError, match="unknown preset"):
        run_sweep("fast", 1, tmp_path)
    with pytest.raises(InputError, match="--tier"):
        run_sweep("quick", 3, tmp_path)


@pytest.mark.parametrize("cases", ["", ",", " , "])
def test_no_cases_is_refused_before_anything_is_written(tmp_path, cases):
    with pytest.raises(InputError, match="--cases: no case named; give 'all' or case names such as A-c50-v1.0"):
        run_sweep("quick", 1, tmp_path / "s", cases)
    assert not (tmp_path / "s").exists()


def test_output_that_is_a_file_or_under_one_is_refused(tmp_path):
    (tmp_path / "f").write_text("keep")
    for out, why in ((tmp_path / "f", "is a file, not a folder"), (tmp_path / "f" / "s", "which is a file")):
        with pytest.raises(InputError, match=f"--output: .*{why}"):
            run_sweep("quick", 1, out, ["A-c68-v1.0"])
    assert (tmp_path / "f").read_text() == "keep"


def test_cuda_without_a_gpu_names_the_flag(tmp_path, monkeypatch):
    from iceresist.backends import jit

    monkeypatch.setattr(jit, "cuda_available", lambda: False)
    monkeypatch.setattr(jit, "_HOST_STAND_IN", False)
    with pytest.raises(InputError, match="--backend: backend 'cuda' asked for but no CUDA GPU is visible"):
        run_sweep("quick", 1, tmp_path / "s", ["A-c68-v1.0"], backend="cuda")
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("text", ["{bad", "[1, 2]", "\udcff\udcfe"])
def test_a_corrupt_sweep_json_names_the_file_and_is_kept(tmp_path, text):
    out = tmp_path / "s"
    out.mkdir()
    (out / "sweep.json").write_bytes(text.encode("utf-8", "surrogateescape"))
    before = (out / "sweep.json").read_bytes()
    with pytest.raises(InputError, match="sweep.json: not a sweep description"):
        run_sweep("quick", 1, out, ["A-c68-v1.0"])
    assert (out / "sweep.json").read_bytes() == before


def test_cli_errors_exit_2(tmp_path, capsys):
    import argparse

    from iceresist.sweep import add_sweep_arguments

    p = add_sweep_arguments(argparse.ArgumentParser())
    for argv in (["--cases", "nope"], ["--preset", "huge"], ["--tier", "3"]):
        args = p.parse_args(argv + ["--output", str(tmp_path / "s")])
        with pytest.raises(InputError):
            args.func(args)


def test_report_is_self_contained(tiny_sweep):
    from reports.report import write_report

    out, _ = tiny_sweep
    html, pdf = write_report(out)
    text = html.read_text()
    assert text.count("data:image/png;base64,") == 4
    assert "src=\"http" not in text and "A-c68-v1.0" in text and "FSICR" in text
    assert "Bow B above Bow A" in text and "rises with ship speed" in text and "not run (" in text
    assert "cells per cube (finest)" in text and "grid-converged" in text       # the run table's resolution
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 10_000


def test_report_reads_the_cases_and_leaves_sweep_csv_as_the_sweep_wrote_it(tiny_sweep):
    """``iceresist report`` builds its table from the case files through post and writes no sweep.csv: the
    file keeps its bytes and its modification time."""
    import os

    from reports.report import write_report

    out, _ = tiny_sweep
    csv = out / "sweep.csv"
    before, stat = csv.read_bytes(), csv.stat()
    os.utime(csv, ns=(stat.st_atime_ns, stat.st_mtime_ns - 10**9))  # a rewrite within the same tick shows too
    mtime_ns = csv.stat().st_mtime_ns
    write_report(out)
    sweep_table(out)
    assert csv.read_bytes() == before and csv.stat().st_mtime_ns == mtime_ns


def test_interval_notes_are_table_data_not_log_lines(tiny_sweep, caplog):
    """What limits a case's interval (a window short against tau_int, batches shorter than 5 tau_int, no
    steadiness check) is said once, in the row's ``note``, and nothing is logged at WARNING or above."""
    import logging

    out, table = tiny_sweep
    with caplog.at_level(logging.WARNING):
        again = sweep_table(out)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert list(again.note) == list(table.note)
    for row in again.itertuples():
        fallback = row.ci_method != "batch means"
        assert ("using 5 batches" in row.note) == fallback
        assert row.note.count("likely too narrow") <= 1
    back = pd.read_csv(out / "sweep.csv", keep_default_na=False)
    assert list(back.note) == list(table.note)


def test_preset_note_names_what_the_quick_tiers_trade_away():
    from iceresist.post.sweeptable import preset_note

    tier1, tier2 = preset_note("quick", 1), preset_note("quick", 2)
    assert tier1.startswith("Quick preset: a 1.39 m long channel") and "grid" not in tier1
    assert tier2.startswith(tier1) and "3 cells per 41 mm cube" in tier2 and "Not grid-converged" in tier2
    assert "``" not in tier2 and ":mod:" not in tier2 and "  " not in tier2
    assert preset_note("paper", 2) == ""
    from iceresist.scene.case_scenes import FIDELITIES, TIER2

    # the notes are data beside the presets: they name the presets' own grid and channel
    assert " x ".join(map(str, TIER2["quick"]["cells"])) + " = " in tier2
    assert f"1.39 m / {round(1.39 / TIER2['quick']['dx_m'])} = {1e3 * TIER2['quick']['dx_m']:.1f} mm" in tier2
    assert f"a {FIDELITIES['quick']['channel_length_m']} m long channel" in tier1


def test_report_refuses_missing_folder(tmp_path):
    from reports.report import write_report

    with pytest.raises(InputError, match="no such sweep folder"):
        write_report(tmp_path / "missing")
    with pytest.raises(InputError, match="not a sweep folder"):
        write_report(tmp_path)


@pytest.mark.parametrize("argv, needle", [
    (["--cases", ""], "--cases: no case named"),
    (["--cases", ","], "--cases: no case named"),
    (["--cases", "A-c68-v1.0", "--output", "FILE"], "--output: FILE is a file, not a folder"),
    (["--cases", "A-c68-v1.0", "--amr"], "--amr: refined levels are a tier-2 tank; add --tier 2"),
])
def test_sweep_command_refusals_are_one_line_exit_2(tmp_path, capsys, monkeypatch, argv, needle):
    from iceresist import cli

    monkeypatch.chdir(tmp_path)
    (tmp_path / "FILE").write_text("keep")
    argv = argv if "--output" in argv else argv + ["--output", "out"]
    rc = cli.main(["sweep", *argv, "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and needle in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FILE"] and (tmp_path / "FILE").read_text() == "keep"
