"""``iceresist validate [--quick|--full] [--cases a,b] [--out DIR] [--backend cpu|cuda] [--stability]``.

Runs the resolution ladders of the reference cases (:mod:`iceresist.validate.ladder`) into ``DIR/ladder.csv``
(a rerun skips finished rungs) and prints their error against run time (:mod:`iceresist.post.convergence`).
``--stability`` runs the stability matrix of :mod:`iceresist.validate.stability` instead. ``iceresist validate``
(:mod:`iceresist.cli`) then draws the report from the files (:mod:`reports.validation`). Bad flags: one line
on stderr, exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import sys

from fsicr.cliparser import OneLineParser
from iceresist.backends.jit import resolve_target
from iceresist.console import configure_logging
from iceresist.errors import InputError
from iceresist.io.paths import check_output_dir
from iceresist.post.convergence import markdown_table
from iceresist.sweep import set_threads
from iceresist.validate.ladder import run_ladders
from iceresist.validate.stability import main as stability_main

log = logging.getLogger(__name__)


def add_validate_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``iceresist validate``; sets ``func=cmd_validate``."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", dest="quick", action="store_true", default=True,
                   help="small ladders, minutes on a 2-core CPU (default)")
    g.add_argument("--full", dest="quick", action="store_false", help="the full ladders (a GPU run)")
    p.add_argument("--cases", default="all", help="comma-separated case names or 'all'")
    p.add_argument("--out", metavar="DIR", help="output folder (default runs/validate-quick or runs/validate-full)")
    p.add_argument("--backend", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--precision", choices=("float32", "float64"), default="float32")
    p.add_argument("--threads", type=int, help="CPU threads of the numba kernels")
    p.add_argument("--stability", action="store_true", help="run the stability matrix instead of the ladders")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_validate)
    return p


def output_dir(args) -> str:
    """The validation folder of parsed arguments (``--out``, else runs/validate-quick or runs/validate-full)."""
    return args.out or f"runs/validate-{'quick' if args.quick else 'full'}"


def cmd_validate(args) -> int:
    """Run the ladders (or ``--stability`` the matrix) into the files of :func:`output_dir`."""
    out = output_dir(args)
    set_threads(args.threads)
    resolve_target(args.backend, "--backend")       # a backend this machine lacks is refused before a file is made
    check_output_dir(out, "--out")
    if args.stability:
        argv = ["--quick" if args.quick else "--full", "--out", out, "--backend", args.backend]
        return int(stability_main(argv) or 0)
    table = run_ladders(out, quick=args.quick, cases=args.cases, backend=args.backend, precision=args.precision,
                        progress=not args.no_progress)
    if table.empty:
        raise InputError(f"{out}: no rung finished; see the errors above")
    print(markdown_table(table))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="iceresist validate", description="Error against run time of the reference cases.")
    p.add_argument("-v", "--verbose", action="store_true", help="debug lines of iceresist itself")
    return add_validate_arguments(p)


def main(argv=None) -> int:
    """``iceresist validate`` as a function: returns the exit status (2 for bad flags or input)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:           # --help (0) or a usage error (2, one line already on stderr)
        return int(exc.code or 0)
    configure_logging(verbose=args.verbose)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"iceresist validate: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("iceresist validate: interrupted; the rungs already in ladder.csv are kept", file=sys.stderr)
        return 130
