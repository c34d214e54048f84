"""What the commands print besides their results: log lines, set up once per process.

* INFO lines of iceresist (and of the report and FSICR packages) by default; ``-v`` raises those packages to DEBUG
  and nothing else (numba's own DEBUG logging, hundreds of thousands of lines a minute while kernels compile, needs
  ``--debug-numba``).
* The compile progress lines of :mod:`iceresist.backends.compilelog` are switched on for every command.
* Under MPI one rank speaks: rank 0 logs as one process would; another rank logs only its warnings and errors, each
  marked ``rank N``, and drops those about the scene itself (the same on every rank: they come from rank 0).
"""

from __future__ import annotations

import logging

from iceresist.backends import compilelog

#: The packages ``-v`` raises to DEBUG.
OWN_LOGGERS = ("iceresist", "reports", "fsicr", "validation")
#: Loggers whose lines are about the scene, the same on every rank: only rank 0 says them.
SCENE_LOGGERS = ("iceresist.units", "iceresist.scene", "iceresist.limits", "iceresist.backends.compilelog")
FORMAT = "%(levelname)s %(name)s: %(message)s"


class OtherRank(logging.Filter):
    """On a rank other than 0: drop what rank 0 says too (the scene's lines), mark the rest with the rank."""

    def __init__(self, rank: int):
        super().__init__()
        self.rank = rank

    def filter(self, record: logging.LogRecord) -> bool:
        if any(record.name == n or record.name.startswith(n + ".") for n in SCENE_LOGGERS):
            return False
        if not getattr(record, "_rank_marked", False):
            record.msg = f"rank {self.rank}: {record.msg}"
            record._rank_marked = True
        return True


def configure_logging(verbose: bool = False, numba_debug: bool = False, rank: int = 0) -> None:
    """Log lines on stderr for a command: see the module's docstring. ``rank``: this process's MPI rank."""
    logging.basicConfig(level=logging.INFO, format=FORMAT)
    for name in OWN_LOGGERS:
        logging.getLogger(name).setLevel(logging.DEBUG if verbose else logging.NOTSET)
    logging.getLogger("numba").setLevel(logging.DEBUG if numba_debug else logging.WARNING)
    if rank:
        logging.getLogger().setLevel(logging.WARNING)
        for handler in logging.getLogger().handlers:
            if not any(isinstance(f, OtherRank) for f in handler.filters):
                handler.addFilter(OtherRank(rank))
    compilelog.install()
