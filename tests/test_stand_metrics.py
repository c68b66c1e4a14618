"""Tree metrics for a stand's table (mitsuba_veg.trees.stand_metrics), against hand values."""
from __future__ import annotations

import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees.stand_metrics import COLUMNS, crown_radius, stand_table, tree_metrics
from mitsuba_veg.trees.structure import Leaves, Tree
from mitsuba_veg.world.trees import WorldTree


def small_tree():
    """A trunk (0,0,0)-(0,2,0), a live branch to (1,3,0), a dead one to (-1,2.5,0), a live
    twig (1,3,0)-(1,3.5,0); three horizontal leaves (normal +y, so their corners keep the
    centre's height) of sizes 0.2, 0.2, 0.4."""
    start = [[0, 0, 0], [0, 2, 0], [0, 2, 0], [1, 3, 0]]
    end = [[0, 2, 0], [1, 3, 0], [-1, 2.5, 0], [1, 3.5, 0]]
    leaves = Leaves(position=np.array([[1.0, 3.6, 0.0], [0.0, 2.2, 1.0], [1.0, 3.0, -1.0]]),
                    normal=np.tile([0.0, 1.0, 0.0], (3, 1)), size=np.array([0.2, 0.2, 0.4]),
                    segment=np.array([3, 0, 1]), up=np.tile([1.0, 0.0, 0.0], (3, 1)))
    return Tree(start, end, [0.1, 0.05, 0.05, 0.02], [0.08, 0.03, 0.03, 0.01], [-1, 0, 0, 1],
                [0, 1, 1, 1], alive=[True, True, False, True], leaves=leaves, name="small")


def test_crown_radius_is_the_90th_percentile_by_hand():
    # (x, z) with mean (0, 0); distances 3, 1, 2, 4, sqrt(8): sorted 1, 2, 2.83, 3, 4; the 90th
    # percentile (linear) sits at rank 0.9 x 4 = 3.6: 3 + 0.6 x (4 - 3) = 3.6
    p = np.array([[3, 1, 0], [-1, 7, 0], [0, 2, 2], [0, 0, -4], [-2, 5, 2]], float)
    assert crown_radius(p) == pytest.approx(3.6)
    assert crown_radius(np.zeros((0, 3))) == 0.0


def test_metrics_of_a_small_tree_by_hand():
    m = tree_metrics(small_tree())
    # top: leaf 0 at y = 3.6 (twig end 3.5, dead branch excluded); base y = 0
    assert m["height"] == pytest.approx(3.6)
    # leaf centres (1, 0), (0, 1), (1, -1) in (x, z): mean (2/3, 0); distances
    # sqrt(1/9), sqrt(4/9 + 1), sqrt(1/9 + 1); 90th percentile of three sorted values
    d = np.sort([1 / 3, math.sqrt(4 / 9 + 1), math.sqrt(1 / 9 + 1)])
    assert m["crown_radius"] == pytest.approx(d[1] + 0.8 * (d[2] - d[1]))
    assert m["leaf_area"] == pytest.approx(0.6 * (0.04 + 0.04 + 0.16))
    assert (m["leaves"], m["live_branches"], m["dead_branches"]) == (3, 3, 1)
    assert (m["x"], m["y"], m["z"]) == (0.0, 0.0, 0.0) and m["name"] == "small"
    # without the top leaf: height from the twig end 3.5, two leaves
    m2 = tree_metrics(small_tree(), on_tree=[False, True, True])
    assert m2["height"] == pytest.approx(3.5) and m2["leaves"] == 2
    assert m2["leaf_area"] == pytest.approx(0.6 * 0.2)
    # bare: the crown points are the live segment ends (0,2,0), (1,3,0), (1,3.5,0): mean x 2/3
    bare = tree_metrics(small_tree(), on_tree=[False] * 3)
    d = np.sort([2 / 3, 1 / 3, 1 / 3])
    assert bare["crown_radius"] == pytest.approx(d[1] + 0.8 * (d[2] - d[1]))
    assert bare["leaf_area"] == 0.0 and bare["height"] == pytest.approx(3.5)


def test_world_trees_and_mesh_trees_in_one_table():
    t = small_tree().translated((5.0, 1.0, -2.0))
    quads = np.array([[[5.5, 4.0, -2], [5.7, 4.0, -2], [5.7, 4.9, -2], [5.5, 4.9, -2]],
                      [[4.0, 3.0, -1], [4.2, 3.0, -1], [4.2, 3.2, -1], [4.0, 3.2, -1]]])
    wt = WorldTree("oak", "growth", np.array([5.0, 1.0, -2.0]), (np.zeros((0, 3)),
                   np.zeros((0, 3), int)), quads, np.array([0.18, 0.04]), t)
    # a user's mesh tree: no branch structure, wood vertices up to y = 6
    wood = (np.array([[10, 0.5, 10], [10, 6.0, 10], [10.5, 0.5, 10]]), np.array([[0, 1, 2]]))
    tri = np.array([[[9, 4, 10], [11, 4, 10], [10, 5, 10]]], float)
    mt = WorldTree("mine", "mesh", np.array([10.0, 0.5, 10.0]), wood, tri, np.array([2.0]))
    rows = stand_table([wt, mt], on_tree=[None, [True]], year=3)
    assert list(rows[0]) == ["year", *COLUMNS]
    a, b = rows
    assert a["year"] == 3 and a["tree"] == 0 and a["name"] == "oak" and a["model"] == "growth"
    # world tree: base (5, 1, -2); top = leaf corner 4.9 -> 3.9 m (structure top 4.5)
    assert a["height"] == pytest.approx(3.9)
    assert a["leaf_area"] == pytest.approx(0.22) and a["leaves"] == 2
    assert (a["live_branches"], a["dead_branches"]) == (3, 1)
    c = quads.mean(axis=1)[:, [0, 2]]              # (5.6, -2), (4.1, -1): both 0.901 from mean
    assert a["crown_radius"] == pytest.approx(np.hypot(*(c[0] - c.mean(0))))
    assert b["height"] == pytest.approx(5.5) and b["live_branches"] is None
    assert b["leaf_area"] == 2.0 and b["crown_radius"] == 0.0
    with pytest.raises(ParameterError):
        stand_table([wt], on_tree=[None, None])
    with pytest.raises(ParameterError):
        tree_metrics(wt, on_tree=[True])
