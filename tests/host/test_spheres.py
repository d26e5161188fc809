"""Bounding spheres: grouping, enclosure, and the top-down hierarchy cull."""

import numpy as np
import pytest

from raplas_hdl.host.scenes import get_scene
from raplas_hdl.host.spheres import build_sphere_tree, cull_tree, unit_margin


def _tree(name="spheres", tps=8, fanout=4, margin=0.0, **kw):
    tris = get_scene(name, **kw).triangles
    return tris, build_sphere_tree(tris, tps, fanout, margin)


def _below(tree, node):
    """Triangles below a node (through its leaves)."""
    stack, out = [node], []
    while stack:
        k = stack.pop()
        if tree.node_leaf[k] >= 0:
            lst = tree.leaf_tris[tree.node_leaf[k]]
            out += list(lst[lst >= 0])
        else:
            stack += list(tree.child_index[tree.child_start[k]:tree.child_start[k + 1]])
    return np.array(out)


@pytest.mark.parametrize("tps, fanout", [(1, 2), (4, 8), (8, 4), (16, 16)])
def test_partition_and_enclosure(tps, fanout):
    tris, tree = _tree(tps=tps, fanout=fanout, margin=0.01)
    ids = tree.leaf_tris[tree.leaf_tris >= 0]
    assert np.array_equal(np.sort(ids), np.arange(len(tris)))       # each triangle once
    assert tree.leaf_counts.max() <= tps
    assert np.all(np.diff(tree.child_start) <= fanout)
    for node in range(tree.n_nodes):
        below = _below(tree, node)
        assert len(below) == tree.node_tris[node]
        dist = np.linalg.norm(tris[below] - tree.centres[node], axis=2)
        # every vertex inside, with the margin on top
        assert dist.max() + 0.01 <= tree.radii[node] * (1 + 1e-12)


def test_leaves_are_depth_first_and_full():
    _, tree = _tree(tps=8, fanout=8)
    assert np.all(np.diff(tree.leaf_node) > 0)
    # splits round to multiples of tris_per_sphere: few partial leaves
    assert np.mean(tree.leaf_counts == 8) > 0.5


def test_cull_drops_subtrees_and_counts():
    tris, tree = _tree(tps=4, fanout=4)
    # drop the second child of the root (an inner node)
    kids = tree.child_index[tree.child_start[0]:tree.child_start[1]]
    victim = next(k for k in kids if tree.node_leaf[k] < 0)
    tested = []

    def touched(nodes):
        tested.extend(nodes.tolist())
        return nodes != victim

    leaves, st = cull_tree(tree, touched)
    gone = set(_below(tree, victim).tolist())
    kept = set(tree.leaf_tris[leaves][tree.leaf_tris[leaves] >= 0].tolist())
    assert kept.isdisjoint(gone) and kept | gone == set(range(len(tris)))
    assert st.dropped.sum() == 1 and st.tris_dropped.sum() == len(gone)
    assert st.tested.sum() == len(tested)
    assert all(tree.node_leaf[n] < 0 for n in tested)   # the unit tests the leaves
    # nothing below the victim was tested
    desc = [n for n in range(tree.n_nodes) if n != victim and
            set(_below(tree, n).tolist()) <= gone]
    assert not set(desc) & set(tested)


def test_cull_all_and_none():
    _, tree = _tree(tps=4, fanout=2)
    leaves, st = cull_tree(tree, lambda n: np.ones(len(n), bool))
    assert np.array_equal(leaves, np.arange(tree.n_leaves))
    leaves, st = cull_tree(tree, lambda n: np.zeros(len(n), bool))
    assert leaves.size == 0 and st.dropped[0] == 1 and st.tested.sum() == 1
    leaves, st = cull_tree(tree, None, hierarchy=False)
    assert leaves.size == tree.n_leaves and st.tested.sum() == 0


def test_margin_conservative_only():
    from raplas_hdl.fp import FP24, FP32

    tris = get_scene("soup", n=20).triangles
    assert np.all(unit_margin(tris, FP24, 16.0, "paper") == 0)
    m24 = unit_margin(tris, FP24, 16.0, "conservative")
    m32 = unit_margin(tris, FP32, 16.0, "conservative")
    assert np.all(m24 > 0) and np.all(m32 < m24 / 64)           # 7 more fraction bits


@pytest.mark.parametrize("kwargs, message", [
    ({"tris": np.zeros((0, 3, 3))}, "zero triangles"),
    ({"tris": np.zeros((2, 3))}, "shape"),
    ({"tris": np.full((1, 3, 3), np.nan)}, "NaN"),
    ({"tris": np.zeros((1, 3, 3)), "tris_per_sphere": 0}, "tris_per_sphere"),
    ({"tris": np.zeros((1, 3, 3)), "fanout": 3}, "fanout"),
])
def test_bad_build(kwargs, message):
    with pytest.raises(ValueError, match=message):
        build_sphere_tree(**kwargs)
