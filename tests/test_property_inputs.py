"""Property-based refusals: ship files, scene files and command-line flags with values drawn at random (wrong
types, signs, magnitudes, inf, NaN, text, lists) give exit status 0 or 2 and never a traceback, and write nothing
outside the output folder they name.

The engine's stepping is replaced by a stub (these tests are about input handling; a scene that passes every check
would otherwise spend its kernel compilation here): everything up to and including the model's construction runs.
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
import tomllib
from pathlib import Path
from types import SimpleNamespace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fsicr import cli as fsicr_cli
from iceresist import cli as iceresist_cli
from iceresist import run as run_module
from iceresist.scene import preset_text

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
#: The calculator answers in milliseconds: many more examples.
FAST = settings(max_examples=400, deadline=None)

#: Values a user might mistype: numbers of every size and sign, non-numbers, text, lists, empty things.
ODD_VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10 ** 30, max_value=10 ** 30),
    st.sampled_from([0, -1, 1e-320, 1e-300, 1e-30, 1e30, 1e200, 1e308, -1e308, "", " ", "abc", "1e999", "nan", True,
                     False]),
    st.text(max_size=12),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
)


def _toml_value(v) -> str:
    """A TOML literal for ``v`` (floats TOML cannot spell as inf/nan use its own words)."""
    import tomli_w

    if isinstance(v, float) and v != v:
        return "nan"
    if isinstance(v, float) and v in (float("inf"), float("-inf")):
        return "inf" if v > 0 else "-inf"
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return tomli_w.dumps({"v": v})[len("v = "):-1]


def _replace_key(text: str, section: str, key: str, value) -> str:
    """``text`` with ``key`` of ``[section]`` set to ``value`` (the line replaced, or added under the header)."""
    lines, out, current, done = text.splitlines(), [], None, False
    for line in lines:
        stripped = line.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            if current == section and not done:
                out.append(f"{key} = {_toml_value(value)}")
                done = True
            current = stripped[1:-1]
        elif current == section and stripped.split("=")[0].strip() == key:
            out.append(f"{key} = {_toml_value(value)}")
            done = True
            continue
        out.append(line)
    if not done:
        out += ([f"[{section}]"] if current != section else []) + [f"{key} = {_toml_value(value)}"]
    return "\n".join(out) + "\n"


def _run(main, argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 2
    return rc, err.getvalue()


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


# -- ship files and fsicr flags -------------------------------------------------------------------------
SHIP = Path(__file__).resolve().parents[1] / "fsicr" / "ships" / "b063_bow_a.toml"
SHIP_KEYS = sorted(k for k, v in tomllib.loads(SHIP.read_text()).items() if not isinstance(v, dict))


@FAST
@given(key=st.sampled_from(SHIP_KEYS), value=ODD_VALUES)
def test_ship_files_with_odd_values_exit_0_or_2(key, value):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ship.toml"
        path.write_text(_replace_key("[s]\n" + SHIP.read_text(), "s", key, value).replace("[s]\n", "", 1))
        rc, err = _run(fsicr_cli.main, ["resistance", "--class", "IA", "--ship", str(path), "--json"])
        assert rc in (0, 2), err
        assert "Traceback" not in err
        if rc == 2:
            assert err.count("\n") == 1 and err.startswith("fsicr: error: ")
        assert _files(Path(tmp)) == {path}


FLAGS = ["--L", "--B", "--T", "--LPAR", "--LBOW", "--Awf", "--alpha", "--phi1", "--phi2", "--Dp", "--lower-T",
         "--lower-B", "--propellers", "--class"]


@FAST
@given(flag=st.sampled_from(FLAGS), value=st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                                                    st.text(max_size=10),
                                                    st.sampled_from(["", "-0", "1e400", "1e200", "1e-300", "1e308"])))
def test_fsicr_flags_with_odd_values_exit_0_or_2(flag, value):
    if value.startswith("-") and value not in ("-0",):
        value = " " + value          # argparse would read a leading '-' as a flag
    rc, err = _run(fsicr_cli.main, ["power", "--ship", str(SHIP), "--class", "IA", "--Dp", "5.0", flag, value])
    assert rc in (0, 2), err
    assert "Traceback" not in err


# -- scene files and iceresist run -------------------------------------------------------------------------
POISEUILLE = preset_text("poiseuille")
SCENE_KEYS = [("domain", "dx_m"), ("domain", "size_m"), ("fluid", "nu_m2_s"), ("fluid", "rho_kg_m3"),
              ("fluid", "body_force_N_m3"), ("fluid", "operator"), ("numerics", "u_max_m_s"), ("numerics", "mach"),
              ("numerics", "precision"), ("numerics", "dt_s"), ("run", "end_time_s"), ("run", "steps"),
              ("output", "fields_every_s"), ("output", "directory"), ("output", "timeseries_every_steps"),
              ("scene", "name"), ("scene", "units")]


@pytest.fixture
def no_stepping(monkeypatch):
    """run_model replaced by a stub: the input checks and the model's construction run, the stepping does not."""
    def stub(model, scene, path, checkpoint_path=None, **kw):
        return SimpleNamespace(sim=SimpleNamespace(diverged=False))

    monkeypatch.setattr(run_module, "run_model", stub)


@SETTINGS
@given(where=st.sampled_from(SCENE_KEYS), value=ODD_VALUES)
def test_scene_files_with_odd_values_exit_0_or_2_and_write_only_into_the_output(where, value, no_stepping):
    section, key = where
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        scene = root / "s.toml"
        scene.write_text(_replace_key(POISEUILLE, section, key, value))
        before = _files(root)
        cwd = os.getcwd()
        os.chdir(root)
        try:
            rc, err = _run(iceresist_cli.main, ["run", str(scene), "--output", str(root / "out"), "--no-progress"])
        finally:
            os.chdir(cwd)
        assert rc in (0, 2), err
        assert "Traceback" not in err
        new = _files(root) - before
        assert all(root / "out" in p.parents for p in new), new
