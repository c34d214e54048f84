"""The models: state plus one time step of the components a scene uses, no I/O (docs/ARCHITECTURE.md, "The model contract").

==========================  ======================================================  =============================
model                       what it holds                                           scene sections
==========================  ======================================================  =============================
:class:`FluidModel`         block forest + LBM                                      no optional section
:class:`FreeSurfaceModel`   LBM + phase field (eqs. 1-11)                           ``[free_surface]``
:class:`Tier1Model`         DEM ship + ice + water models                           ``[ship]`` tier 1, ``[ice]``
:class:`Tier2Model`         free-surface LBM + DEM + coupling (eqs. 1-21)           ``[ship]`` tier 2, ``[ice]``
:class:`BodiesModel`        LBM (free surface optional) + DEM + coupling            ``[[bodies]]`` (no ship)
:class:`RefinedFluidModel`  LBM on refined levels                                   ``[refinement]`` alone
:class:`RefinedFreeSurfaceModel` free surface on the finest of refined levels       ``[refinement]`` + ``[free_surface]``
:class:`RefinedBodiesModel`  bodies and their coupling on the finest level            ``[refinement]`` + ``[[bodies]]``
:class:`RefinedSurfaceBodiesModel` bodies in water with a free surface, on the finest level ``[refinement]`` + ``[free_surface]`` + ``[[bodies]]``
:class:`RefinedTier2Model`  tier 2 with the ship, ice and surface on the finest level    ``[ship]`` tier 2, ``[ice]``, ``[refinement]``
==========================  ======================================================  =============================

All follow the contract :class:`~iceresist.models.base.Model`; :func:`build_model` builds only what the scene
asks for.
"""

from __future__ import annotations

from iceresist.errors import InputError
from iceresist.models.base import Model
from iceresist.models.bodies import BodiesModel
from iceresist.models.fluid import FluidModel, FreeSurfaceModel
from iceresist.models.refined import RefinedFluidModel
from iceresist.models.refined_bodies import RefinedBodiesModel
from iceresist.models.refined_surface import RefinedFreeSurfaceModel
from iceresist.models.refined_surface_bodies import RefinedSurfaceBodiesModel
from iceresist.models.refined_tier2 import RefinedTier2Model
from iceresist.models.tier1 import Tier1Model
from iceresist.models.tier2 import Tier2Model

__all__ = ["Model", "FluidModel", "FreeSurfaceModel", "RefinedFluidModel", "RefinedFreeSurfaceModel",
           "RefinedBodiesModel", "RefinedSurfaceBodiesModel", "RefinedTier2Model", "Tier1Model", "Tier2Model", "BodiesModel", "build_model"]


def build_model(scene, *, backend: str | None = None, precision: str | None = None, comm=None) -> Model:
    """The model of the components ``scene`` uses: fluid-only scenes, free-surface scenes ([free_surface]
    alone), tier-1 and tier-2 ship scenes ([ship] + [ice]) and scenes of rigid bodies ([[bodies]], with or
    without [free_surface] and [contact]). ``comm``: the MPI communicator of a run on several ranks
    (:mod:`iceresist.parallel`: every scene but a tier-1 ship, on a uniform grid or on levels)."""
    if comm is not None and comm.size > 1:
        extra = scene.optional_sections()
        if extra == ["refinement"]:
            return RefinedFluidModel(scene, backend=backend, precision=precision, comm=comm)
        if extra == ["free_surface", "refinement"]:
            return RefinedFreeSurfaceModel(scene, backend=backend, precision=precision, comm=comm)
        if "refinement" in extra and scene.bodies and set(extra) <= {"refinement", "bodies", "contact"}:
            return RefinedBodiesModel(scene, backend=backend, precision=precision, comm=comm)
        if "refinement" in extra and scene.bodies and set(extra) <= {"refinement", "bodies", "contact",
                                                                        "free_surface"}:
            return RefinedSurfaceBodiesModel(scene, backend=backend, precision=precision, comm=comm)
        if "refinement" in extra and scene.ship is not None and scene.ice is not None and scene.ship.tier == 2 \
                and not scene.bodies:
            return RefinedTier2Model(scene, backend=backend, precision=precision, comm=comm)
        if "refinement" in extra:
            raise InputError(f"mpirun -n {comm.size}: refinement: this refined scene "
                             f"({', '.join('[' + s + ']' for s in extra)}) has no model on levels; run it without "
                             f"mpirun to see why")
        if scene.ship is not None and scene.ice is not None and scene.ship.tier == 2 and not scene.bodies:
            return Tier2Model(scene, backend=backend, precision=precision, comm=comm)
        if extra == ["free_surface"]:
            return FreeSurfaceModel(scene, backend=backend, precision=precision, comm=comm)
        if scene.bodies and set(extra) <= {"contact", "bodies", "free_surface"}:
            return BodiesModel(scene, backend=backend, precision=precision, comm=comm)
        if extra:
            raise InputError(f"mpirun -n {comm.size}: a scene with {', '.join('[' + s + ']' for s in extra)} runs on "
                             f"one process so far (the fluid, the free surface, bodies and a tier-2 ship run on "
                             f"several); run it without mpirun")
        return FluidModel(scene, backend=backend, precision=precision, comm=comm)
    if scene.ship is not None and scene.ice is not None:
        if scene.bodies:
            raise InputError(f"{scene.source_name}: bodies: a ship scene takes no extra [[bodies]] yet; remove "
                             f"the [[bodies]] tables (or the [ship] and [ice] sections)")
        if scene.refinement is not None:
            if scene.ship.tier != 2:
                raise InputError(f"{scene.source_name}: refinement: tier 1 has no lattice to refine; remove "
                                 f"[refinement] or set ship.tier = 2")
            return RefinedTier2Model(scene, backend=backend, precision=precision)
        model = Tier2Model if scene.ship.tier == 2 else Tier1Model
        return model(scene, backend=backend, precision=precision)
    extra = scene.optional_sections()
    if "refinement" in extra:
        if extra == ["free_surface", "refinement"]:
            return RefinedFreeSurfaceModel(scene, backend=backend, precision=precision)
        if scene.bodies and set(extra) <= {"refinement", "bodies", "contact"}:
            return RefinedBodiesModel(scene, backend=backend, precision=precision)
        if scene.bodies and set(extra) <= {"refinement", "bodies", "contact", "free_surface"}:
            return RefinedSurfaceBodiesModel(scene, backend=backend, precision=precision)
        if extra != ["refinement"]:
            others = ", ".join("[" + s + "]" for s in extra if s not in ("refinement", "free_surface"))
            raise InputError(f"{scene.source_name}: refinement: a refined scene is the fluid alone, with a "
                             f"[free_surface], with [[bodies]] or with both so far; remove [refinement] to run "
                             f"{others} on a uniform grid")
        return RefinedFluidModel(scene, backend=backend, precision=precision)
    wants = [f for f in scene.output.fields if f in ("phi", "surface")]
    if wants and scene.free_surface is None:
        raise InputError(f"output.fields: {', '.join(wants)} need a [free_surface] section; "
                         f"remove them from output.fields")
    if scene.bodies and set(extra) <= {"free_surface", "contact", "bodies"}:
        return BodiesModel(scene, backend=backend, precision=precision)
    if extra == ["free_surface"]:
        return FreeSurfaceModel(scene, backend=backend, precision=precision)
    if extra:
        raise InputError(f"{scene.source_name}: sections {', '.join('[' + s + ']' for s in extra)} need the "
                         f"free-surface, DEM and coupling engine, which `iceresist run` does not build yet; "
                         f"remove them to run the fluid alone")
    return FluidModel(scene, backend=backend, precision=precision)
