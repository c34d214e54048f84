"""``python -m iceresist.validate``: the same as ``iceresist validate``."""

from iceresist.validate.cli import main

raise SystemExit(main())
