"""The CI's test processes keep each ``xdist_group`` in one process (`make test`: pytest-xdist ``--dist
loadgroup``): the tests of one costly build (the GPU build check) or kernel family (tier 2's) rely on it, so that a
cold kernel cache compiles them once. pytest 9 with pytest-xdist 3.8 dropped the groups without a word
(pyproject.toml pins pytest below 9)."""

import pytest


@pytest.mark.xdist_group("test_groups")
def test_a_grouped_test_carries_its_group_under_loadgroup(request):
    """Under ``--dist loadgroup`` the node id ends in ``@test_groups`` (how pytest-xdist's scheduler finds the
    group); elsewhere (one process, another --dist) there is nothing to check. Planted: under pytest 9 the id has
    no group (seen with pytest 9.2 and pytest-xdist 3.8), as without the mark."""
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not a test process of --dist loadgroup")
    assert request.node.nodeid.endswith("@test_groups"), request.node.nodeid
