"""Autumn logical time, stages, leaf fall, the Barnsley maple leaf and its aging (paper 003), and
red/far-red attenuations from leaf spectra (paper 001's α_r, α_fr)."""
import numpy as np
import pytest

import mitsuba_veg.foliage as fo
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.foliage.attenuation import (FORWARD_R, FORWARD_T, absorbed_fraction,
                                             red_far_red_attenuation)
from mitsuba_veg.foliage.spectra import leaf_spectra
from mitsuba_veg.foliage.autumn import AutumnParams, autumn_time
from mitsuba_veg.foliage.canopy import sphere_crown_tree
from mitsuba_veg.foliage.ifs import MAPLE_IFS, chaos_game, fixed_point, leaf_image, maple_leaf
from mitsuba_veg.foliage.insolation import leaf_insolation, sun_path


# ---- autumn logical time ----------------------------------------------------------------------
def test_tau_is_cumulative_insolation_over_H_full():
    daily = np.array([[10.0] * 30, [5.0] * 30, [0.0] * 30])
    st = autumn_time(daily, AutumnParams(insolation_full=100.0, time_weight=0.0, rate_sigma=0.0))
    assert st.tau(9).tolist() == pytest.approx([1.0, 0.5, 0.0])
    assert st.stage(4).tolist() == pytest.approx([1 + 6 * 0.5, 1 + 6 * 0.25, 1.0])
    # time share: a shaded leaf still colours, later
    st2 = autumn_time(daily, AutumnParams(insolation_full=100.0, time_weight=0.5, days_full=30,
                                          rate_sigma=0.0))
    assert st2.tau(-1)[2] == pytest.approx(0.5)
    # onset: nothing counts before it
    st3 = autumn_time(daily, AutumnParams(insolation_full=100.0, time_weight=0.0, onset_day=20,
                                          rate_sigma=0.0))
    assert st3.tau(19).tolist() == [0.0, 0.0, 0.0] and st3.tau(-1)[0] == pytest.approx(1.0)


def test_random_rates_and_leaf_fall():
    daily = np.full((5000, 60), 5.0)
    p = AutumnParams(insolation_full=150.0, time_weight=0.0, rate_sigma=0.2, fall=True,
                     fall_tau=1.9, fall_sigma=0.1)
    st = autumn_time(daily, p, seed=3)
    assert np.std(np.log(st.rate)) == pytest.approx(0.2, rel=0.05)
    fd = st.fall_day()
    assert (st.fallen(-1) == (fd >= 0)).all()
    assert 0.4 < st.fallen(-1).mean() < 0.8          # median leaf falls at τ_raw = 1.9 ~ day 57
    assert (st.tau_raw[fd >= 0, fd[fd >= 0]] >= st.fall_threshold[fd >= 0]).all()
    assert not autumn_time(daily, AutumnParams()).fallen(-1).any()
    pig = st.pigments(30, seed=1)
    assert pig["Anth"].shape == (5000,) and pig["Anth"].std() > 0
    with pytest.raises(ParameterError):
        autumn_time(daily, AutumnParams(insolation_full=-1))
    with pytest.raises(ParameterError):
        autumn_time(-daily)


@pytest.fixture(scope="module")
def tree_autumn():
    tree = sphere_crown_tree(4000, seed=1)
    path = sun_path(35.0, 139.0, "2026-10-01", days=40)
    ins = leaf_insolation(tree, path)
    st = autumn_time(ins, AutumnParams(), seed=0)
    return tree, ins, st


def test_sunny_outer_leaves_colour_before_shaded_inner_leaves(tree_autumn):
    tree, ins, st = tree_autumn
    r = np.linalg.norm(tree.leaves.position - [0, 3.0, 0], axis=1)
    outer, inner = r > 0.8 * 1.5, r < 0.4 * 1.5
    for day in (14, 29, 39):
        assert st.tau(day)[outer].mean() > st.tau(day)[inner].mean() + 0.1
    assert ins.cumulative[outer].mean() > 1.4 * ins.cumulative[inner].mean()
    # south side (sun side, +z) ahead of the north side
    south = tree.leaves.position[:, 2] > 1.0
    north = tree.leaves.position[:, 2] < -1.0
    assert st.tau(29)[south].mean() > st.tau(29)[north].mean()


def test_stage_rises_with_cumulative_insolation(tree_autumn):
    tree, ins, st = tree_autumn
    H = ins.cumulative
    s = st.stage(-1)
    q = np.quantile(H, [0.0, 0.25, 0.5, 0.75, 1.0])
    means = [s[(H >= a) & (H <= b)].mean() for a, b in zip(q[:-1], q[1:])]
    assert np.all(np.diff(means) > 0)
    assert np.corrcoef(H, s)[0, 1] > 0.6


# ---- the maple leaf ---------------------------------------------------------------------------
def test_chaos_game_stays_on_the_attractor():
    pts, addr = chaos_game(50_000, seed=1)
    assert pts.shape == (50_000, 2) and addr.shape == (50_000,)
    assert pts.min() > 0.05 and pts.max() < 0.95
    # the attractor is invariant: mapping points by any w_i gives points near the set (within
    # 0.01 of one of the 50,000; points drawn uniformly over the same box: 40 % farther)
    from scipy.spatial import cKDTree
    from mitsuba_veg.foliage.ifs import _apply
    tree = cKDTree(pts)
    for m in MAPLE_IFS:
        assert tree.query(_apply(m, pts[::25]))[0].max() < 0.01
    u = np.random.default_rng(0).uniform(pts.min(0), pts.max(0), (2000, 2))
    assert (tree.query(u)[0] > 0.01).mean() > 0.2
    base = fixed_point(MAPLE_IFS[0])
    assert base == pytest.approx([0.5, 0.3])
    assert fixed_point(MAPLE_IFS[1]) == pytest.approx([0.5, 0.93])


@pytest.fixture(scope="module")
def leaf():
    return maple_leaf(60_000, seed=0)


def test_aging_highest_at_margin_and_tip(leaf):
    a = leaf.aging
    assert a.min() == 0.0 and a.max() == 1.0
    margin = leaf.components["margin"]
    assert a[margin > 0.9].mean() > a[margin < 0.3].mean() + 0.2
    tip = leaf.components["tip"]
    assert a[tip > 0.8].mean() > a[tip < 0.3].mean() + 0.2


def test_colour_area_follows_ishikura_and_moves_inwards(leaf):
    tb = fo.stage_table()
    depth = 1.0 - leaf.components["margin"]          # 0 at the margin, 1 deepest inside
    prev = -1.0
    for s in range(1, 8):
        w = leaf.state_weights(float(s))
        coloured = w[:, 1] + w[:, 2]
        assert coloured.mean() == pytest.approx(tb.coloured[s - 1], abs=0.12)
        assert w[:, 2].mean() == pytest.approx(tb.red[s - 1], abs=0.15)
        assert np.allclose(w.sum(1), 1.0)
        if 2 <= s <= 4:   # the coloured front moves inwards
            front = np.average(depth, weights=coloured + 1e-12)
            assert front > prev
            prev = front
    img1 = leaf_image(leaf, stage=1, size=64)
    img7 = leaf_image(leaf, stage=7, size=64)
    blade = (img1 < 0.99).any(axis=2)
    assert img1[blade][:, 1].mean() > img1[blade][:, 0].mean()   # green
    assert img7[blade][:, 0].mean() > img7[blade][:, 1].mean()   # red
    with pytest.raises(ParameterError):
        leaf_image(leaf, size=8)


# ---- red / far-red attenuation ----------------------------------------------------------------
def test_forward_scatter_fractions_for_spherical_leaves():
    """Monte Carlo check of 5/6 (transmitted) and 1/6 (reflected) going forward."""
    rng = np.random.default_rng(0)
    n = 400_000
    nrm = rng.standard_normal((n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    d = np.array([0.0, 0.0, -1.0])                      # beam direction
    c = nrm @ d
    w = np.abs(c)                                       # interception weight
    m = np.where(c[:, None] < 0, nrm, -nrm)                      # facing the beam: m . d < 0
    # cosine lobes: transmitted around -m, reflected around +m
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], 1)
    a = np.where(np.abs(m[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t1 = np.cross(m, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(m, t1)
    lobe = local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:] * m
    fwd_r = np.average((lobe @ d) > 0, weights=w)
    fwd_t = np.average((-lobe @ d) > 0, weights=w)
    assert fwd_t == pytest.approx(FORWARD_T, abs=0.005)
    assert fwd_r == pytest.approx(FORWARD_R, abs=0.005)


def test_alpha_r_alpha_fr_from_leaf_spectra():
    green = red_far_red_attenuation(tau=0.0)
    assert green["alpha_par"] == pytest.approx(0.3)             # paper 001's α_l
    assert green["alpha_r"] < green["alpha_fr"]                  # red lost more than far-red
    assert green["alpha_r"] == pytest.approx(0.3, abs=0.05)     # paper: 0.3
    assert green["alpha_fr"] == pytest.approx(0.7, abs=0.15)    # paper: 0.7
    red = red_far_red_attenuation(tau=1.0)
    assert red["alpha_r"] > green["alpha_r"] + 0.1              # autumn leaves pass more red
    assert red["alpha_r"] / red["alpha_fr"] > green["alpha_r"] / green["alpha_fr"]
    # an explicit gap fraction / leaf area along the path
    g0 = red_far_red_attenuation(tau=0.0, gap_fraction=0.0)
    s = fo.leaf_spectra(tau=0.0)
    R, T = s.band_mean(655, 665)
    assert g0["alpha_r"] == pytest.approx((5 * T + R) / 6)
    assert red_far_red_attenuation(tau=0.0, lai_path=0.0)["alpha_r"] == pytest.approx(1.0)
    ab = absorbed_fraction(s)
    assert ab["r"] == pytest.approx(1 - R - T) and ab["r"] > 0.9 and ab["fr"] < 0.3


def test_apply_to_tree_stores_leaf_attributes(tree_autumn):
    """The leaves carry the state of the day asked for (not the last day's), and a subset of
    the leaves keeps its rows of every attribute."""
    tree, ins, st = tree_autumn
    fo.apply_to_tree(tree, st, day=20)
    a = tree.leaves.attrs
    assert a["autumn_stage"].shape == (len(tree.leaves),)
    np.testing.assert_array_equal(a["autumn_tau"], st.tau(20))
    assert np.abs(a["autumn_tau"] - st.tau(-1)).max() > 0.05     # day 20, not day 39
    assert np.allclose(a["autumn_stage"], 1 + 6 * a["autumn_tau"])
    np.testing.assert_array_equal(a["fallen"], st.fallen(20))
    p = st.pigments(20, seed=0)
    for k, name in (("cab", "Cab"), ("car", "Car"), ("anth", "Anth")):
        np.testing.assert_array_equal(a[k], p[name])
    assert (a["anth"] >= 0).all()
    keep = a["autumn_tau"] > 0.5
    assert 0 < keep.sum() < len(keep)
    sub = tree.leaves.subset(keep)
    np.testing.assert_array_equal(sub.attrs["cab"], a["cab"][keep])
    np.testing.assert_array_equal(sub.attrs["autumn_tau"], a["autumn_tau"][keep])


def test_growth_params_take_alphas_from_leaf_spectra():
    from mitsuba_veg.foliage.attenuation import growth_alphas, with_leaf_optics
    g = growth_alphas(0.0)
    assert g["alpha"] == pytest.approx(0.3) and g["alpha_red"] < g["alpha_far_red"]
    growth = pytest.importorskip("mitsuba_veg.trees.growth")
    with pytest.raises(ParameterError, match="spectra/tau"):
        growth_alphas(0.5, spectra=leaf_spectra(tau=0.5))    # one of them, never both
    p = with_leaf_optics(growth.GrowthParams(), tau=1.0)
    assert p.alpha_red == pytest.approx(red_far_red_attenuation(tau=1.0)["alpha_r"])
    assert p.alpha_red > growth.GrowthParams().alpha_red
    with pytest.raises(ParameterError):
        with_leaf_optics(object())
