"""Command line: ``iceresist demo | run | sweep | report | steadiness | validate``.

Every subcommand turns bad input into one line on stderr and exit status 2,
with no traceback (:class:`iceresist.errors.InputError`).
"""

from __future__ import annotations

import argparse
import logging
import sys

from fsicr.cliparser import OneLineParser
from iceresist import __version__
from iceresist.errors import InputError

log = logging.getLogger("iceresist")


def _cmd_demo(args) -> int:
    """The quick tier-1 sweep of the paper's cases, the FSICR comparison and the report (runs/demo)."""
    from iceresist.sweep import demo

    return demo(args.output, json_output=args.json)


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="iceresist",
                      description="Ice resistance of a ship in a brash-ice channel (LBM-DEM) beside FSICR.")
    p.add_argument("--version", action="version", version=f"iceresist {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    d = sub.add_parser("demo", help="run the main job on the built-in default scene")
    d.add_argument("--json", action="store_true", help="machine-readable output")
    d.add_argument("--output", default="runs/demo", help="sweep folder for the demo (default: runs/demo)")
    d.set_defaults(func=_cmd_demo)

    from iceresist.run import add_run_arguments

    r = sub.add_parser("run", help="run one scene file (SCENE.toml or a built-in scene name)")
    add_run_arguments(r)

    from iceresist.sweep import add_sweep_arguments
    from reports.report import add_report_arguments

    s = sub.add_parser("sweep", help="run the paper's ship cases (quick|paper, tier 1|2) into a sweep folder")
    add_sweep_arguments(s)
    rp = sub.add_parser("report", help="write report.html and report.pdf of a sweep folder")
    add_report_arguments(rp)

    from iceresist.steadiness import add_steadiness_arguments

    st = sub.add_parser("steadiness", help="mean ice force over steps of stem travel through the channel: does it "
                                         "settle? (finished or running case files)")
    add_steadiness_arguments(st)

    from iceresist.validate.cli import add_validate_arguments

    v = sub.add_parser("validate", help="error against run time of the reference cases, or (--stability) the "
                                        "stability matrix; report.html and report.pdf")
    add_validate_arguments(v)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"iceresist: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("iceresist: interrupted; files already written are complete", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
