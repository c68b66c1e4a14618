"""Non-growth model of paper 002: the death rule on hand-set light, heliotropism as a rigid
rotation towards light, and the paper's 5 x 5 experiment as measured assertions."""
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees import Environment, GrowthParams, Leaves, Tree, branching
from mitsuba_veg.trees import nongrowth
from mitsuba_veg.trees.analysis import lean


def _binary(depth=2):
    """A symmetric binary tree: trunk + ``depth`` levels (segment 0 is the trunk)."""
    start, end, parent = [[0, 0, 0]], [[0, 1, 0]], [-1]
    frontier = [0]
    for _ in range(depth):
        nxt = []
        for p in frontier:
            for sx in (-1, 1):
                s = end[p]
                start.append(s)
                end.append([s[0] + 0.5 * sx, s[1] + 1, s[2]])
                parent.append(p)
                nxt.append(len(end) - 1)
        frontier = nxt
    n = len(end)
    return Tree(start, end, np.full(n, 0.05), np.full(n, 0.05), parent, np.zeros(n, int))


class _FakeLight:
    def __init__(self, values):
        self.values = np.asarray(values, float)
        self.stats = {}

    def light(self, points):
        return self.values


@pytest.mark.parametrize("order,count,alive_tips", [("bottom_up", "branches", 3),
                                                     ("simultaneous", "branches", 2),
                                                     ("bottom_up", "tips", 3),
                                                     ("simultaneous", "tips", 3)])
def test_death_rule_t_over_n(order, count, alive_tips):
    """Tips lit 0.5, 0.5, 0.5, 0.0, threshold 0.2. N = branches, simultaneous: the right
    subtree has T/N = 0.5/3 < 0.2 and dies whole; bottom up: the dark tip dies first, then
    the right subtree has T/N = 0.5/2 = 0.25 and lives. N = tips: the right subtree has
    T/N = 0.5/2 = 0.25 in both orders and lives; only the dark tip (0/1) dies."""
    t = _binary(2)
    stand = nongrowth._Stand([t])
    tips = stand.tips()
    assert len(tips) == 4
    st = nongrowth._death(stand, _FakeLight([0.5, 0.5, 0.5, 0.0]), tips, 0.2, order, count)
    assert stand.alive[0]
    assert np.isin(tips, np.nonzero(stand.alive)[0]).sum() == alive_tips
    assert st["died"] == 7 - stand.alive.sum()


def test_whole_tree_dies_in_the_dark():
    env = Environment().add_box((-30, 4.0, -30), (30, 5.0, 30))          # a roof over it
    res = nongrowth.deform(_binary(3), env, rules=("death",))
    assert res.trees.metrics()["live_branches"] == 0
    assert res.stats[0]["tip_light_mean"] < 1e-6


def test_heliotropism_rotates_rigidly_away_from_a_wall():
    t = branching(GrowthParams(branch_angle=45, lateral_length=5, random_phase=False), 6)
    t.leaves = Leaves(t.end[t.tips()] + [0, 0.1, 0], np.tile([0, 1.0, 0], (len(t.tips()), 1)),
                      np.full(len(t.tips()), 0.1), t.tips())
    wall = Environment().add_box((-3.0, 0, -10), (-2.5, 12, 10))
    res = nongrowth.deform(t, wall, rules=("heliotropism",))
    d = res.trees
    assert lean(d, t)[0] > 0.3                     # away from the wall at -x
    assert np.allclose(d.length, t.length)         # rigid rotations only
    ok = d.parent >= 0
    assert np.allclose(d.start[ok], d.end[d.parent[ok]], atol=1e-9)   # still connected
    assert np.allclose(d.start[0], t.start[0])     # the root's base is the pivot
    # leaves and leaf spheres follow their segments
    # (each leaf sat 0.1 m along its normal from its segment's end: still so, both rotated)
    off = d.leaves.position - d.end[d.leaves.segment]
    assert np.allclose(off, 0.1 * d.leaves.normal, atol=1e-9)
    assert not np.allclose(d.leaves.normal, [0, 1, 0])
    seg = d.attrs["leaf_sphere_segment"]
    assert np.allclose(d.attrs["leaf_sphere_center"], d.end[seg])
    assert res.stats[0]["rotations"] > 0 and res.stats[0]["angle_max_deg"] <= 30.0 + 1e-9
    # the input tree is unchanged
    assert not np.allclose(d.end, t.end)


def test_bad_input():
    with pytest.raises(ParameterError):
        nongrowth.deform(_binary(), rules=("grow",))
    with pytest.raises(ParameterError):
        nongrowth.deform(["not a tree"])
    with pytest.raises(ParameterError):
        nongrowth.deform(_binary(), death_order="random")


@pytest.fixture(scope="module")
def stand_5x5():
    """Paper 002 §6: 25 identical binary-branching sample trees on a 4 m grid."""
    sample = branching(GrowthParams(branch_angle=45, lateral_length=5, random_phase=False), 7)
    trees = [sample.translated((4.0 * i, 0.0, 4.0 * j)) for j in range(5) for i in range(5)]
    death = nongrowth.deform(trees, rules=("death",), death_threshold=0.5)
    helio = nongrowth.deform(death.trees, rules=("heliotropism",))
    return trees, death, helio


def _ring(values):
    v = np.asarray(values, float).reshape(5, 5)
    inner = v[1:4, 1:4].ravel()
    edge = np.concatenate([v[0], v[4], v[1:4, 0], v[1:4, 4]])
    return inner, edge, v


def test_paper002_death_thins_the_inside_of_the_stand(stand_5x5):
    """Fig 1-2: after the death rule the inner trees keep fewer branches (~153 of 255) than
    the edge trees (~204); the centre tree fewest (123), corners most (218-239)."""
    trees, death, _ = stand_5x5
    live = [t.metrics()["live_branches"] for t in death.trees]
    inner, edge, v = _ring(live)
    print("live branches\n", v)
    assert inner.mean() < 0.85 * edge.mean()
    assert v[2, 2] == min(live)
    assert min(v[0, 0], v[0, 4], v[4, 0], v[4, 4]) > inner.max()
    assert max(live) < 255              # even edge trees lose their inward branches


def test_paper002_heliotropism_leans_edge_trees_outwards(stand_5x5):
    """Fig 3-4: after heliotropism every edge tree's crown moves outwards (~1.3-2.1 m),
    more than the inner trees' (|mean| ~0.3 m)."""
    trees, death, helio = stand_5x5
    shift = [lean(a, b) for a, b in zip(helio.trees, death.trees)]
    bases = np.array([t.metrics()["base"] for t in trees])[:, [0, 2]]
    c = bases.mean(0)
    out = []
    for s, b in zip(shift, bases):
        n = np.linalg.norm(b - c)
        out.append(s @ (b - c) / n if n > 0 else np.nan)
    inner, edge, v = _ring(out)
    print("outward lean [m]\n", np.round(v, 2))
    assert np.all(edge > 0.5)
    assert edge.mean() > 3 * np.nanmean(np.abs(inner))


def test_weber_penn_trees_deform_with_leaf_shading():
    """Trees from another model (Weber-Penn, paper 004) are valid samples: leaves shade by
    their blade area, stems made of several segments count as one branch."""
    wp = pytest.importorskip("mitsuba_veg.trees.weber_penn")
    t = wp.generate("quaking_aspen", seed=0)
    res = nongrowth.deform([t, t.translated((3.0, 0.0, 0.0))], shade_from="leaves")
    live = [x.metrics()["live_branches"] for x in res.trees]
    assert all(0 < n < len(t) for n in live)
    assert res.stats[1]["rotations"] > 0
    for x in res.trees:
        assert np.all(x.alive[x.leaves.segment])        # leaves of dead branches are gone


@pytest.mark.parametrize("spacing, sample_kw", [(6.0, {}),
                                                (4.0, dict(branch_angle=45, lateral_length=5,
                                                           random_phase=False))])
def test_death_rule_has_no_cliff(spacing, sample_kw):
    """Issue: with N = branches a whole tree's T/N is about half its mean tip light, so on a
    5 x 5 stand of default trees 6 m apart nothing dies at 0.25 and every tree dies whole at
    0.4. With N = tips (the default) the thresholds 0.2-0.5 thin the stand gradually: no tree
    dies whole, live branches never increase with the threshold, and where branches die the
    inner trees lose more than the edge trees."""
    sample = branching(GrowthParams(**sample_kw), 7)
    trees = [sample.translated((spacing * i, 0.0, spacing * j))
             for j in range(5) for i in range(5)]
    prev = None
    table = {}
    for th in (0.2, 0.3, 0.4, 0.5):
        res = nongrowth.deform(trees, rules=("death",), death_threshold=th)
        live = np.array([t.metrics()["live_branches"] for t in res.trees])
        assert all(t.alive[0] for t in res.trees)            # trunks kept
        assert live.min() > 0.25 * len(sample)                # no tree dies whole
        if prev is not None:
            assert np.all(live <= prev)
        inner, edge, _ = _ring(live)
        if live.min() < len(sample):                          # partial death: inside first
            assert inner.mean() < edge.mean()
        table[th] = (inner.mean(), edge.mean())
        prev = live
    print(table)
    # the printed reading (N = branches) is the cliff: every tree dies whole at 0.4
    cliff = nongrowth.deform(trees, rules=("death",), death_threshold=0.4,
                             death_count="branches")
    if spacing == 6.0:
        assert sum(t.metrics()["live_branches"] for t in cliff.trees) == 0


def test_death_rule_on_leaf_light_by_hand():
    """Paper 002's death rule with a light per leaf (the world's yearly rule): the binary tree
    0 -> (1, 2), 1 -> (3, 4), 2 -> (5, 6) with one leaf on each tip, lights 0.9, 0.1, 0.2, 0.3,
    threshold 0.5. Bottom up: tips 4, 5, 6 die (< 0.5); segment 2 has no live leaf left (N = 0)
    and dies; segment 1 keeps leaf 3 (T/N = 0.9) and the trunk too. Judged on the intact tree
    (simultaneous) the trunk has 1.5 / 4 = 0.375 and the tree dies at 0.5; at 0.3 segment 1
    (0.5) and the trunk live, 2 (0.25) dies with 5 and 6 (6 has 0.3, not below, but falls with
    its parent), 4 (0.1) dies. A threshold above every leaf's light kills the whole tree."""
    t = _binary(2)
    tips = np.array([3, 4, 5, 6])
    t.leaves = Leaves(t.end[tips], np.tile([0.0, 0.0, 1.0], (4, 1)), np.full(4, 0.1), tips)
    t.weber_penn = {"preset": "test"}
    light = np.array([0.9, 0.1, 0.2, 0.3])
    res = nongrowth.death_by_leaf_light(t, light, 0.5)
    assert res.trees.alive.tolist() == [True, True, False, True, False, False, False]
    assert res.trees.leaves.segment.tolist() == [3] and res.stats[0]["died"] == 4
    assert res.trees.weber_penn == {"preset": "test"}          # still a Weber-Penn tree
    assert t.alive.all() and len(t.leaves) == 4                # the input is not changed
    # judged on the intact tree the trunk's leaves average 0.375: below 0.5 the tree dies
    sim = nongrowth.death_by_leaf_light(t, light, 0.5, order="simultaneous")
    assert not sim.trees.alive.any()
    sim = nongrowth.death_by_leaf_light(t, light, 0.3, order="simultaneous")
    assert sim.trees.alive.tolist() == [True, True, False, True, False, False, False]
    whole = nongrowth.death_by_leaf_light([t], [light], 0.95)
    assert not whole.trees[0].alive.any() and len(whole.trees[0].leaves) == 0
    assert whole.stats[0]["died_per_tree"] == [7]
    with pytest.raises(ParameterError, match="leaf_light"):
        nongrowth.death_by_leaf_light(t, light[:3], 0.5)
    with pytest.raises(ParameterError, match="order"):
        nongrowth.death_by_leaf_light(t, light, 0.5, order="top_down")
