"""``python -m fsicr``: the FSICR calculator's command line."""

from fsicr.cli import main

raise SystemExit(main())
