"""The shared Tree structure: the extensions used by the growth and non-growth models keep the
original API working (subtree sums, masks, metrics, meshes, export)."""
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees.structure import Leaves, Tree, segment_depth, subtree_sum


def _loop_subtree_sum(parent, values):
    acc = np.array(values, float)
    for i in range(len(parent) - 1, 0, -1):
        if parent[i] >= 0:
            acc[parent[i]] += acc[i]
    return acc


def _random_tree(n=200, seed=0, roots=2):
    rng = np.random.default_rng(seed)
    parent = np.full(n, -1)
    for i in range(roots, n):
        parent[i] = rng.integers(0, i)
    start = np.zeros((n, 3))
    end = np.zeros((n, 3))
    for i in range(n):
        if parent[i] >= 0:
            start[i] = end[parent[i]]
        end[i] = start[i] + rng.normal(size=3) * 0.3 + [0, 1, 0]
    return Tree(start, end, np.full(n, 0.05), np.full(n, 0.04), parent, np.zeros(n, int))


def test_subtree_sum_matches_reference_loop():
    t = _random_tree()
    v = np.random.default_rng(1).random(len(t))
    assert np.allclose(t.subtree_sum(v), _loop_subtree_sum(t.parent, v))
    assert np.allclose(subtree_sum(t.parent, v), _loop_subtree_sum(t.parent, v))


def test_depth_and_tips():
    # chain 0 -> 1 -> 2 and a branch 0 -> 3
    t = Tree(np.zeros((4, 3)), np.ones((4, 3)), np.ones(4), np.ones(4), [-1, 0, 1, 0], [0] * 4)
    assert segment_depth(t.parent).tolist() == [0, 1, 2, 1]
    assert sorted(t.tips().tolist()) == [2, 3]
    t.alive[2] = False
    assert sorted(t.tips().tolist()) == [1, 3]
    assert t.subtree_mask(1).tolist() == [False, True, True, False]


def test_copy_is_independent_and_translated_moves_leaf_spheres():
    t = _random_tree(20)
    t.attrs["leaf_sphere_center"] = t.end[:3].copy()
    c = t.copy()
    c.end[0] += 5.0
    c.attrs["leaf_sphere_center"][0] += 1.0
    assert not np.allclose(c.end[0], t.end[0])
    assert not np.allclose(c.attrs["leaf_sphere_center"][0], t.attrs["leaf_sphere_center"][0])
    m = t.translated((1.0, 2.0, 3.0))
    assert np.allclose(m.attrs["leaf_sphere_center"], t.attrs["leaf_sphere_center"] + [1, 2, 3])
    assert np.allclose(m.metrics()["crown_centroid"],
                       np.array(t.metrics()["crown_centroid"]) + [1, 2, 3])


def test_metrics_use_leaf_spheres_and_keep_keys():
    t = _random_tree(30)
    m0 = t.metrics()
    for k in ("height", "crown_centroid", "crown_radius", "live_branches", "dead_branches",
              "leaves", "base"):
        assert k in m0
    t.attrs["leaf_sphere_center"] = np.array([[1.0, 5.0, 0.0], [-1.0, 5.0, 0.0]])
    m = t.metrics()
    assert m["crown_centroid"] == pytest.approx([0.0, 5.0, 0.0])
    assert m["crown_radius"] == pytest.approx(1.0)
    assert m["leaf_spheres"] == 2


def test_drop_dead_leaves_filters_leaves_and_spheres():
    t = Tree(np.zeros((3, 3)), np.ones((3, 3)), np.ones(3), np.ones(3), [-1, 0, 0], [0] * 3)
    t.leaves = Leaves(np.zeros((4, 3)), np.tile([0, 1.0, 0], (4, 1)), np.ones(4),
                      np.array([1, 1, 2, 2]), attrs={"sphere": np.array([0, 0, 1, 1])})
    t.attrs.update({"leaf_sphere_center": np.array([[0, 1.0, 0], [0, 2.0, 0]]),
                    "leaf_sphere_segment": np.array([1, 2]), "light": np.array([0.5, 0.1])})
    t.alive[1] = False
    t.drop_dead_leaves()
    assert len(t.leaves) == 2 and set(t.leaves.segment) == {2}
    assert t.leaves.attrs["sphere"].tolist() == [0, 0]
    assert t.attrs["leaf_sphere_segment"].tolist() == [2]
    assert t.attrs["light"].tolist() == [0.1]


def test_mesh_and_export(tmp_path):
    t = _random_tree(10)
    t.leaves = Leaves(t.end[:4], np.tile([0, 1.0, 0], (4, 1)), np.full(4, 0.1), np.arange(4))
    mesh = t.to_mesh(sides=6)
    assert len(mesh.faces) == 10 * 12 + 4 * 2
    assert (mesh.metadata["part"] == 1).sum() == 8
    for ext in ("ply", "glb", "obj"):
        p = t.export(tmp_path / f"t.{ext}")
        assert (tmp_path / f"t.{ext}").stat().st_size > 0 and p.endswith(ext)
    with pytest.raises(ParameterError):
        t.export(tmp_path / "t.xyz")
