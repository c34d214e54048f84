"""Benchmark dispatcher: ``python -m validation.bench NAME [--backend cpu|cuda] [--precision ...] [--n N]
[--steps S] [--json]`` (docs/PERFORMANCE.md).

NAME selects the module ``validation.bench_NAME``, which provides ``add_arguments(parser)`` and
``run(args) -> list[dict]`` (or an iterator of rows, each printed as it comes with ``--json``). With ``--json`` every
measurement is printed as one JSON object per line; otherwise as a table. Interrupted (Ctrl-C, SIGINT at a
deadline), the rows measured so far are printed and one line says so; exit status 130.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys

from tabulate import tabulate

#: Benchmarks with a module of their own; any ``validation.bench_NAME`` module is found as well.
REGISTRY = {"lbm": "validation.bench_lbm"}

COLUMNS = ("name", "backend", "precision", "cells", "steps", "seconds", "mlups", "bandwidth_GBps",
           "compile_seconds")


def _module(name):
    modname = REGISTRY.get(name, f"validation.bench_{name}")
    try:
        return importlib.import_module(modname)
    except ModuleNotFoundError as exc:
        if exc.name != modname:
            raise
        raise SystemExit(f"unknown benchmark {name!r}; known: {', '.join(sorted(REGISTRY))}") from None


def common_parser(name: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"python -m validation.bench {name}")
    p.add_argument("--backend", choices=("auto", "cpu", "cuda"), default="cpu")
    p.add_argument("--precision", choices=("float32", "float64"), action="append",
                   help="repeatable; default: both")
    p.add_argument("--n", type=int, default=64, help="cells per side of the cubic case")
    p.add_argument("--steps", type=int, default=20, help="timed steps per measurement")
    p.add_argument("--json", action="store_true", help="one JSON object per measurement")
    return p


def format_table(rows) -> str:
    """The measurements as a plain text table (tabulate, as pandas' ``to_markdown``): the usual columns first,
    floats to 4 significant digits, a key a row lacks left blank."""
    cols = [c for c in COLUMNS if any(c in r for r in rows)]
    cols = list(dict.fromkeys(cols + [c for r in rows for c in r]))
    return tabulate([[r.get(c) for c in cols] for r in rows], headers=cols, tablefmt="plain", floatfmt=".4g",
                    missingval="")


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-"):
        raise SystemExit(f"usage: python -m validation.bench NAME [options]; NAME in {', '.join(sorted(REGISTRY))}")
    name = argv.pop(0)
    mod = _module(name)
    parser = common_parser(name)
    mod.add_arguments(parser)
    args = parser.parse_args(argv)
    args.precision = args.precision or ["float32", "float64"]
    from iceresist.errors import InputError

    rows, status = [], None
    try:
        for r in mod.run(args):     # a list, or a generator whose rows are printed as they come (with --json)
            rows.append(r)
            if args.json:
                print(json.dumps(r), flush=True)
    except InputError as exc:       # bad input: one line, exit status 2 (as the iceresist command)
        print(f"validation.bench {name}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:       # cut off (a deadline): the rows measured so far stand, one line says so
        print(f"validation.bench {name}: interrupted after {len(rows)} row{'' if len(rows) == 1 else 's'}",
              file=sys.stderr)
        status = 130
    if not args.json and rows:
        print(format_table(rows))
    return status if status is not None else getattr(args, "exit_status", 0)


if __name__ == "__main__":
    sys.exit(main())
