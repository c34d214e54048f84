"""``build_model`` is a table keyed by physics (:data:`iceresist.models.MODELS`): each kind of scene names its physics
(:func:`iceresist.models.physics_of`) and ``[refinement]`` picks the grid, on one process and on several ranks."""

from types import SimpleNamespace

import pytest

from iceresist.errors import InputError
from iceresist.models import (MODELS, BodiesModel, FloatingBodiesModel, FluidModel, FreeSurfaceModel,
                              Tier1Model, Tier2Model, build_model, physics_of)
from iceresist.scene.case_scenes import case_scene
from iceresist.scene.load import parse_scene, preset_text
from tests.test_bodies import CHANNEL, TANK

CASE = "A-c68-v1.0"


def test_every_physics_has_one_model_on_any_grid():
    assert MODELS == {"fluid": FluidModel, "free_surface": FreeSurfaceModel, "bodies": BodiesModel,
                      "floating_bodies": FloatingBodiesModel, "tier1": Tier1Model, "tier2": Tier2Model}


@pytest.mark.parametrize("scene, physics, refined", [
    (lambda: parse_scene(preset_text("cavity")), "fluid", False),
    (lambda: parse_scene(preset_text("refined_channel")), "fluid", True),
    (lambda: parse_scene(preset_text("dam_break")), "free_surface", False),
    (lambda: parse_scene(preset_text("refined_tank")), "free_surface", True),
    (lambda: parse_scene(CHANNEL), "bodies", False),
    (lambda: parse_scene(TANK), "floating_bodies", False),
    (lambda: case_scene(CASE, "quick", 1), "tier1", False),
    (lambda: case_scene(CASE, "quick", 2), "tier2", False),
    (lambda: case_scene(CASE, "quick", 2, amr=True), "tier2", True),
])
def test_each_kind_of_scene_names_its_physics(scene, physics, refined):
    s = scene()
    assert physics_of(s) == physics
    assert (s.refinement is not None) == refined


def test_a_tier1_ship_on_several_ranks_is_refused_in_one_line():
    with pytest.raises(InputError, match=r"^mpirun -n 2: a tier-1 ship has no lattice to split"):
        build_model(case_scene(CASE, "quick", 1), comm=SimpleNamespace(size=2))


def test_a_ship_with_bodies_or_a_fluid_with_contact_is_refused_naming_the_key():
    s = case_scene(CASE, "quick", 2)
    with pytest.raises(InputError, match="bodies: a ship scene takes no extra"):
        physics_of(s.model_copy(update={"bodies": parse_scene(CHANNEL).bodies}))
    contact = parse_scene(CHANNEL.split("[[bodies]]")[0] + "[contact]\nstiffness_N_m = 1.0e4\n")
    with pytest.raises(InputError, match=r"sections \[contact\] need the free-surface, DEM and coupling engine"):
        physics_of(contact)
