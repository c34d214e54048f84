"""The models: state plus one time step of the components a scene uses, no I/O (docs/ARCHITECTURE.md, "The model contract").

==========================  ======================================================  =============================
model                       what it holds                                           scene sections
==========================  ======================================================  =============================
:class:`FluidModel`         LBM on one level or on refined levels                   no optional section (``[refinement]``)
:class:`FreeSurfaceModel`   LBM + phase field (eqs. 1-11), on one level or levels   ``[free_surface]`` (``[refinement]``)
:class:`Tier1Model`         DEM ship + ice + water models                           ``[ship]`` tier 1, ``[ice]``
:class:`Tier2Model`         free-surface LBM + DEM + coupling (eqs. 1-21)           ``[ship]`` tier 2, ``[ice]``
:class:`BodiesModel`        LBM + DEM + coupling on the finest level (of one or more) ``[[bodies]]`` (``[refinement]``)
:class:`FloatingBodiesModel` bodies in water with a free surface, on the finest level  ``[[bodies]]`` + ``[free_surface]`` (``[refinement]``)
:class:`RefinedTier2Model`  tier 2 with the ship, ice and surface on the finest level    ``[ship]`` tier 2, ``[ice]``, ``[refinement]``
==========================  ======================================================  =============================

All follow the contract :class:`~iceresist.models.base.Model`; :func:`build_model` builds only what the scene
asks for: :func:`physics_of` names the physics, :data:`MODELS` gives its model on one grid or on levels.
"""

from __future__ import annotations

from iceresist.errors import InputError
from iceresist.models.base import Model
from iceresist.models.bodies import BodiesModel
from iceresist.models.floating_bodies import FloatingBodiesModel
from iceresist.models.fluid import FluidModel
from iceresist.models.surface import FreeSurfaceModel
from iceresist.models.refined_tier2 import RefinedTier2Model
from iceresist.models.tier1 import Tier1Model
from iceresist.models.tier2 import Tier2Model

__all__ = ["Model", "FluidModel", "FreeSurfaceModel", "BodiesModel", "FloatingBodiesModel", "RefinedTier2Model",
           "Tier1Model", "Tier2Model", "MODELS", "physics_of", "build_model"]


#: The model of each physics a scene asks for (:func:`physics_of`): on one uniform grid, and on the levels of a
#: ``[refinement]`` (None: that physics has no lattice to refine).
MODELS: dict[str, tuple[type, type | None]] = {
    "fluid": (FluidModel, FluidModel),
    "free_surface": (FreeSurfaceModel, FreeSurfaceModel),
    "bodies": (BodiesModel, BodiesModel),
    "floating_bodies": (FloatingBodiesModel, FloatingBodiesModel),
    "tier1": (Tier1Model, None),
    "tier2": (Tier2Model, RefinedTier2Model),
}


def _sections(names) -> str:
    return ", ".join("[" + s + "]" for s in names)


def physics_of(scene) -> str:
    """The physics a scene asks for, a key of :data:`MODELS`: ``tier1`` / ``tier2`` ([ship] + [ice]), ``bodies``
    ([[bodies]], with [contact] or not), ``floating_bodies`` (the same in water with a [free_surface]),
    ``free_surface`` ([free_surface] alone) or ``fluid`` (no optional section); ``[refinement]`` picks the grid, not
    the physics. A scene that mixes what no model holds is an :class:`~iceresist.errors.InputError` naming the key."""
    if scene.ship is not None and scene.ice is not None:
        if scene.bodies:
            raise InputError(f"{scene.source_name}: bodies: a ship scene takes no extra [[bodies]] yet; remove "
                             f"the [[bodies]] tables (or the [ship] and [ice] sections)")
        if scene.refinement is not None and scene.ship.tier != 2:
            raise InputError(f"{scene.source_name}: refinement: tier 1 has no lattice to refine; remove "
                             f"[refinement] or set ship.tier = 2")
        return f"tier{scene.ship.tier}"
    extra = [s for s in scene.optional_sections() if s != "refinement"]
    wants = [f for f in scene.output.fields if f in ("phi", "surface")]
    if wants and scene.free_surface is None:
        raise InputError(f"output.fields: {', '.join(wants)} need a [free_surface] section; "
                         f"remove them from output.fields")
    if scene.bodies and set(extra) <= {"free_surface", "contact", "bodies"}:
        return "floating_bodies" if scene.free_surface is not None else "bodies"
    if extra == ["free_surface"]:
        return "free_surface"
    if extra and scene.refinement is not None:
        raise InputError(f"{scene.source_name}: refinement: a refined scene is the fluid alone, with a "
                         f"[free_surface], with [[bodies]] or with both so far; remove [refinement] to run "
                         f"{_sections(s for s in extra if s != 'free_surface')} on a uniform grid")
    if extra:
        raise InputError(f"{scene.source_name}: sections {_sections(extra)} need the free-surface, DEM and coupling "
                         f"engine, which `iceresist run` does not build yet; remove them to run the fluid alone")
    return "fluid"


def build_model(scene, *, backend: str | None = None, precision: str | None = None, comm=None) -> Model:
    """The model of the physics ``scene`` asks for (:func:`physics_of`, :data:`MODELS`) on its grid: one uniform
    grid, or the levels of its ``[refinement]``. ``comm``: the MPI communicator of a run on several ranks
    (:mod:`iceresist.parallel`: every physics but tier 1, on a uniform grid or on levels)."""
    physics = physics_of(scene)
    uniform, levels = MODELS[physics]
    model = levels if scene.refinement is not None else uniform
    if comm is None or comm.size == 1:
        return model(scene, backend=backend, precision=precision)
    if physics == "tier1":
        raise InputError(f"mpirun -n {comm.size}: a tier-1 ship has no lattice to split over ranks and runs on one "
                         f"process; run it without mpirun")
    return model(scene, backend=backend, precision=precision, comm=comm)
