"""The model contract: state plus one time step of the components a scene uses, no I/O (docs/ARCHITECTURE.md, "The model contract").

Every model (:class:`~iceresist.models.fluid.FluidModel`, :class:`~iceresist.models.surface.FreeSurfaceModel`,
:class:`~iceresist.models.tier1.Tier1Model`, :class:`~iceresist.models.tier2.Tier2Model`) derives from
:class:`Model`, so the driver (:mod:`iceresist.driver`), the time loop (:mod:`iceresist.simulation`) and the
watchdog ask every model the same questions and never test what it happens to have. After Oceananigans'
``AbstractModel``: the model is a state and a step; schedules, writers and checkpoints belong to the
simulation around it.

The model speaks physical units to the outside (``time_s``, ``fields()``, ``diagnostics()``) and lattice units
inside.
"""

from __future__ import annotations

import abc

import numpy as np


class Model(abc.ABC):
    """What every model gives the time loop and the driver.

    Clock: ``iteration`` (model steps taken), ``dt_s`` (seconds per model step), ``time_s``.
    Size: ``cells`` (lattice cells, 0 where there is no lattice), ``shape_cells`` (or None),
    ``lattice_steps_per_step`` (LBM steps in one model step: a tier-2 record holds several), ``allocation()``.
    Identity: ``components``, ``units`` (the lattice's :class:`~iceresist.units.Units`, None for a model without
    a lattice), ``precision``, ``target`` (the compile target), ``describe()``.
    """

    #: Names of the components the model holds (run metadata).
    components: tuple[str, ...] = ()
    #: Lattice cells (for MLUPS); 0 for a model without a lattice (tier 1).
    cells: int = 0
    #: Cells along x, y, z of the lattice, or None.
    shape_cells: tuple[int, ...] | None = None
    #: LBM steps in one model step.
    lattice_steps_per_step: int = 1
    #: Model steps between watchdog checks, or None for the watchdog's default by kind (:mod:`iceresist.watchdog`).
    watchdog_interval: int | None = None
    #: Seconds of simulated time per model step.
    dt_s: float
    #: Scales of the lattice (:class:`iceresist.units.Units`; its ``dt_s`` is the LBM step), or None.
    units = None
    #: The MPI communicator of a model split over several ranks (:mod:`iceresist.parallel`), or None. Its
    #: ``fields()`` and ``state()`` then return the whole domain on rank 0 and None on the others, and its
    #: ``diagnostics()``, ``is_finite()`` and ``watchdog_probe()`` the same values on every rank.
    comm = None
    #: The split of the model's blocks over several ranks (:class:`~iceresist.parallel.decomposition.Decomposition`
    #: or :class:`~iceresist.parallel.levels.LevelDecomposition`), or None.
    decomp = None
    #: The cells the model steps and their split over the ranks (:class:`~iceresist.grid.grid.Grid`: sums, gathers
    #: and exchanges over the ranks, the value itself on one process), or None for a model without a lattice.
    grid = None

    # -- clock ------------------------------------------------------------------------------------------
    @property
    @abc.abstractmethod
    def iteration(self) -> int:
        """Model steps taken since t = 0 (a continued run counts from its first leg)."""

    @property
    def time_s(self) -> float:
        """Simulated time (s)."""
        return self.iteration * self.dt_s

    @abc.abstractmethod
    def step(self, n: int = 1) -> None:
        """Advance ``n`` model steps."""

    # -- output -----------------------------------------------------------------------------------------
    @abc.abstractmethod
    def fields(self) -> dict[str, np.ndarray]:
        """Dense host fields, name -> [x, y, z(, 3)] array in physical units ({} for a model without a lattice)."""

    def field_units(self, lattice: bool) -> dict[str, str]:
        """Unit of each field of :meth:`fields` (``lattice``: the scene is written in lattice units)."""
        return {}

    def level_fields(self, names=None) -> list[dict] | None:
        """Each refinement level's leaf cells and their fields (``names``: those fields only), written beside the
        dense fields; None for a model on one level (the default). With MPI gathered on rank 0."""
        return None

    @abc.abstractmethod
    def diagnostics(self) -> dict[str, float]:
        """One time-series row: plain floats in physical units (mass, energy, forces, ...)."""

    def is_finite(self) -> bool:
        """A cheap NaN/Inf check of the state (the NaN checker calls it); by default the fields are checked."""
        return all(np.isfinite(a).all() for a in self.fields().values()
                   if np.issubdtype(np.asarray(a).dtype, np.floating))

    @abc.abstractmethod
    def watchdog_probe(self) -> dict:
        """What the run watchdog checks, each ``name: (value, where)`` (:mod:`iceresist.watchdog`)."""

    # -- checkpoints ------------------------------------------------------------------------------------
    @abc.abstractmethod
    def state(self) -> dict:
        """Everything a bit-for-bit restart needs, as a nested dict of host arrays and plain values."""

    @abc.abstractmethod
    def load_state(self, state: dict) -> None:
        """Continue from :meth:`state` of a model built from the same scene; a wrong checkpoint is an
        :class:`~iceresist.errors.InputError` naming what differs."""

    # -- identity and memory ----------------------------------------------------------------------------
    @abc.abstractmethod
    def describe(self) -> dict:
        """Plain values for the run metadata (JSON-serialisable)."""

    @abc.abstractmethod
    def allocation(self) -> dict[str, int]:
        """Bytes of state held per component (e.g. ``{"lbm": ..., "phase_field": ..., "dem": ...}``)."""

    def allocated_bytes(self) -> int:
        """Bytes of state this model holds, all components together."""
        return int(sum(self.allocation().values()))

    @property
    def lattice_updates_per_step(self) -> int:
        """Cell updates in one model step (MLUPS counts these)."""
        return int(self.cells) * int(self.lattice_steps_per_step)


def array_bytes(*objects) -> int:
    """Bytes of the NumPy (or device) arrays held by the attributes of ``objects`` (directly, or in lists,
    tuples and dicts of them), each array counted once."""
    seen, total = set(), 0

    def visit(v):
        nonlocal total
        if isinstance(v, (list, tuple)):
            for x in v:
                visit(x)
        elif isinstance(v, dict):
            for x in v.values():
                visit(x)
        elif not isinstance(v, type) and hasattr(v, "nbytes") and hasattr(v, "shape") and id(v) not in seen:
            seen.add(id(v))
            total += int(v.nbytes)

    for obj in objects:
        if obj is not None:
            for v in vars(obj).values():
                visit(v)
    return total
