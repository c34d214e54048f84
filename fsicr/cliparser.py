"""The argument parser of every command line of the project (``fsicr``, ``iceresist``, ``iceresist validate``):
argparse that reports a usage error as one line and exit status 2.

It lives in fsicr, the package that imports nothing from the engine, so fsicr stays standalone and iceresist
(which already imports fsicr for the rules comparison) shares it rather than keeping a copy per command line.
"""

from __future__ import annotations

import argparse


class OneLineParser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line (``prog: error: message``) and exit status 2, without
    argparse's usage block; subcommands get the same parser through ``add_subparsers(parser_class=...)``."""

    def error(self, message):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message}\n")
