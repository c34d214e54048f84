"""The Morton partition of a block forest over MPI ranks and the halo it implies (iceresist.parallel.decomposition),
without MPI: the split itself, checked against what a rank must see."""

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from iceresist.errors import InputError
from iceresist.grid import BlockForest
from iceresist.grid.forest import Face
from iceresist.parallel.decomposition import Decomposition, morton_partition


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(1.0, 8.0), min_size=1, max_size=80), st.integers(1, 8))
def test_shares_are_contiguous_cover_every_block_and_balance_the_weight(weights, ranks):
    w = np.array(weights)
    if ranks > len(w):
        with pytest.raises(InputError, match=f"mpirun -n {ranks}: the scene has {len(w)} blocks"):
            morton_partition(w, ranks)
        return
    owner = morton_partition(w, ranks)
    assert owner[0] == 0 and owner[-1] == ranks - 1
    assert np.all(np.diff(owner) >= 0) and set(owner.tolist()) == set(range(ranks))
    share = np.bincount(owner, weights=w, minlength=ranks)
    if len(np.unique((np.cumsum(w) - 0.5 * w) / w.sum() * ranks // 1)) == ranks:   # the weighted cut held
        assert share.max() - share.min() <= 2 * w.max() + 1e-9


class _Comm:
    def __init__(self, rank, size):
        self.rank, self.size = rank, size


def test_each_rank_receives_the_layer_its_blocks_pull_and_sends_what_the_others_pull():
    """A 32 x 8 x 8 channel (4 blocks along x, periodic along x, walls elsewhere) on 2 ranks: rank 0 owns blocks
    0-1, rank 1 blocks 2-3; each rank's halo is the two blocks beside its share (one across the periodic face), and
    from each it receives, of the one layer of 64 cells facing its own block, the 9 populations streaming towards
    it (c_x = -1 from the block at +x, +1 from the one at -x); what one rank sends is what the other receives."""
    faces = {"x-": Face("periodic"), "x+": Face("periodic"), "y-": Face("wall"), "y+": Face("wall"),
             "z-": Face("wall"), "z+": Face("wall")}
    fo = BlockForest.uniform((32, 8, 8), faces)
    d0, d1 = Decomposition(fo, _Comm(0, 2)), Decomposition(fo, _Comm(1, 2))
    assert d0.nowned == d1.nowned == 2
    assert sorted(fo.origin[d0.halo][:, 0].tolist()) == [2, 3]
    from iceresist.lattice import C

    (r, rows, comps, cells), = d0.recvs
    assert r == 1 and len(cells) == 2 * 64 * 9
    x = (cells & 7)
    per_block = {int(b): (set(x[rows == b].tolist()), set(C[comps[rows == b], 0].tolist())) for b in np.unique(rows)}
    xs = {int(fo.origin[d0.global_ids[b], 0]): v for b, v in per_block.items()}
    # block 2's low-x layer faces block 1 and streams -x into it, block 3's high-x layer streams +x into block 0
    assert xs == {2: ({0}, {-1}), 3: ({7}, {1})}
    (r1, srows, scomps, scells), = d1.sends
    assert r1 == 0
    assert np.array_equal(d1.global_ids[srows], d0.global_ids[rows]) and np.array_equal(scells, cells)
    assert np.array_equal(scomps, comps)


def test_a_rank_updates_the_blocks_it_sends_before_its_messages_go_and_the_rest_while_they_travel():
    """A 64 x 8 x 8 channel (8 blocks along x, periodic along x) on 2 ranks: rank 0 owns the blocks at x = 0-3;
    the ones at x = 0 and 3 send a layer to rank 1 (across the periodic face and to x = 4) and are updated before
    the messages are posted, the ones at x = 1 and 2 while they travel; its halo blocks are updated by neither."""
    faces = {"x-": Face("periodic"), "x+": Face("periodic"), "y-": Face("wall"), "y+": Face("wall"),
             "z-": Face("wall"), "z+": Face("wall")}
    fo = BlockForest.uniform((64, 8, 8), faces)
    d = Decomposition(fo, _Comm(0, 2))
    h = d.solver_halo()
    x = fo.origin[d.global_ids, 0]
    assert sorted(x[h.sent == 1].tolist()) == [0, 3] and sorted(x[h.inner == 1].tolist()) == [1, 2]
    assert (h.nsent, h.ninner) == (2, 2) and not (h.sent[d.nowned:] | h.inner[d.nowned:]).any()
    (_, rows, _, _), = d.sends
    assert set(np.unique(rows).tolist()) == set(np.flatnonzero(h.sent).tolist())


def test_each_rank_on_a_node_takes_its_own_gpu(monkeypatch):
    """Four GPUs visible on a node of six ranks: the ranks take GPUs 0, 1, 2, 3, 0, 1 by their rank on the node; one
    GPU visible (a launcher gave each rank its own, or the simulator): nothing is selected."""
    pytest.importorskip("mpi4py")
    from iceresist import parallel
    from iceresist.backends import jit

    chosen = []
    monkeypatch.setattr(jit, "select_device", chosen.append)

    class Node:
        def __init__(self, rank):
            self.rank = rank

        def Split_type(self, kind, key):
            return self

        def Free(self):
            pass

    monkeypatch.setattr(jit, "device_count", lambda: 4)
    assert [parallel.use_local_gpu(Node(r)) for r in range(6)] == [0, 1, 2, 3, 0, 1]
    assert chosen == [0, 1, 2, 3, 0, 1]
    monkeypatch.setattr(jit, "device_count", lambda: 1)
    assert parallel.use_local_gpu(Node(3)) is None and len(chosen) == 6


def _two_level_channel():
    """A 64 x 8 x 16 channel (8 x 1 x 2 level-0 trees, periodic along x and y, walls in z) whose trees at x 16-48,
    z 0-8 are refined to level 1 (8 level-1 blocks each), with its level views."""
    from iceresist.grid.levels import level_views
    from iceresist.grid.octree import BlockOctree

    t = BlockOctree((8, 1, 2), 1, periodic=(True, True, False))
    t = t.refine(lambda lo, hi: ((lo[:, 0] >= 16) & (hi[:, 0] <= 48) & (hi[:, 2] <= 8)).astype(np.int64))
    faces = {"x-": Face("periodic"), "x+": Face("periodic"), "y-": Face("periodic"), "y+": Face("periodic"),
             "z-": Face("wall"), "z+": Face("wall")}
    return t, level_views(t, faces)


def test_whole_trees_are_dealt_out_along_the_morton_curve_in_equal_work():
    """The two-level channel on 2 ranks: each rank takes 8 of the 16 trees, a contiguous run of the Morton curve, and
    half the cells x sub-steps (the four refined trees weigh 16 level-0 blocks' work each); more ranks than trees is
    refused in one line."""
    from iceresist.parallel.levels import tree_partition, tree_weights

    t, _ = _two_level_channel()
    w = tree_weights(t)
    assert sorted(w.tolist()) == [512.0] * 12 + [8 * 512.0 * 2] * 4
    owner = tree_partition(t, 2)
    x, y, z = np.unravel_index(np.arange(16), (8, 1, 2), order="F")
    from iceresist.grid.forest import morton_key

    along = owner[np.argsort(morton_key(x, y, z), kind="stable")]
    assert np.all(np.diff(along) >= 0) and np.bincount(owner).tolist() == [8, 8]
    assert np.bincount(owner, weights=w).tolist() == [w.sum() / 2] * 2
    with pytest.raises(InputError, match="mpirun -n 17: the refined scene has 16 level-0 blocks"):
        tree_partition(t, 17)


def test_each_rank_holds_its_trees_and_the_ring_around_them_and_swaps_its_halo_leaves():
    """The two-level channel on 2 ranks: on every level each leaf is one rank's own; a rank holds its own leaves
    first, then the level's leaves within one block of its trees (across the periodic face too), then the ghost
    blocks among them; what rank 1 sends rank 0 after a step of a level is, block for block, rank 0's halo leaves
    of that level from rank 1."""
    from iceresist.parallel.levels import LevelDecomposition

    t, views = _two_level_channel()
    d = [LevelDecomposition(t, views, _Comm(r, 2)) for r in range(2)]
    for lv in (0, 1):
        v = views[lv]
        own = [dr.global_ids[lv][:dr.nown[lv]] for dr in d]
        assert sorted(np.concatenate(own).tolist()) == list(range(v.nleaves))
        for r, dr in enumerate(d):
            ids = dr.global_ids[lv]
            local = dr.views[lv]
            assert (ids[:local.nleaves] < v.nleaves).all() and (ids[local.nleaves:] >= v.nleaves).all()
            assert np.array_equal(local.forest.origin, v.forest.origin[ids])
            # held: the blocks of the level within one block of the rank's trees (x only: one block row in y,
            # trees of 2^lv blocks along x, periodic over 8 trees)
            n = 8 << lv
            mine = {int(x) >> lv for x in v.forest.origin[own[r], 0]}
            near = {x for x in range(n) if {((x + o) % n) >> lv for o in (-1, 0, 1)} & mine}
            want = np.flatnonzero(np.isin(v.forest.origin[:, 0], sorted(near)))
            assert sorted(ids.tolist()) == want.tolist()
        (r, rows), = d[0]._recvs[lv]
        (r1, srows), = d[1]._sends[lv]
        assert r == 1 and r1 == 0
        assert np.array_equal(d[0].global_ids[lv][rows], d[1].global_ids[lv][srows]) and len(rows) > 0
        # its own leaves that rank 0 sends are updated before the messages go, its other own leaves while they travel
        solver = SimpleNamespace()
        d[1].step_own(lv, solver)
        h = solver.halo
        assert np.flatnonzero(h.sent).tolist() == sorted(set(srows.tolist()))
        assert np.flatnonzero(h.sent | h.inner).tolist() == list(range(d[1].nown[lv])) and h.ninner > 0


@pytest.mark.parametrize("layers", [True, False], ids=["populations", "whole-blocks"])
def test_a_cuda_rank_packs_its_messages_on_the_device_and_unpacks_what_arrives(layers):
    """iceresist.parallel.staging under the CUDA simulator: the device buffer of a message holds the values of its
    entries in order (9 populations of a layer of 64 cells of blocks 3 and 5, or the whole of blocks 3 and 5);
    unpacking it into blocks 0 and 1 writes those values there and nothing else."""
    from iceresist.backends import jit

    if not jit.cuda_available():
        pytest.skip("no CUDA GPU and the simulator is off")
    from iceresist.parallel.staging import DevicePlan

    target = jit.cuda()
    rng = np.random.default_rng(3)
    host = rng.standard_normal((6, 27, 512))
    arr = target.to_device(host)
    if layers:
        comps = np.tile(np.repeat(np.arange(9, 18), 64), 2)
        cells = np.tile(np.arange(0, 512, 8), 18)
        send, recv = (np.repeat([3, 5], 9 * 64), comps, cells), (np.repeat([0, 1], 9 * 64), comps, cells)
    else:
        send, recv = ([3, 5], None, None), ([0, 1], None, None)
    plan = DevicePlan(target, arr.shape, arr.dtype, [(1, *recv)], [(1, *send)])
    plan.pack_sends(arr)
    (m,), (back,) = plan.sends, plan.recvs
    buf = m.dbuf.copy_to_host()
    want = host[send] if layers else host[[3, 5]].ravel()
    assert np.array_equal(buf, want)
    back.dbuf.copy_to_device(buf)
    plan.unpack_recvs(arr)
    out = arr.copy_to_host()
    expect = host.copy()
    if layers:
        expect[recv] = host[send]
    else:
        expect[[0, 1]] = host[[3, 5]]
    assert np.array_equal(out, expect) and not np.array_equal(out, host)
