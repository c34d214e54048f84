"""Command line: ``iceresist demo | run | sweep | report | steadiness | validate``.

Every subcommand turns bad input into one line on stderr and exit status 2,
with no traceback (:class:`iceresist.errors.InputError`).
"""

from __future__ import annotations

import argparse
import logging
import sys

from fsicr.cli import main as fsicr_main
from fsicr.cliparser import OneLineParser
from fsicr.compare import compare_table2
from fsicr.errors import too_long_path
from iceresist import __version__, parallel
from iceresist.console import configure_logging
from iceresist.errors import InputError
from iceresist.run import add_run_arguments
from iceresist.sweep import add_sweep_arguments, run_sweep
from iceresist.validate.cli import add_validate_arguments, cmd_validate, output_dir
from iceresist.validate.ladder import discover_cases
from reports.report import add_report_arguments, write_report
from reports.steadiness import add_steadiness_arguments
from reports.validation import write_stability_map, write_validation_report

log = logging.getLogger("iceresist")


def demo(out_dir="runs/demo", *, json_output: bool = False, backend: str = "auto", progress: bool = True,
         cases=None, overrides: dict | None = None) -> int:
    """``iceresist demo``: the FSICR comparison of the paper's table 2, the quick tier-1 sweep of every case
    and its report (about 7 minutes on a 2-core x86 VM). ``cases`` and ``overrides`` shrink it (tests).

    The engine runs the sweep into case files and ``sweep.csv`` (:func:`iceresist.sweep.run_sweep`, whose table
    :mod:`iceresist.post` builds from the files); the report reads the same files
    (:func:`reports.report.write_report`). What limits a case's interval is in the table's ``note`` column.
    With ``json_output`` one JSON object is printed: ``{"fsicr": ..., "sweep": [...], "report": {...}}``.
    """
    import json

    rc = 0 if json_output else fsicr_main(["compare"])
    table = run_sweep("quick", 1, out_dir, cases, backend=backend, progress=progress and not json_output,
                      overrides=overrides)
    html, pdf = write_report(out_dir)
    cols = ["case", "mean_force_N", "R_sim_kN", "R_CH_FSICR_kN", "ratio_sim_FSICR"]
    if json_output:
        print(json.dumps({"command": "demo", "fsicr": compare_table2(),
                          "sweep": json.loads(table[cols + ["note"]].to_json(orient="records")),
                          "report": {"html": str(html), "pdf": str(pdf)}}))
    else:
        print("\nQuick tier-1 sweep (DEM with water models), model scale -> full scale by the cubic law")
        print(table[cols].to_string(index=False, float_format="%.4g"))
        print(f"report: {html}\n        {pdf}")
    return rc


def _cmd_demo(args) -> int:
    """The quick tier-1 sweep of the paper's cases, the FSICR comparison and the report (runs/demo). The
    engine's and the report's progress lines stay off the terminal (``--verbose`` shows them); warnings still
    show."""
    loggers = [logging.getLogger(name) for name in ("iceresist", "reports")]
    levels = [lg.level for lg in loggers]
    if not args.verbose:
        for lg in loggers:
            lg.setLevel(logging.WARNING)
    try:
        return demo(args.output, json_output=args.json)
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def _cmd_validate(args) -> int:
    """``iceresist validate``: the ladders (or the stability matrix) into their files, then the report drawn
    from those files (:mod:`reports.validation`)."""
    rc = cmd_validate(args)
    out = output_dir(args)
    if args.stability:
        print(f"stability map: {write_stability_map(out)}")
        return rc
    available, missing = discover_cases()
    references = {name: getattr(mod, "REFERENCE", "") for name, mod in available.items()}
    html, pdf = write_validation_report(out, references=references, missing=missing)
    print(f"report: {html}\n        {pdf}")
    return rc


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="iceresist",
                      description="Ice resistance of a ship in a brash-ice channel (LBM-DEM) beside FSICR.")
    p.add_argument("--version", action="version", version=f"iceresist {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="debug lines of iceresist itself")
    p.add_argument("--debug-numba", action="store_true", help="numba's own debug logging too (very long)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    d = sub.add_parser("demo", help="run the main job on the built-in default scene")
    d.add_argument("--json", action="store_true", help="machine-readable output")
    d.add_argument("--output", default="runs/demo", help="sweep folder for the demo (default: runs/demo)")
    d.set_defaults(func=_cmd_demo)

    r = sub.add_parser("run", help="run one scene file (SCENE.toml or a built-in scene name)",
                       description="Run one scene into <output.directory>/<scene.name>.h5. A first run compiles the "
                                   "kernels its scene needs, a line per kernel: about 2 min on a 2-core CPU for a "
                                   "free-surface scene (iceresist run still_tank), seconds for tier 1; they are kept "
                                   "in ~/.cache/iceresist/kernels (ICERESIST_CACHE) and later runs load them in "
                                   "seconds.")
    add_run_arguments(r)

    s = sub.add_parser("sweep", help="run the paper's ship cases (quick|paper, tier 1|2) into a sweep folder")
    add_sweep_arguments(s)
    rp = sub.add_parser("report", help="write report.html and report.pdf of a sweep folder")
    add_report_arguments(rp)

    st = sub.add_parser("steadiness", help="mean ice force over steps of stem travel through the channel: does it "
                                         "settle? (finished or running case files)")
    add_steadiness_arguments(st)

    v = sub.add_parser("validate", help="error against run time of the reference cases, or (--stability) the "
                                        "stability matrix; report.html and report.pdf")
    add_validate_arguments(v)
    v.set_defaults(func=_cmd_validate)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    root = True
    try:
        rank = parallel.rank() if parallel.launched_by_mpi() else 0
        root = rank == 0       # one rank speaks: the others log their own warnings only and print no errors
        configure_logging(verbose=args.verbose, numba_debug=args.debug_numba, rank=rank)
        return int(args.func(args) or 0)
    except InputError as exc:
        if root:
            print(f"iceresist: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("iceresist: interrupted; files already written are complete", file=sys.stderr)
        return 130
    except OSError as exc:
        if too_long_path(exc) is None:          # only a path no check before caught is still the user's input
            raise
        if root:
            print(f"iceresist: error: {too_long_path(exc)}", file=sys.stderr)
        return 2
    except Exception:
        if parallel.launched_by_mpi() and parallel.world() is not None:
            parallel.abort(parallel.world())       # the other ranks would wait in their next collective call forever
        raise


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
