"""``python -m iceresist.validate``: the same as ``iceresist validate`` (the command line composes the report)."""

import sys

from iceresist.cli import main

raise SystemExit(main(["validate", *sys.argv[1:]]))
