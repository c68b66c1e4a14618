"""Stand layout (mitsuba_veg.trees.stand): spacing, density, clumping, seeds, slopes, refusals."""
from __future__ import annotations

import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.forest_floor import rolling_ground
from mitsuba_veg.trees.stand import (StandSpec, clark_evans, inside_polygon, layout,
                                     poisson_disc, polygon_area, variant_seed)

HA = [0.0, 0.0, 100.0, 100.0]


def _nn_by_hand(xz):
    """Nearest-neighbour distance of every point, all pairs by brute force."""
    d = np.hypot(xz[:, None, 0] - xz[None, :, 0], xz[:, None, 1] - xz[None, :, 1])
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def _R_by_hand(xz, area):
    """Clark & Evans (1954): mean NN distance over 0.5 / sqrt(density)."""
    return _nn_by_hand(xz).mean() / (0.5 / math.sqrt(len(xz) / area))


def test_clark_evans_of_a_square_lattice():
    # four corners of a 1 m square in a 2 m x 2 m window: NN distance 1 m, density 1 m-2,
    # expected NN distance 0.5 m -> R = 2
    pts = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    assert clark_evans(pts, 4.0) == pytest.approx(2.0)
    # a pair 0.1 m apart plus a far point: NN 0.1, 0.1, ~7.07; n = 3 in 100 m2
    pts = np.array([[0, 0], [0.1, 0], [5, 5]], float)
    r_obs = (0.1 + 0.1 + math.hypot(4.9, 5)) / 3
    assert clark_evans(pts, 100.0) == pytest.approx(r_obs / (0.5 / math.sqrt(3 / 100)))


def test_poisson_disc_keeps_the_spacing_and_the_density_on_one_hectare():
    st = layout(StandSpec(plot=HA, density=400, min_spacing=3.0, seed=3))
    xz = st.positions[:, [0, 2]]
    assert len(st) == 400 and st.density == pytest.approx(400.0)
    assert st.area == pytest.approx(1e4)
    assert _nn_by_hand(xz).min() >= 3.0
    assert np.all((xz >= 0) & (xz <= 100))
    # spread evenly: each quarter hectare holds 100 +- 20 trees
    q = np.histogram2d(xz[:, 0], xz[:, 1], bins=2, range=[[0, 100], [0, 100]])[0]
    assert np.all(np.abs(q - 100) <= 20), q


def test_the_fill_itself_is_denser_than_asked_and_spaced():
    fill = poisson_disc(HA, 3.0, seed=0)
    assert _nn_by_hand(fill).min() >= 3.0
    # Bridson's fill: 0.62 / s^2 measured (POISSON_DISC_FILL = 0.6 is the refused limit)
    assert 0.6 <= len(fill) * 9.0 / 1e4 <= 0.68


def test_clumped_gives_R_below_one_and_poisson_disc_above():
    common = dict(plot=HA, density=400, seed=5)
    pd = layout(StandSpec(**common, min_spacing=3.0))
    th = layout(StandSpec(**common, placement="clumped", cluster="thomas", cluster_radius=4.0,
                          parent_density=20, min_spacing=1.0))
    ma = layout(StandSpec(**common, placement="clumped", cluster="matern", cluster_radius=6.0,
                          parent_density=20, min_spacing=0.0))
    for st in (pd, th, ma):
        assert len(st) == 400
        assert st.clark_evans() == pytest.approx(_R_by_hand(st.positions[:, [0, 2]], 1e4))
    assert _R_by_hand(pd.positions[:, [0, 2]], 1e4) > 1.2
    assert _R_by_hand(th.positions[:, [0, 2]], 1e4) < 0.9
    assert _R_by_hand(ma.positions[:, [0, 2]], 1e4) < 0.7
    assert _nn_by_hand(th.positions[:, [0, 2]]).min() >= 1.0       # the hard core holds


def test_same_seed_same_stand_and_streams_are_independent():
    spec = dict(plot=HA, density=300, min_spacing=2.5, seed=11,
                mix={"quaking_aspen": 2, "black_tupelo": 1, "growth": 1})
    a, b = layout(StandSpec(**spec)), layout(StandSpec(**spec))
    for k in ("positions", "heights", "yaw", "seeds", "variants"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    np.testing.assert_array_equal(a.species, b.species)
    c = layout(StandSpec(**{**spec, "seed": 12}))
    assert not np.allclose(a.positions[:10], c.positions[:10])
    # another height spread moves no tree: every choice has its own stream
    d = layout(StandSpec(**{**spec, "height_cv": 0.3}))
    np.testing.assert_array_equal(a.positions, d.positions)
    np.testing.assert_array_equal(a.species, d.species)
    assert not np.allclose(a.heights, d.heights)


def test_species_mix_heights_and_variants():
    st = layout(StandSpec(plot=HA, density=500, min_spacing=2.0, seed=2, variants=3,
                          mix={"quaking_aspen": 3, "sassafras": 1, "growth": 1},
                          height_mean=12.0, height_cv=0.5, height_range=[8.0, 16.0]))
    share = {s: float(np.mean(st.species == s)) for s in ("quaking_aspen", "sassafras", "growth")}
    assert share["quaking_aspen"] == pytest.approx(0.6, abs=0.07)
    assert share["sassafras"] == pytest.approx(0.2, abs=0.06)
    assert np.all(st.variants[st.species == "growth"] == -1)
    wp = st.species != "growth"
    assert set(st.variants[wp]) == {0, 1, 2}
    assert st.variant_keys() == [(s, v) for s in ("quaking_aspen", "sassafras") for v in range(3)]
    assert st.heights.min() == 8.0 and st.heights.max() == 16.0      # clipped, both sides hit
    assert np.all((st.heights >= 8.0) & (st.heights <= 16.0))
    assert len(set(st.seeds.tolist())) == len(st)
    assert st.variant_seed("sassafras", 1) == variant_seed(2, "sassafras", 1)
    assert st.variant_seed("sassafras", 1) != st.variant_seed("sassafras", 2)
    rows = st.rows()
    assert rows[7]["height"] == st.heights[7] and rows[7]["species"] == st.species[7]


def test_tree_bases_follow_a_sloped_heightfield():
    ground = rolling_ground((0, 0, 100, 100), slope_deg=25.0, aspect_deg=90.0, resolution=2.0)
    st = layout(StandSpec(plot=[5, 5, 95, 95], density=200, min_spacing=3.0, seed=1), ground)
    x, y, z = st.positions.T
    # east-facing 25 deg plane through (50, 0, 50): y = -tan(25 deg) (x - 50)
    np.testing.assert_allclose(y, -math.tan(math.radians(25.0)) * (x - 50.0), atol=1e-9)
    rough = rolling_ground((0, 0, 100, 100), slope_deg=10.0, roughness=0.5, seed=4)
    st2 = layout(StandSpec(plot=[5, 5, 95, 95], density=200, min_spacing=3.0, seed=1), rough)
    np.testing.assert_array_equal(st2.positions[:, 1],
                                  rough.height(st2.positions[:, 0], st2.positions[:, 2]))
    assert layout(StandSpec(plot=HA, density=50, min_spacing=3.0), 2.5).positions[:, 1].max() \
        == 2.5


def test_transforms_place_scale_and_turn_each_variant():
    st = layout(StandSpec(plot=HA, density=30, min_spacing=3.0, seed=9, variants=2))
    h0 = {k: 10.0 for k in st.variant_keys()}
    M = st.transforms(h0)
    for i in (0, 5):
        s = st.heights[i] / 10.0
        a = math.radians(st.yaw[i])
        top = M[i] @ np.array([0.0, 10.0, 0.0, 1.0])
        np.testing.assert_allclose(top[:3], st.positions[i] + [0, st.heights[i], 0])
        # +x of the mesh turns by the yaw about +y (right-handed): (cos a, 0, -sin a)
        east = M[i] @ np.array([1.0, 0.0, 0.0, 1.0])
        np.testing.assert_allclose(east[:3], st.positions[i] + s * np.array([math.cos(a), 0,
                                                                             -math.sin(a)]))


def test_polygon_plot():
    poly = [[0, 0], [100, 0], [100, 50], [50, 50], [50, 100], [0, 100]]     # an L: 0.75 ha
    assert polygon_area(poly) == 7500.0
    assert list(inside_polygon([[75, 75], [25, 75], [75, 25]], poly)) == [False, True, True]
    st = layout(StandSpec(plot=poly, density=300, min_spacing=3.0, seed=2))
    assert len(st) == 225
    assert inside_polygon(st.positions[:, [0, 2]], poly).all()
    assert _nn_by_hand(st.positions[:, [0, 2]]).min() >= 3.0
    cl = layout(StandSpec(plot=poly, density=300, placement="clumped", cluster_radius=3.0,
                          parent_density=15, min_spacing=0.5, seed=2))
    assert len(cl) == 225 and inside_polygon(cl.positions[:, [0, 2]], poly).all()


def test_impossible_specs_are_refused_with_field_value_range_and_fix():
    with pytest.raises(ParameterError) as e:
        StandSpec(plot=HA, density=800, min_spacing=3.0)
    assert e.value.field == "density" and "667 trees/ha" in e.value.allowed
    assert "min_spacing <= 2.74" in e.value.fix
    with pytest.raises(ParameterError) as e:      # beyond even hexagonal packing
        StandSpec(plot=HA, density=2000, min_spacing=3.0, placement="clumped")
    assert e.value.field == "density" and "hexagonal" in e.value.allowed
    with pytest.raises(ParameterError) as e:
        StandSpec(mix={"quaking_aspen": 1, "oak": 1})
    assert e.value.field == "mix.oak" and "sassafras" in e.value.allowed
    with pytest.raises(ParameterError) as e:
        StandSpec(mix={"quaking_aspen": -1})
    assert e.value.field == "mix.quaking_aspen"
    with pytest.raises(ParameterError) as e:      # 80 trees per 1 m Matérn cluster at 3 m
        StandSpec(placement="clumped", density=400, min_spacing=3, cluster="matern",
                  cluster_radius=1, parent_density=5)
    assert e.value.field == "cluster_radius" and e.value.fix
    with pytest.raises(ParameterError) as e:
        StandSpec.from_dict({"densty": 300}, source="forest.toml")
    assert e.value.field == "stand.densty" and "stand.density" in e.value.fix
    assert "forest.toml" in str(e.value)
    with pytest.raises(ParameterError) as e:
        StandSpec.from_dict({"height_cv": 2.0})
    assert e.value.field == "stand.height_cv"
    for bad in ({"plot": [0, 0, -1, 5]}, {"plot": [[0, 0], [1, 1]]}, {"variants": 0},
                {"seed": -1}, {"placement": "grid"}, {"height_range": [5, 2]}):
        with pytest.raises(ParameterError):
            StandSpec(**bad)


def test_a_fill_short_of_the_density_is_refused(monkeypatch):
    # Edges let small plots hold more than 0.62/s^2, so a short fill is rare: the check after
    # placing is exercised with a fill cut to 100 points
    from mitsuba_veg.trees import stand as S
    real = S.poisson_disc
    monkeypatch.setattr(S, "poisson_disc", lambda *a, **k: real(*a, **k)[:100])
    with pytest.raises(ParameterError) as e:
        layout(StandSpec(plot=HA, density=400, min_spacing=3.0))
    assert e.value.field == "density" and "fill holds 100 trees" in e.value.allowed
    assert len(layout(StandSpec(plot=HA, density=100, min_spacing=3.0))) == 100
