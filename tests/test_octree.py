"""The block octree of adaptive refinement (iceresist.grid.octree): the leaves cover the domain once, two leaves
that touch differ by at most one level (faces, edges and corners), the Morton order is the octree's depth-first
order, and the neighbour tables name exactly the leaves across each face, edge and corner. Checked against a
rasterisation of the leaves onto the finest level."""

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.grid.octree import OFFSETS, BlockOctree


def _point_refinement(points, levels=(4, 3), radii=(1.0, 3.0)):
    """Finest level within radii[0] level-0 cells of a point, the next within radii[1], else level 0."""
    points = np.atleast_2d(points)

    def wanted(lo, hi):
        d = np.min([np.linalg.norm(np.clip(p, lo, hi) - p, axis=1) for p in points], axis=0)
        return np.where(d < radii[0], levels[0], np.where(d < radii[1], levels[1], 0))
    return wanted


def _raster(t):
    """Owner leaf and its level on the finest grid."""
    L = t.max_level
    owner = np.full(tuple(t.root << L), -1)
    for i, (lv, c) in enumerate(zip(t.level, t.coord)):
        s = 1 << (L - int(lv))
        sl = tuple(slice(int(c[a]) * s, (int(c[a]) + 1) * s) for a in range(3))
        assert (owner[sl] == -1).all(), "two leaves overlap"
        owner[sl] = i
    return owner, t.level[owner]


def _trees():
    yield BlockOctree((4, 3, 2), 4, periodic=(True, False, False)).refine(_point_refinement([[10.3, 7.1, 5.2]]))
    # a point at a periodic face: refinement reaches across it
    yield BlockOctree((3, 3, 3), 3, periodic=(True, True, True)).refine(
        _point_refinement([[0.2, 23.8, 12.0]], levels=(3, 2)))
    # two points and a closed domain
    yield BlockOctree((2, 2, 2), 4).refine(_point_refinement([[3.0, 3.0, 3.0], [12.5, 9.0, 14.0]]))


@pytest.fixture(params=range(3))
def tree(request):
    return list(_trees())[request.param]


def test_leaves_cover_the_domain_once_and_differ_by_at_most_one_level_where_they_touch(tree):
    owner, level = _raster(tree)
    assert (owner >= 0).all()
    assert level.max() == tree.max_level
    for off in OFFSETS:
        other = np.roll(level, tuple(-off), axis=(0, 1, 2))
        valid = np.ones(level.shape, dtype=bool)
        for a in range(3):
            if tree.periodic[a] or off[a] == 0:
                continue
            idx = [slice(None)] * 3
            idx[a] = -1 if off[a] > 0 else 0
            valid[tuple(idx)] = False
        assert np.abs(level - other)[valid].max() <= 1, f"2:1 balance broken across offset {off}"


def test_refinement_reaches_what_the_criterion_asks():
    wanted = _point_refinement([[10.3, 7.1, 5.2]])
    t = BlockOctree((4, 3, 2), 4).refine(wanted)
    lo, hi = t.box()
    assert (t.level >= np.minimum(wanted(lo, hi), 4)).all()
    # the leaf holding the point is at the finest level
    i = [k for k in range(t.nleaves) if (lo[k] <= [10.3, 7.1, 5.2]).all() and (hi[k] > [10.3, 7.1, 5.2]).all()]
    assert len(i) == 1 and t.level[i[0]] == 4
    assert t.blocks_per_level().sum() == t.nleaves
    assert t.cells_per_level().sum() == t.nleaves * 512
    # the volume of the leaves is the domain's
    assert np.prod(hi - lo, axis=1).sum() == pytest.approx(np.prod(t.root * 8))


def test_the_level_map_is_the_raster_of_the_leaves_and_covers_compares_two_octrees(tree):
    """level_map equals the leaves drawn one by one on the finest block grid; an octree refined about a point
    covers one refined less far about it (and a finer level's copy refined about a second point too), not the
    other way round. Planted: the map's repeat skipped on one axis, or covers with <=: fails."""
    _, level = _raster(tree)
    assert tree.level_map().shape == level.shape
    assert np.array_equal(tree.level_map(), level)
    p = [[3.0, 3.0, 3.0]]
    wide = BlockOctree((2, 2, 2), 3).refine(_point_refinement(p, levels=(3, 2), radii=(3.0, 6.0)))
    narrow = BlockOctree((2, 2, 2), 3).refine(_point_refinement(p, levels=(3, 2), radii=(1.0, 3.0)))
    other = BlockOctree((2, 2, 2), 3).refine(_point_refinement([[12.5, 12.0, 12.0]], levels=(3, 2)))
    assert wide.covers(narrow) and wide.covers(wide)
    assert wide.updates_per_step() == sum(512 * 2 ** int(lv) for lv in wide.level) > narrow.updates_per_step()
    assert not narrow.covers(wide)
    assert not wide.covers(other) and not other.covers(wide)


def test_morton_order_is_the_depth_first_order(tree):
    """Every block of every level holds a contiguous run of leaves, and runs of siblings follow child order."""
    for m in range(tree.max_level):
        deeper = tree.level > m
        anc = tree.coord[deeper] >> (tree.level[deeper] - m)[:, None]
        pos = np.flatnonzero(deeper)
        keys = [tuple(a) for a in anc]
        first, last, count = {}, {}, {}
        for p, k in zip(pos, keys):
            first.setdefault(k, p)
            last[k] = p
            count[k] = count.get(k, 0) + 1
        for k in first:
            assert last[k] - first[k] + 1 == count[k], f"the leaves under block {k} of level {m} are not contiguous"


def _adjacent_owners(tree, owner, b, off):
    """Leaves owning the finest cells that touch leaf b across offset off (raster reference)."""
    L = tree.max_level
    s = 1 << (L - int(tree.level[b]))
    lo = tree.coord[b] * s
    shape = np.array(owner.shape)
    ranges = []
    for a in range(3):
        if off[a] > 0:
            r = np.array([lo[a] + s])
        elif off[a] < 0:
            r = np.array([lo[a] - 1])
        else:
            r = np.arange(lo[a], lo[a] + s)
        if tree.periodic[a]:
            r %= shape[a]
        elif (r < 0).any() or (r >= shape[a]).any():
            return set()
        ranges.append(r)
    return set(np.unique(owner[np.ix_(*ranges)]).tolist())


def test_neighbour_tables_name_exactly_the_leaves_across_each_face_edge_and_corner(tree):
    owner, _ = _raster(tree)
    same, coarse, fine = tree.neighbours()
    for b in range(tree.nleaves):
        for k, off in enumerate(OFFSETS):
            if not off.any():
                assert same[b, k] == coarse[b, k] == -1 and (fine[b, k] == -1).all()
                continue
            ref = _adjacent_owners(tree, owner, b, off)
            got = {int(same[b, k])} - {-1} | {int(coarse[b, k])} - {-1} | set(fine[b, k].tolist()) - {-1}
            assert got == ref, (b, off)
            kinds = (same[b, k] >= 0) + (coarse[b, k] >= 0) + (fine[b, k, 0] >= 0)
            assert kinds == (1 if ref else 0)
            if same[b, k] >= 0:
                assert tree.level[same[b, k]] == tree.level[b]
            if coarse[b, k] >= 0:
                assert tree.level[coarse[b, k]] == tree.level[b] - 1
            n_fine = (fine[b, k] >= 0).sum()
            if n_fine:
                assert n_fine == 2 ** int((off == 0).sum()) and (tree.level[fine[b, k, :n_fine]] == tree.level[b] + 1).all()


def test_find_and_leaf_at():
    t = BlockOctree((2, 1, 1), 2).refine(lambda lo, hi: np.where(lo[:, 0] < 1, 2, 0))
    assert t.find(np.array([0]), np.array([[1, 0, 0]]))[0] >= 0      # level-0 block (1, 0, 0) is a leaf
    idx, lev = t.leaf_at(np.array([2]), np.array([[7, 3, 3]]))         # inside it, at level 2
    assert lev[0] == 0 and idx[0] == t.find(np.array([0]), np.array([[1, 0, 0]]))[0]
    idx, lev = t.leaf_at(np.array([0]), np.array([[0, 0, 0]]))         # refined: no leaf holds it whole
    assert idx[0] == -1


def test_an_unbalanced_tree_is_refused_by_the_neighbour_tables():
    t = BlockOctree((2, 1, 1), 3)
    t._split(np.array([True, False]))
    t._split(t.level == 1)
    t._split(t.level == 2)
    with pytest.raises(InputError, match="not 2:1 balanced"):
        t.neighbours()


@pytest.mark.parametrize("root,level,match", [((0, 1, 1), 2, "root"), ((2, 2), 2, "root"), ((2, 2, 2), 16, "max_level")])
def test_bad_sizes_are_refused(root, level, match):
    with pytest.raises(InputError, match=match):
        BlockOctree(root, level)
