"""Light at leaf spheres (paper 001 eqs 2.1-2.4): sky cells, analytic occlusion cases, the three
sphere-counting engines against each other, obstacles' reflected light."""
import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees.environment import Environment
from mitsuba_veg.trees.leaflight import Sky, inside_counts, leaf_sphere_light, sphere_grid

ALPHAS = {"light": 0.3, "red": 0.3, "far_red": 0.7}
ENGINES = ("grid", "mitsuba", "analytic")


def test_sky_cells_cover_the_sphere():
    sky = Sky(10, 10, 1.5)
    N, S, upper, B0 = sky.cells()
    assert N.shape == (100, 3) and sky.M == 100
    assert S.sum() == pytest.approx(4 * math.pi)
    assert upper.sum() == 50 and np.all(N[upper, 1] > 0) and np.all(N[~upper, 1] < 0)
    assert np.allclose(np.linalg.norm(N, axis=1), 1.0)
    assert set(B0[upper]) == {1.5} and set(B0[~upper]) == {1.0}
    with pytest.raises(ParameterError):
        Sky(10, 9)
    with pytest.raises(ParameterError):
        Sky(10, 10, 0.0)


@pytest.mark.parametrize("engine", ENGINES)
def test_open_sky_is_one_and_points_up(engine):
    res = leaf_sphere_light([[0.0, 5.0, 0.0]], 1.0, Sky(), ALPHAS, engine=engine)
    for b in ALPHAS:
        assert res.received[b][0] == pytest.approx(1.0)
    assert np.allclose(res.vector[0], [0, 1, 0], atol=1e-9)


@pytest.mark.parametrize("engine", ENGINES)
def test_one_sphere_above_shades_the_cells_inside_its_cone(engine):
    """Sphere B (radius 1) 3 above A: A's rays within asin(1/3) = 19.5 deg of the zenith pass
    B (the 10 cells of the top row, centred 9 deg from the zenith); eq 2.3 by hand."""
    sky = Sky(10, 10, 1.5)
    N, S, upper, B0 = sky.cells()
    res = leaf_sphere_light([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0]], 1.0, sky, ALPHAS, engine=engine)
    cone = N[:, 1] > math.cos(math.asin(1 / 3))
    assert cone.sum() == 10
    norm = (B0 * S).sum()
    for b, a in ALPHAS.items():
        expect = 1 - (1 - a) * (B0 * S)[cone].sum() / norm
        assert res.received[b][0] == pytest.approx(expect, rel=1e-6)
        # B sees A below it through the bottom row (C2 there)
        cone_dn = N[:, 1] < -math.cos(math.asin(1 / 3))
        assert res.received[b][1] == pytest.approx(1 - (1 - a) * (B0 * S)[cone_dn].sum() / norm,
                                                   rel=1e-6)
    # red:far-red drops behind leaves (alpha_r < alpha_fr)
    assert res.ratio()[0] < 1.0
    # opaque spheres (every pass factor 0): the cone is dark, the rest of the sky unchanged
    opaque = leaf_sphere_light([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0]], 1.0, sky,
                               {b: 0.0 for b in ALPHAS}, engine=engine)
    for b in ALPHAS:
        assert opaque.received[b][0] == pytest.approx(1 - (B0 * S)[cone].sum() / norm, rel=1e-6)


@pytest.mark.parametrize("engine", ENGINES)
def test_sphere_containing_the_centre_attenuates_every_direction(engine):
    res = leaf_sphere_light([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]], 1.0, Sky(), ALPHAS,
                            engine=engine)
    for b, a in ALPHAS.items():
        assert res.received[b] == pytest.approx([a, a])
    assert inside_counts([[0, 0, 0], [0.5, 0, 0], [3, 0, 0]], 1.0).tolist() == [1, 1, 0]


def _cloud(n=400, seed=3):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-5, 5, (n, 3))
    c[:, 1] += 7
    return c


def test_engines_count_the_same_spheres():
    c = _cloud()
    env = Environment().add_ground(60).add_box((-9, 0, -9), (-7, 14, 9), max_edge=2.0)
    for e in (None, env):
        r = {eng: leaf_sphere_light(c, 1.0, Sky(), ALPHAS, env=e, engine=eng, cutoff=1e-9)
             for eng in ENGINES}
        for b in ALPHAS:
            # the grid walk and the all-pairs test make identical decisions
            assert np.abs(r["grid"].received[b] - r["analytic"].received[b]).max() < 1e-9
            # Mitsuba's float32 ellipsoid test differs on a few grazing rays
            d = np.abs(r["mitsuba"].received[b] - r["grid"].received[b])
            assert d.max() < 0.02 and np.mean(d > 1e-3) < 0.02
        assert r["grid"].spheres_passed == pytest.approx(r["mitsuba"].spheres_passed, rel=0.01)


def test_grid_lists_every_overlapping_sphere():
    c = _cloud(50)
    lo, h, shape, start, items = sphere_grid(c, 1.0)
    assert start[-1] == len(items) and len(items) >= len(c)
    # every sphere is listed in the cell that holds its centre
    ijk = np.floor((c - lo) / h).astype(int)
    cell = ijk[:, 0] + shape[0] * (ijk[:, 1] + shape[1] * ijk[:, 2])
    for i, ci in enumerate(cell):
        assert i in items[start[ci]:start[ci + 1]]


def test_open_ground_reflects_like_the_ideal_environment():
    env = Environment.flat_ground(60)
    sky = Sky()
    assert np.allclose(env.reflected_light(sky), 1.0)
    a = leaf_sphere_light([[0.0, 5.0, 0.0]], 1.0, sky, ALPHAS, env=env, engine="grid")
    assert a.received["light"][0] == pytest.approx(1.0, abs=1e-9)


def test_wall_darkens_and_turns_the_light_vector_away():
    env = Environment().add_ground(60).add_box((-3, 0, -20), (-2, 20, 20), max_edge=2.0)
    sky = Sky()
    envv = env.reflected_light(sky)
    V, F, nrm, cen, area, obj, lf = env.triangles()
    wall_face = (obj == 1) & (nrm[:, 0] > 0.9) & (cen[:, 1] < 15)   # facing the tree
    assert 0.4 < envv[wall_face].mean() < 0.95
    ground = obj == 0
    near = ground & (np.abs(cen[:, 0] + 1.0) < 2.0) & (np.abs(cen[:, 2]) < 10)
    far = ground & (cen[:, 0] > 20)
    assert envv[near].mean() < envv[far].mean() - 0.1
    for engine in ENGINES:
        r = leaf_sphere_light([[0.0, 4.0, 0.0]], 1.0, sky, ALPHAS, env=env, engine=engine)
        assert 0.3 < r.received["light"][0] < 0.95
        assert r.vector[0, 0] > 0.2          # away from the wall (at -x)


def test_buried_spheres_get_no_light():
    env = Environment().add_ground(40)
    r = leaf_sphere_light([[0.0, -2.0, 0.0], [0.0, 3.0, 0.0]], 1.0, Sky(), ALPHAS, env=env,
                          engine="grid")
    assert r.received["light"][0] == 0.0 and r.received["light"][1] > 0.9
    assert r.stats["buried"] == 1
