"""The models: state plus one time step of the components a scene uses, no I/O (docs/ARCHITECTURE.md, "The model contract").

One model per physics, each on any grid (one level, or the levels of a ``[refinement]``; one process or several):

* :class:`FluidModel`: the LBM (no optional section);
* :class:`FreeSurfaceModel`: LBM + phase field, eqs. 1-11 (``[free_surface]``);
* :class:`BodiesModel`: LBM + DEM + coupling, the bodies on the finest level (``[[bodies]]``);
* :class:`FloatingBodiesModel`: both, bodies in water with a free surface (``[[bodies]]`` + ``[free_surface]``);
* :class:`Tier1Model`: DEM ship + ice + water models (``[ship]`` tier 1, ``[ice]``; no lattice);
* :class:`Tier2Model`: the floating bodies with the ship and its ice, eqs. 1-21 (``[ship]`` tier 2, ``[ice]``).

All follow the contract :class:`~iceresist.models.base.Model`; :func:`build_model` builds only what the scene
asks for: :func:`physics_of` names the physics, :data:`MODELS` gives its model.
"""

from __future__ import annotations

from iceresist.errors import InputError
from iceresist.models.base import Model
from iceresist.models.bodies import BodiesModel
from iceresist.models.floating_bodies import FloatingBodiesModel
from iceresist.models.fluid import FluidModel
from iceresist.models.surface import FreeSurfaceModel
from iceresist.models.tier1 import Tier1Model
from iceresist.models.tier2 import Tier2Model

__all__ = ["Model", "FluidModel", "FreeSurfaceModel", "BodiesModel", "FloatingBodiesModel", "Tier1Model", "Tier2Model",
           "MODELS", "physics_of", "build_model"]


#: The model of each physics a scene asks for (:func:`physics_of`), on whatever grid the scene gives it.
MODELS: dict[str, type] = {"fluid": FluidModel, "free_surface": FreeSurfaceModel, "bodies": BodiesModel,
                           "floating_bodies": FloatingBodiesModel, "tier1": Tier1Model, "tier2": Tier2Model}


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
    model = MODELS[physics]
    if comm is None or comm.size == 1:
        return model(scene, backend=backend, precision=precision)
    if physics == "tier1":
        raise InputError(f"mpirun -n {comm.size}: a tier-1 ship has no lattice to split over ranks and runs on one "
                         f"process; run it without mpirun")
    return model(scene, backend=backend, precision=precision, comm=comm)
