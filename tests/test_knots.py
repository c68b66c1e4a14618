"""Paper 004 §3.3: knot equations 3.1-3.4, the knot rate and dormancy, against hand values."""
from __future__ import annotations

import numpy as np
import pytest

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees import knots as kn
from mitsuba_veg.trees import weber_penn as wp
from mitsuba_veg.trees.structure import KNOT, NORMAL, SPROUTED_KNOT


# ---- eqs 3.1 - 3.4 ----------------------------------------------------------------------------
def test_eq31_knot_length_hand_values():
    # 2 m branch, Contraction 4 ± 1, Random = +0.5, offset 0.25: 2 / 4.5 * 0.75
    assert kn.knot_length(2.0, 0.25, 4.0, 1.0, 0.5) == pytest.approx(1.0 / 3.0, rel=1e-12)
    # Random = -1 (the lower bound 4 - 1 = 3), offset 0: 2 / 3
    assert kn.knot_length(2.0, 0.0, 4.0, 1.0, -1.0) == pytest.approx(2.0 / 3.0)
    # a knot at the tip of its parent has no length
    assert kn.knot_length(2.0, 1.0, 4.0, 1.0, 0.3) == 0.0
    # vectorised
    np.testing.assert_allclose(kn.knot_length([1.0, 3.0], [0.5, 0.5], 2.0), [0.25, 0.75])


def test_eq32_knot_radius_hand_values():
    assert kn.knot_radius(0.1, 2.0, 0.5, -1.0) == pytest.approx(0.15)
    assert kn.knot_radius(0.1, 2.0, 0.5, 1.0) == pytest.approx(0.25)
    assert kn.knot_radius(0.04, 1.5) == pytest.approx(0.06)


def test_eq33_sprout_length_hand_values():
    # length_p 0.2 m, Contraction 10 ± 2 (Random 0.5), Length_N 0.6: 0.2 * 11 * 0.6
    assert kn.sprout_length(0.2, 10.0, 2.0, 0.6, 0.5) == pytest.approx(1.32)
    # eq 3.3 undoes eq 3.1's contraction: sprout = branch length * (1 - offset) * Length_N
    Lb, off, C = 3.0, 0.2, 8.0
    Lk = kn.knot_length(Lb, off, C)
    assert kn.sprout_length(Lk, C, 0.0, 0.5) == pytest.approx(Lb * (1 - off) * 0.5)


def test_eq34_sprout_radius_hand_values():
    # radius_p 0.05, Density 2.5 ± 0.5 (Random -1 -> 2.0), length ratio 4, RatioPower 1.3
    assert kn.sprout_radius(0.05, 0.8, 0.2, 2.5, 0.5, 1.3, -1.0) == pytest.approx(
        0.025 * 4.0 ** 1.3, rel=1e-12)
    # eq 3.4 undoes eq 3.2 when the sprout is as long as the knot
    rk = kn.knot_radius(0.03, 2.0)
    assert kn.sprout_radius(rk, 1.0, 1.0, 2.0, 0.0, 1.2) == pytest.approx(0.03)


# ---- knot rate ---------------------------------------------------------------------------------
def test_expected_knots_hand_iteration():
    # rate 0.5 halved by every knot, 4 normal buds wanted in the zone; by hand:
    # p = .5, .353553, .276705, .228425, .194972, then .170324 for the last 0.667316 bud
    assert kn.expected_knots(4.0, 0.5, 0.5) == pytest.approx(1.66731, abs=2e-5)  # 6 digits
    # constant rate r: E = n r / (1 - r)
    assert kn.expected_knots(10.0, 0.2, 0.0) == pytest.approx(2.5)
    assert kn.expected_knots(0.0, 0.5, 0.0) == 0.0
    np.testing.assert_allclose(kn.expected_knots(np.array([10.0, 4.0]), np.array([0.2, 0.5]),
                                                 np.array([0.0, 0.5])), [2.5, 1.66731], atol=2e-5)
    # rate 1 without decay is capped (no endless loop)
    assert kn.expected_knots(5.0, 1.0, 0.0) == pytest.approx(20.0)     # 4 x 5 buds, all knots


def test_assign_knots_rate_decreases_per_parent():
    row = np.array([0, 0, 0, 0, 1, 1])
    in_zone = np.array([True, True, True, True, True, True])
    forced = np.zeros(6, bool)
    u = np.array([0.1, 0.1, 0.3, 0.1, 0.6, 0.1])
    is_knot, used = kn.assign_knots(row, in_zone, forced, np.array([0.5, 0.5]), 0.5, u)
    # parent 0: .1 < .5 knot (rate -> .25); .1 < .25 knot (-> .125); .3 no; .1 < .125 knot
    np.testing.assert_array_equal(is_knot, [True, True, False, True, False, True])
    np.testing.assert_allclose(used, [0.5, 0.25, 0.125, 0.125, 0.5, 0.5])
    # forced knots (below BaseSize) and buds outside the zone
    is_knot, used = kn.assign_knots(np.array([0, 0, 0]), np.array([False, False, True]),
                                    np.array([True, False, False]), np.array([0.0]), 0.0,
                                    np.array([0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(is_knot, [True, False, False])


def test_dormancy_decreases_per_level():
    assert kn.dormancy_after(2.0) == 1.0
    assert kn.dormancy_after(2.0, 0.5) == 1.5
    np.testing.assert_array_equal(kn.sprouts(np.array([0.5, 1.0, 1.5])), [True, True, False])


# ---- knots in the generator --------------------------------------------------------------------
def _aspen(**kw):
    base = {"preset": "quaking_aspen", "SegSplits": [0, 0, 0, 0], "KnotRateV": 0.0,
            "KnotPositionV": 0.0}
    base.update(kw)
    return base


def test_branch_count_includes_knots_computed_in_advance():
    # constant rate 0.2 over the whole bearing trunk: 50 normal buds expected, so
    # E = 50 * 0.2 / 0.8 = 12.5 extra buds, 62.5 -> 63 by error diffusion
    t = wp.generate(_aspen(KnotRate=0.2, KnotRateDecay=0.0, KnotPosition=0.4), seed=5,
                    knots=True)
    st = t.weber_penn.stats["levels"][0]
    assert st["expected"] == pytest.approx(50.0)
    assert st["expected_knots"] == pytest.approx(12.5)
    assert st["buds"] == 63
    assert st["knots"] + st["branches"] == st["buds"]
    # level 1 on the tree: every bud became a stem unless too short (a knot right at the tip
    # has length ~0 by eq 3.1), knots have kind 1
    lv1 = t.level == 1
    first = lv1 & ~t.attrs["clone"] & (t.attrs["stem"][np.maximum(t.parent, 0)]
                                      != t.attrs["stem"])
    assert st["dropped_short"] <= 1
    assert first.sum() == 63 - st["dropped_short"]
    assert (t.kind[first] != NORMAL).sum() == st["knots"] - st["dropped_short"]
    # over many trees the normal branches average nBranches (knots do not thin the crown)
    normal = [wp.generate(_aspen(KnotRate=0.2, KnotRateDecay=0.0, KnotPosition=0.4), seed=s,
                          knots=True).weber_penn.stats["levels"][0]["branches"]
              for s in range(40)]
    assert np.mean(normal) == pytest.approx(50.0, abs=1.5)


def test_knots_off_gives_weber_penn_counts():
    t = wp.generate(_aspen(KnotRate=0.3), seed=1, knots=False)
    st = t.weber_penn.stats["levels"][0]
    assert st["buds"] == 50 and st["knots"] == 0
    assert not (t.kind != NORMAL).any()


def test_knot_position_below_base_size_turns_all_buds_into_knots():
    # BaseSize 0.4, knot position 0.2: the trunk from 0.2 to 0.4 carries 50/0.6*0.2 = 16.7 -> 17
    # buds, all knots; the rate applies above BaseSize
    t = wp.generate(_aspen(KnotRate=0.0, KnotPosition=0.2), seed=2, knots=True)
    st = t.weber_penn.stats["levels"][0]
    assert st["forced_knots"] == 17
    assert st["knots"] == 17 and st["branches"] == 50
    a = t.attrs
    first = (t.level == 1) & (a["stem"][np.maximum(t.parent, 0)] != a["stem"])
    L0 = a["stem_length"][0]
    h = a["arc"][t.parent[first]] + a["attach"][first] * np.linalg.norm(
        t.end[t.parent[first]] - t.start[t.parent[first]], axis=1)
    low = h < 0.4 * L0 - 1e-9
    assert low.sum() == 17
    assert np.all(t.kind[first][low] == KNOT)
    assert np.all(h[low] > 0.2 * L0 - 1e-9)


def test_dormancy_break_sprouts_and_subknots():
    # DormancyBreak 1: knots of level 1 sprout at level 2 (one branch each, eqs 3.3-3.4)
    p = _aspen(KnotRate=0.3, KnotPosition=0.4, DormancyBreak=1.0, DormancyBreakV=0.0,
               ContractionV=0.0, DensityV=0.0)
    t = wp.generate(p, seed=4, knots=True)
    a = t.attrs
    st = t.weber_penn.stats["levels"]
    n_knots1 = st[0]["knots"]
    assert n_knots1 > 0 and st[1]["sprouts"] == n_knots1 and st[1]["subknots"] == 0
    first = (t.parent >= 0) & (a["stem"][np.maximum(t.parent, 0)] != a["stem"]) & ~a["clone"]
    spr = first & a["sprout"]
    assert spr.sum() <= n_knots1                     # a sprout may be dropped if too thin
    parent_kind = t.kind[t.parent[spr]]
    assert np.all(parent_kind == SPROUTED_KNOT)
    # eq 3.3 with ContractionV = 0: length = knot length * Contraction * 2Length
    pk = t.weber_penn.params
    Lk = a["stem_length"][t.parent[spr]]
    np.testing.assert_allclose(a["stem_length"][spr],
                               Lk * pk.kn("Contraction", 1) * pk.lv("Length", 2), rtol=1e-9)
    # eq 3.4 (capped by the knot's radius at the bud, the Weber-Penn child rule)
    rk = a["stem_radius"][t.parent[spr]]
    raw = rk / pk.kn("Density", 1) * (a["stem_length"][spr] / Lk) ** pk["RatioPower"]
    assert np.all(a["stem_radius"][spr] <= raw * (1 + 1e-9))
    # DormancyBreak 2.5: level 2 holds sub-knots (value 1.5), nothing sprouts before level 3
    t2 = wp.generate(_aspen(KnotRate=0.3, KnotPosition=0.4, DormancyBreak=2.5,
                            DormancyBreakV=0.0), seed=4, knots=True)
    st2 = t2.weber_penn.stats["levels"]
    assert st2[1]["subknots"] == st2[0]["knots"] and st2[1]["sprouts"] == 0
    a2 = t2.attrs
    head = (t2.parent >= 0) & (a2["stem"][np.maximum(t2.parent, 0)] != a2["stem"])
    sub = head & (t2.level == 2) & (t2.kind == KNOT) & (t2.kind[np.maximum(t2.parent, 0)] == KNOT)
    knots1 = (t2.level == 1) & (t2.kind == KNOT)
    assert sub.any()
    np.testing.assert_allclose(np.unique(t2.attrs["dormancy"][sub]), [1.5])
    np.testing.assert_allclose(np.unique(t2.attrs["dormancy"][knots1]), [2.5])


def test_knot_geometry_follows_eqs_31_32():
    # no variation: every knot is its branch shortened by Contraction and (1 - offset) and
    # thickened by Density (checked against the same tree grown without knots' lengths)
    p = _aspen(KnotRate=1.0, KnotRateDecay=0.0, KnotPosition=0.4, ContractionV=0.0,
               DensityV=0.0, Contraction=10.0, Density=1.5, Levels=2, Leaves=0)
    t = wp.generate(p, seed=8, knots=True)
    a = t.attrs
    first = (t.level == 1) & (a["stem"][np.maximum(t.parent, 0)] != a["stem"])
    k = first & (t.kind != NORMAL)
    assert k.sum() == first.sum()                   # rate 1: every zone bud is a knot
    L0 = a["stem_length"][0]
    h = a["arc"][t.parent[k]] + a["attach"][k] * np.linalg.norm(
        t.end[t.parent[k]] - t.start[t.parent[k]], axis=1)
    prm = t.weber_penn.params
    ratio = np.clip((L0 - h) / (L0 * (1 - prm["BaseSize"])), 0, 1)
    Lb = L0 * (prm.lv("Length", 1)) * wp.shape_ratio(prm["Shape"], ratio)
    np.testing.assert_allclose(a["stem_length"][k], Lb / 10.0 * (1 - h / L0), rtol=1e-9)


def test_bad_knot_parameters_get_clear_errors():
    with pytest.raises(ParameterError, match="ContractionV"):
        wp.generate(_aspen(Contraction=2.0, ContractionV=2.0))
    with pytest.raises(ParameterError, match="KnotRate"):
        wp.generate(_aspen(KnotRate=1.5))
    with pytest.raises(ParameterError, match="SproutVariation"):
        wp.generate(_aspen(SproutVariation="Random"))


@pytest.mark.parametrize("variation", ["ContractionV", "DensityV"])
def test_eq33_variation_as_read_or_as_printed(variation):
    # only the variation named by SproutVariation makes the sprouts' lengths vary
    p = _aspen(KnotRate=0.4, KnotPosition=0.4, DormancyBreak=1.0, DormancyBreakV=0.0,
               ContractionV=0.0, DensityV=0.5, SproutVariation=variation)
    t = wp.generate(p, seed=6, knots=True)
    a = t.attrs
    head = (t.parent >= 0) & (a["stem"][np.maximum(t.parent, 0)] != a["stem"])
    spr = head & a["sprout"]
    assert spr.sum() >= 3
    ratio = a["stem_length"][spr] / a["stem_length"][t.parent[spr]]
    pk = t.weber_penn.params
    nominal = pk.kn("Contraction", 1) * pk.lv("Length", 2)
    if variation == "ContractionV":          # ContractionV = 0: no variation
        np.testing.assert_allclose(ratio, nominal, rtol=1e-9)
    else:                                    # as printed: Contraction ± DensityV·Random
        assert np.ptp(ratio) > 0
        assert np.all(np.abs(ratio / pk.lv("Length", 2) - pk.kn("Contraction", 1)) <= 0.5 + 1e-9)
