"""FSICR command line: printed terms and warnings, JSON, the paper comparison, one-line errors with status 2."""

import json
import subprocess
import sys

import pytest

from fsicr.cli import main

BOW_A = "fsicr/ships/b063_bow_a.toml"
SHIP_FLAGS = ["--L", "76", "--B", "17.5", "--T", "11", "--LPAR", "45.7", "--LBOW", "15.15", "--Awf", "96.25",
              "--alpha", "30", "--phi1", "30", "--phi2", "30"]


def run(capsys, argv):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_resistance_of_bow_a_prints_every_term_and_its_warnings(capsys):
    code, out, err = run(capsys, ["resistance", "--ship", BOW_A, "--class", "IA"])
    assert code == 0 and err == ""
    for text in ("psi", "C_mu   before clamp", "C_psi", "H_F", "(L T / B^2)^3 before clamp",
                 "C1     consolidated layer", "C2     consolidated layer", "C3 C_mu (H_F + H_M)^2",
                 "C4 LPAR H_F^2", "C5 (L T / B^2)^3 Awf / L", "bound <= 20 ACTIVE"):
        assert text in out, text
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("R_CH (FSICR 2017)"))
    assert float(line.split()[-1]) == pytest.approx(293.0, rel=5e-3)
    assert "292.22" in line
    assert "292.57" in out  # unclamped value beside it
    assert "49.1066" in out and "0.5079" in out and "0.1930" in out and "20.3419" in out
    assert "233.43" in out and "37.89" in out and "20.90" in out
    assert "Warnings (2)" in out
    assert "phi2 = 30 deg is outside the FSICR 2017 range of validity 45-90 deg" in out
    assert "Awf/(L*B) = 0.07237 is outside the FSICR 2017 range of validity 0.09-0.27" in out


def test_resistance_json_parses(capsys):
    code, out, _ = run(capsys, ["resistance", "--ship", BOW_A, "--json"])
    assert code == 0
    d = json.loads(out)
    assert d["ice_class"] == "IA"  # from the ship file
    assert d["r_ch_kN"] == pytest.approx(292.216, abs=1e-3)
    terms = d["waterlines"][0]["terms"]
    assert terms["C3_term_N"] + terms["C4_term_N"] + terms["C5_term_N"] == pytest.approx(d["r_ch_N"])
    assert len(d["warnings"]) == 2


def test_flags_alone_and_flags_override_the_file(capsys):
    code, out, _ = run(capsys, ["resistance", "--class", "IA", "--json", *SHIP_FLAGS])
    assert code == 0 and json.loads(out)["r_ch_kN"] == pytest.approx(292.216, abs=1e-3)
    code, out, _ = run(capsys, ["resistance", "--ship", BOW_A, "--phi2", "45", "--json"])
    assert code == 0 and json.loads(out)["r_ch_kN"] == pytest.approx(354.538, abs=1e-3)  # Bow B's phi2


def test_lower_waterline_from_flags(capsys):
    code, out, _ = run(capsys, ["resistance", "--ship", BOW_A, "--lower-T", "8", "--json"])
    d = json.loads(out)
    assert code == 0 and [w["waterline"] for w in d["waterlines"]] == ["upper", "lower"]
    assert d["waterlines"][1]["ship"]["T_m"] == 8.0
    assert d["r_ch_N_by_waterline"]["lower"] < d["r_ch_N_by_waterline"]["upper"]


def test_power_text_and_json(capsys):
    code, out, _ = run(capsys, ["power", "--ship", BOW_A, "--class", "IA", "--lower-T", "9"])
    assert code == 0
    assert "Ke = 2.03" in out and "REQUIRED ENGINE OUTPUT:       1536 kW" in out
    assert "upper ice waterline" in out and "lower ice waterline" in out
    code, out, _ = run(capsys, ["power", "--ship", BOW_A, "--propellers", "2", "--propulsion", "fp", "--json"])
    d = json.loads(out)
    assert code == 0 and d["Ke"] == 1.60
    assert d["required_kW"] == pytest.approx(1.60 * 292.2164602632128**1.5 / 6.6)


def test_power_class_minimum(capsys):
    code, out, _ = run(capsys, ["power", "--ship", BOW_A, "--class", "IC", "--Dp", "7.5", "--propellers", "3",
                                "--json"])
    d = json.loads(out)
    assert code == 0 and d["required_kW"] == 1000.0 and d["governing"] == "class minimum (IC)"


def test_compare_table(capsys):
    code, out, err = run(capsys, ["compare"])
    assert code == 0 and err == ""
    for text in ("Bow A", "Bow B", "293", "355", "188", "330", "1.76", "1.21", "292.2", "354.5",
                 "-0.27", "-0.13", "292.6", "354.9", "1.213", "LBOW = (L - LPAR)/2"):
        assert text in out, text


def test_compare_json(capsys):
    code, out, _ = run(capsys, ["compare", "--json"])
    d = json.loads(out)
    assert code == 0
    for case in d["cases"]:
        assert abs(case["diff_pct"]) < 0.5 and abs(case["diff_unclamped_pct"]) < 0.5
    assert d["ratios_bow_b_over_bow_a"]["ours"] == pytest.approx(1.2133, abs=1e-4)
    assert d["ratios_bow_b_over_bow_a"]["paper_simulated"] == 1.76


def test_iceresist_demo_prints_the_comparison(capsys, tmp_path, monkeypatch):
    """`iceresist demo` = FSICR comparison + quick sweep + report; shrunk to one tiny case here."""
    import iceresist.cli as cli
    from iceresist.cli import main as iceresist_main
    from iceresist.sweep import TINY_OVERRIDES

    real_demo = cli.demo
    monkeypatch.setattr(cli, "demo", lambda out, **kw: real_demo(out, cases=["A-c68-v1.0"],
                                                                 overrides=TINY_OVERRIDES, **kw))
    assert iceresist_main(["demo", "--output", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert "Bow B" in out and "A-c68-v1.0" in out and "report.html" in out
    assert iceresist_main(["demo", "--json", "--output", str(tmp_path / "d")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["command"] == "demo"
    bow_a = next(c for c in doc["fsicr"]["cases"] if c["case"] == "Bow A")
    assert bow_a["ours_kN"] == pytest.approx(293.0, rel=0.005)
    assert [r["case"] for r in doc["sweep"]] == ["A-c68-v1.0"]
    assert (tmp_path / "d" / "report.html").is_file()


def test_python_dash_m_fsicr():
    proc = subprocess.run([sys.executable, "-m", "fsicr", "ships"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "b063_bow_a" in proc.stdout


def _file(tmp_path, text):
    path = tmp_path / "ship.toml"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))    # surrogate escapes: bytes that are not UTF-8
    return str(path)


GOOD = """L_m = 76.0\nB_m = 17.5\nT_m = 11.0\nLPAR_m = 45.7\nLBOW_m = 15.15\nAwf_m2 = 96.25
alpha_deg = 30.0\nphi1_deg = 30.0\nphi2_deg = 30.0\n"""


@pytest.mark.parametrize(
    "argv, message",
    [
        (["resistance", "--ship", BOW_A, "--L", "-5"], "L_m (--L): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--L", "0"], "L_m (--L): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--L", "1e200"], "L_m (--L): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--T", "1e300"], "T_m (--T): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--B", "1e-300"], "B_m (--B): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--L", "1e308", "--json"], "L_m (--L): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--Awf", "1e300"], "Awf_m2 (--Awf): must be in (0, 1e+06] m^2"),
        (["power", "--ship", BOW_A, "--Dp", "1e-320"], "Dp_m (--Dp): propeller diameter must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--class", ""], "--class: empty; give one of IA Super, IA, IB, IC"),
        (["resistance", "--ship", BOW_A, "--lower-T", "99"], "lower_T_m (--lower-T): the lower ice waterline (99 m) "
                                                             "lies deeper than the upper one (T_m (--T) = 11 m)"),
        (["resistance", "--ship", BOW_A, "--alpha", "95"], "alpha_deg (--alpha): angle must be in (0, 90] degrees"),
        (["resistance", "--ship", BOW_A, "--phi2", "0"], "phi2_deg (--phi2): angle must be in (0, 90] degrees"),
        (["resistance", "--ship", BOW_A, "--lower-T", "-1"], "lower_T_m (--lower-T): must be in [0.01, 1000] m"),
        (["resistance", "--ship", BOW_A, "--class", "ID"], "unknown class 'ID'; allowed: IA Super, IA, IB, IC"),
        (["resistance", "--class", "IA", *SHIP_FLAGS[2:]], "missing field 'L_m' (--L)"),
        (["resistance", "--ship", BOW_A, "--L", "abc"], "argument --L: must be a number, got 'abc'"),
        (["resistance", "--ship", "no/such/ship.toml"], "ship file 'no/such/ship.toml': not found"),
        (["resistance", *SHIP_FLAGS], "ice class missing: give --class"),
        (["power", "--class", "IA", *SHIP_FLAGS], "Dp_m (--Dp): propeller diameter missing"),
        (["power", "--ship", BOW_A, "--propellers", "4"], "n_propellers (--propellers): must be 1, 2 or 3"),
        (["power", "--ship", BOW_A, "--propulsion", "sail"], "argument --propulsion: invalid choice: 'sail'"),
        (["nonsense"], "invalid choice: 'nonsense'"),
    ],
)
def test_bad_input_gives_one_line_and_status_2(capsys, argv, message):
    code, out, err = run(capsys, argv)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert message in err


@pytest.mark.parametrize(
    "text, message",
    [
        (GOOD.replace("L_m = 76.0", 'L_m = "abc"'), "'L_m' (--L) must be a number, got 'abc'"),
        (GOOD + "draught = 11.0\n", "unknown key 'draught'; allowed keys: name, source, ice_class, L_m"),
        (GOOD.replace("B_m = 17.5\n", ""), "missing field 'B_m' (--B): maximum breadth B [m]"),
        (GOOD + "bulbous_bow = 1\n", "'bulbous_bow' (--bulbous-bow) must be true or false"),
        (GOOD + "[lower_waterline]\nL_m = 70.0\n", "missing field 'lower_waterline.T_m' (--lower-T)"),
        (GOOD + "[lower_waterline]\nT_m = 9.0\nbeam = 3.0\n", "unknown key 'lower_waterline.beam'"),
        (GOOD + "L_m = 80.0\n", "not valid TOML"),
        (GOOD.replace("T_m = 11.0", "T_m = -11.0"), "T_m (--T): must be in [0.01, 1000] m"),
        (GOOD.replace("L_m = 76.0", "L_m = 1e200"), "L_m (--L): must be in [0.01, 1000] m"),
        ("\udcff\udcfe\x00\x01binary", "not a text file (byte 0 is not UTF-8)"),
    ],
)
def test_bad_ship_file_gives_one_line_and_status_2(capsys, tmp_path, text, message):
    code, out, err = run(capsys, ["resistance", "--class", "IA", "--ship", _file(tmp_path, text)])
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert message in err


def test_good_ship_file_with_lower_waterline(capsys, tmp_path):
    path = _file(tmp_path, GOOD + "Dp_m = 6.6\n[lower_waterline]\nT_m = 9.0\nphi2_deg = 45.0\n")
    code, out, _ = run(capsys, ["power", "--class", "IA", "--ship", path, "--json"])
    d = json.loads(out)
    assert code == 0 and set(d["power_by_waterline_kW"]) == {"upper", "lower"}
    assert d["required_kW"] == max(d["power_by_waterline_kW"].values())


def test_fsicr_imports_nothing_from_the_engine():
    code = "import sys, fsicr.cli; bad = [m for m in sys.modules if m.startswith(('iceresist', 'numba'))]; print(bad)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "[]"


def test_every_command_line_uses_the_one_line_parser(capsys):
    """fsicr, iceresist and iceresist validate build their parsers (and subcommands) from fsicr.cliparser; no
    other ArgumentParser subclass is left in the packages."""
    import re
    from pathlib import Path

    import fsicr.cli
    import iceresist.cli
    import iceresist.validate.cli
    from fsicr.cliparser import OneLineParser

    for module, argv in ((fsicr.cli, ["power", "--bogus"]), (iceresist.cli, ["run", "--bogus"]),
                         (iceresist.validate.cli, ["--bogus"])):
        parser = module.build_parser()
        assert type(parser) is OneLineParser, module.__name__
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        err = capsys.readouterr().err
        assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and ": error: " in err, (module, err)
    root = Path(__file__).resolve().parents[1]
    subclasses = [str(f.relative_to(root)) for pkg in ("fsicr", "iceresist", "validation", "reports")
                  for f in sorted((root / pkg).rglob("*.py"))
                  if re.search(r"^class \w+\(argparse\.ArgumentParser\)", f.read_text(encoding="utf-8"), re.M)]
    assert subclasses == ["fsicr/cliparser.py"]
