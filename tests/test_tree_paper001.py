"""Paper 001's results (§3.2-3.3) as measured assertions, table 3.1 parameters, G = 10,
unit = 0.25 m (a ~19 m tree). The numbers in the comments are this code's, seed 0
(experiments/trees_001_results.py prints them all and draws the figures)."""
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.trees import Environment, GrowthParams, grow, grow_forest
from mitsuba_veg.trees.analysis import crown_shift, flatness, main_axis_length, outward_shift

P = GrowthParams()


@pytest.fixture(scope="module")
def ground():
    return Environment.flat_ground(80)


def test_two_close_trees_grow_away_from_each_other(ground):
    """§3.3.1 (fig 3.12): bases 6 m apart; each crown moves away from the other (~3-4 m)."""
    a, b = grow_forest([(-3.0, 0.0, 0.0), (3.0, 0.0, 0.0)], P, 10, ground, seed=0)
    out = outward_shift([a, b])
    alone = np.linalg.norm(crown_shift(grow(P, 10, scene=ground, seed=0)))
    print(f"outward shifts {out}, lone tree |shift| {alone:.2f} m")
    assert np.all(out > 1.5)
    assert alone < 0.6
    sep = a.metrics()["crown_centroid"][0] - b.metrics()["crown_centroid"][0]
    assert abs(sep) > 6.0 + 4.0


def test_forest_3x3(ground):
    """§3.3.2 (fig 3.14): 12 m grid; outer crowns shift outwards (~4-6 m), the centre crown is
    narrower (5.3 vs ~7.2 m) and at least as tall as the corner trees (19.2 vs ~18.9 m)."""
    pos = [(i * 12.0, 0.0, j * 12.0) for j in (-1, 0, 1) for i in (-1, 0, 1)]
    trees = grow_forest(pos, P, 10, ground, seed=0)
    out = outward_shift(trees, centre=(0.0, 0.0))
    ms = [t.metrics() for t in trees]
    corners = [ms[k] for k in (0, 2, 6, 8)]
    r_c, h_c = ms[4]["crown_radius"], ms[4]["height"]
    r_k = np.mean([m["crown_radius"] for m in corners])
    h_k = np.mean([m["height"] for m in corners])
    print(f"outward {np.round(out, 2)}; centre r {r_c:.2f} h {h_c:.2f}; corners r {r_k:.2f} "
          f"h {h_k:.2f}")
    assert np.all(np.delete(out, 4) > 1.0)
    assert r_c < 0.9 * r_k
    assert h_c >= h_k


def test_tree_beside_a_wall_grows_away_from_it():
    """§3.3.3 (fig 3.16): a 20 m wall 3 m west of the tree; the crown moves east (~5 m) and
    most leaf spheres are on the far side."""
    env = Environment().add_ground(60).add_box((-4, 0, -15), (-3, 20, 15), max_edge=2.0)
    t = grow(P, 10, scene=env, seed=0)
    dx = crown_shift(t)[0]
    far = np.mean(t.attrs["leaf_sphere_center"][:, 0] > 0)
    print(f"shift away from the wall {dx:.2f} m, leaf spheres on the far side {far:.2f}")
    assert dx > 2.0 and far > 0.75


def test_tree_on_a_slope_shifts_downhill(ground):
    """§3.3.4 (fig 3.19): 30 deg slope going down towards +x; the crown shifts downhill
    (~1.5 m) compared with the same tree on flat ground (~-0.2 m)."""
    slope = Environment().add_slope(30.0, 60.0)
    s = grow(P, 10, position=(0.0, 0.0), scene=slope, seed=0)
    f = grow(P, 10, scene=ground, seed=0)
    ds, df = crown_shift(s)[0], crown_shift(f)[0]
    print(f"downhill shift: slope {ds:.2f} m, flat {df:.2f} m")
    assert ds - df > 0.8


def test_higher_death_threshold_fewer_live_branches():
    """§3.2.3 (fig 3.5): T_D 0.1 / 0.2 / 0.3 / 0.4 -> ~1480 / 1150 / 950 / 800 live branches."""
    live = [grow(P.replace(death_threshold=td), 10, seed=0).metrics()["live_branches"]
            for td in (0.1, 0.2, 0.3, 0.4)]
    print("live branches", live)
    assert all(a > b for a, b in zip(live, live[1:]))


def test_smaller_branch_angle_taller_narrower():
    """§3.2.1 (fig 3.2): θ = 30 deg vs 60 deg: taller (20.5 vs 19.1 m), not wider, higher
    height : crown radius."""
    m30 = grow(P.replace(branch_angle=30.0), 10, seed=0).metrics()
    m60 = grow(P, 10, seed=0).metrics()
    print(f"30 deg: h {m30['height']:.2f} r {m30['crown_radius']:.2f}; "
          f"60 deg: h {m60['height']:.2f} r {m60['crown_radius']:.2f}")
    assert m30["height"] > m60["height"] + 0.5
    assert m30["crown_radius"] <= m60["crown_radius"]
    assert m30["height"] / m30["crown_radius"] > 1.05 * m60["height"] / m60["crown_radius"]


def test_half_phyllotaxis_flat_crown():
    """§3.2.9 (fig 3.11): 1/2 phyllotaxis puts all laterals in one plane: a flat crown
    (flatness ~0.6) against ~0.9 for 1/3, 2/5, 5/8."""
    f = {ph: flatness(grow(P.replace(phyllotaxis=ph), 10, seed=0)) for ph in ("1/2", "2/5",
                                                                             "5/8")}
    print("flatness", f)
    assert f["1/2"] < 0.75
    assert min(f["2/5"], f["5/8"]) > f["1/2"] + 0.15


def test_lower_red_far_red_lengthens_main_axes():
    """§2.3.4 / §3.2.7: stronger shade signal (far-red passing leaves more easily, α_fr
    0.3 -> 0.7 -> 0.9, so lower R:FR behind leaves) makes more shade avoidance: main-axis
    segments get longer (1.00 -> 1.07 -> 1.32 m)."""
    trees = [grow(P.replace(alpha_far_red=a), 10, seed=0) for a in (0.3, 0.7, 0.9)]
    lm = [main_axis_length(t) for t in trees]
    rfr = [float(np.median(t.attrs["red_far_red"])) for t in trees]
    print("main-axis length", lm, "median R:FR", rfr)
    assert lm[0] == pytest.approx(P.main_length * P.unit)      # R:FR = 1: never shaded
    assert lm[0] < lm[1] < lm[2]
    assert rfr[0] > rfr[1] > rfr[2]
