"""The protocol of a reference case of ``iceresist validate`` and the record of one of its runs.

A case module in :mod:`iceresist.validate.cases` defines::

    NAME: str                     # short identifier, e.g. "standing_wave"
    REFERENCE: str                # what the error is measured against (cite the source)
    def ladder(quick: bool) -> list[dict]
        # parameter sets from coarse to fine (at least three); each holds a "label" (e.g. "16 cells/wavelength")
        # and a "resolution" (cells across the case's characteristic length, used for the observed order)
    def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult

``run`` builds the rung's scene and model and runs them through the one driver
(:func:`iceresist.validate.rung.run_rung`) into ``OUT_DIR/runs/NAME/LABEL.h5`` (``out_dir`` None: a scratch
folder), then reduces that run to the relative error of the case's headline quantity against its reference and
the run time (the stepping at the pace of the compiled kernels, :attr:`~iceresist.validate.rung.Rung.run_time_s`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


@dataclass
class CaseResult:
    """One run of a reference case at one rung of its ladder."""

    case: str                 #: the case's NAME
    label: str                #: rung label, e.g. "32 cells/diameter"
    resolution: float         #: cells across the characteristic length
    cells: int                #: lattice cells (or DEM spheres for DEM-only cases)
    steps: int                #: time steps taken
    wall_s: float             #: wall time of the stepping (s)
    quantity: str             #: name of the headline quantity, with units
    value: float              #: its simulated value
    reference: float          #: its reference value
    error: float              #: relative error |value - reference| / |reference|
    backend: str = "cpu"
    precision: str = "float32"
    extra: dict = field(default_factory=dict)  #: case-specific figures (period, decay rate, ...)

    @property
    def mlups(self) -> float:
        """Million lattice-cell updates per second of wall time."""
        return self.cells * self.steps / self.wall_s / 1e6 if self.wall_s > 0 else float("nan")

    def row(self) -> dict:
        """A flat dict for a pandas table (``extra`` keys prefixed ``x_``)."""
        d = asdict(self)
        extra = d.pop("extra")
        d["mlups"] = self.mlups
        d.update({f"x_{k}": v for k, v in extra.items()})
        return d


def relative_error(value: float, reference: float) -> float:
    """|value - reference| / |reference|."""
    return abs(value - reference) / abs(reference)
