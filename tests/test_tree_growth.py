"""Growth model of paper 001: parameters (table 3.1), branching geometry, pipe model, death,
shade avoidance, phototropism, determinism, obstacles."""
import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees import Environment, GrowthParams, branching, grow, grow_forest
from mitsuba_veg.trees.growth import _turn_towards

#: no light effects: pure branching model
PURE = dict(phototropism=0.0, death_threshold=0.0, shade_threshold=0.0)


def test_defaults_are_table_3_1():
    p = GrowthParams()
    assert (p.branch_angle, p.main_length, p.lateral_length) == (60.0, 4.0, 8.0)
    assert (p.phototropism, p.light_ratio, p.leaf_radius) == (0.4, 1.5, 4.0)
    assert (p.alpha, p.alpha_red, p.alpha_far_red) == (0.3, 0.3, 0.7)
    assert (p.death_threshold, p.shade_main_extension, p.shade_lateral_reduction) == (0.2, 4, 4)
    assert p.shade_threshold == 0.5 and p.phyllotaxis == pytest.approx(5 / 8)
    assert (p.sky_h, p.sky_v) == (10, 10)


@pytest.mark.parametrize("kw", [{"branch_angle": 200}, {"phyllotaxis": "3/2"}, {"sky_v": 9},
                                {"alpha": 1.5}, {"leaf_radius": 0}, {"phyllotaxis": "x"},
                                {"engine": "gpu"}, {"unit": -1}])
def test_bad_parameters_name_the_field(kw):
    with pytest.raises(ParameterError) as e:
        GrowthParams(**kw)
    assert list(kw)[0] in str(e.value)


def test_from_dict_rejects_unknown_keys_and_parses_fractions():
    with pytest.raises(ParameterError, match="growth.brnch_angle"):
        GrowthParams.from_dict({"brnch_angle": 50}, source="t.toml")
    assert GrowthParams.from_dict({"phyllotaxis": "2/5"}).phyllotaxis == pytest.approx(0.4)
    with pytest.raises(ParameterError, match="generations"):
        grow(generations=-1)


def test_pure_branching_geometry():
    p = GrowthParams(**PURE)
    G = 5
    t = grow(p, generations=G)
    assert len(t) == 2 ** (G + 1) - 1 and t.metrics()["leaf_spheres"] == 2 ** G
    lat = t.attrs["lateral"]
    assert np.allclose(t.length[~lat], p.main_length * p.unit)
    assert np.allclose(t.length[lat], p.lateral_length * p.unit)
    # branch angle between each lateral and its parent
    d = t.direction
    cosang = (d[lat] * d[t.parent[lat]]).sum(1)
    assert np.allclose(np.degrees(np.arccos(cosang)), p.branch_angle)
    # the trunk's successive laterals turn by the divergence (5/8 of a turn, right-handed)
    trunk = [0]
    while True:
        kids = np.nonzero((t.parent == trunk[-1]) & ~lat)[0]
        if not len(kids):
            break
        trunk.append(int(kids[0]))
    laterals = [int(np.nonzero((t.parent == s) & lat)[0][0]) for s in trunk[:-1]]
    az = np.arctan2(d[laterals, 0], d[laterals, 2])     # right-handed about +y
    turn = np.mod(np.diff(az), 2 * math.pi) / (2 * math.pi)
    assert np.allclose(turn, 5 / 8)
    # branching() is the same model without light
    b = branching(p, generations=G)
    assert np.allclose(b.end, t.end)


def test_pipe_model_radii():
    t = grow(GrowthParams(), generations=7)
    r2 = t.radius_start ** 2
    child_sum = np.zeros(len(t))
    live = t.alive
    np.add.at(child_sum, t.parent[live & (t.parent >= 0)], r2[live & (t.parent >= 0)])
    inner = live & (child_sum > 0)
    assert inner.sum() > 10
    assert np.allclose(r2[inner], child_sum[inner])
    tips = t.attrs["leaf_sphere_segment"]
    assert np.allclose(t.radius_start[tips], GrowthParams().tip_radius * GrowthParams().unit)


def test_death_cascades_to_parents():
    t = grow(GrowthParams(death_threshold=1.0), generations=3)
    m = t.metrics()
    # alone the first leaf sphere sees the open sky (1.0), its two children shade each other
    assert m["live_branches"] == 0 and m["dead_branches"] == 3 and m["leaf_spheres"] == 0
    t = grow(GrowthParams(), generations=8)
    assert np.all(t.attrs["light"] >= GrowthParams().death_threshold)
    assert np.all(t.alive[t.attrs["leaf_sphere_segment"]])
    assert t.metrics()["dead_branches"] > 0


def test_shade_avoidance_swaps_lengths():
    p = GrowthParams(**{**PURE, "shade_threshold": 2.0})   # R:FR <= 1 < 2: always shaded
    t = grow(p, generations=4)
    lat = t.attrs["lateral"]
    main = ~lat & (np.arange(len(t)) > 0)
    assert np.allclose(t.length[main], (p.main_length + p.shade_main_extension) * p.unit)
    assert np.allclose(t.length[lat], (p.lateral_length - p.shade_lateral_reduction) * p.unit)
    # a reduction to zero makes no lateral at all
    t0 = grow(GrowthParams(**{**PURE, "shade_threshold": 2.0, "shade_lateral_reduction": 8.0}),
              generations=3)
    assert len(t0) == 4 and not t0.attrs["lateral"].any()


def test_turn_towards_fraction():
    d = np.array([[0.0, 1.0, 0.0]])
    u = np.array([[1.0, 0.0, 0.0]])
    target = np.array([[1.0, 0.0, 0.0]])
    d1, u1 = _turn_towards(d, np.array([[0.0, 0.0, 1.0]]), target, 1.0)
    assert np.allclose(d1, target)
    d5, u5 = _turn_towards(d, np.array([[0.0, 0.0, 1.0]]), target, 0.5)
    assert np.allclose(d5, [[math.sqrt(0.5), math.sqrt(0.5), 0]])
    assert abs((d5 * u5).sum()) < 1e-12 and np.allclose(np.linalg.norm(u5), 1)
    assert np.allclose(_turn_towards(d, u, d, 0.7)[0], d)


def test_phototropism_turns_children_towards_the_light_vector():
    """H = 1: every child of a tip points along that tip's light vector (eq 2.4). In open sky
    a lone tree's leaf spheres see light from above: the light vector is +y, so H = 1 grows a
    straight vertical line of overlapping segments."""
    t = grow(GrowthParams(phototropism=1.0, death_threshold=0.0, shade_threshold=0.0),
             generations=2)
    assert np.allclose(t.direction[1:3], [0, 1, 0], atol=1e-9)


def test_seed_and_engines():
    p = GrowthParams()
    a = grow(p, generations=7, seed=3)
    b = grow(p, generations=7, seed=3)
    c = grow(p, generations=7, seed=4)
    assert np.array_equal(a.end, b.end)
    assert not np.allclose(a.end[-1], c.end[-1])
    g = grow(p.replace(engine="grid"), generations=7, seed=3)
    an = grow(p.replace(engine="analytic"), generations=7, seed=3)
    assert np.array_equal(g.end, an.end)
    mi_ = grow(p.replace(engine="mitsuba"), generations=7, seed=3)
    assert mi_.metrics()["live_branches"] == pytest.approx(g.metrics()["live_branches"], rel=0.05)
    f = grow_forest([(0.0, 0.0, 0.0)], p, generations=7, seed=3)[0]
    assert np.array_equal(f.end, a.end)


def test_positions_on_terrain_and_obstacle_collision():
    env = Environment().add_slope(20.0, 40.0)
    t = grow(GrowthParams(), generations=2, position=(3.0, 0.0), scene=env)
    assert t.start[0, 1] == pytest.approx(-3.0 * math.tan(math.radians(20)), abs=1e-4)
    wall = Environment().add_ground(40).add_box((-1.5, 0, -10), (-1.0, 12, 10))
    hist = []
    t = grow_forest([(0.0, 0.0, 0.0)], GrowthParams(), generations=8, scene=wall,
                    history=hist)[0]
    live = t.alive
    seg_dir = t.direction[live]
    assert not wall.blocked(t.start[live] + 1e-4 * seg_dir, seg_dir, t.length[live] - 2e-4).any()
    assert hist[-1]["blocked"] > 0
    with pytest.raises(ParameterError):
        grow_forest([(0.0, np.nan, 0.0)])


def test_mitsuba_scene_as_environment():
    import mitsuba as mi
    from mitsuba_veg.light.validation import box_mesh, grid_mesh, make_mesh
    gv, gf = grid_mesh(10, 10, (-20, 20), (-20, 20))
    bv, bf = box_mesh((-4, 0, -10), (-3, 15, 10))
    scene = mi.load_dict({"type": "scene", "ground": make_mesh("ground", gv, gf),
                          "wall": make_mesh("wall", bv, bf)}, optimize=False)
    t = grow(GrowthParams(), generations=8, scene=scene)
    env = Environment.coerce(scene)
    assert len(env) == 2
    assert t.metrics()["crown_centroid"][0] > 1.0


def test_branching_reads_a_dict_like_grow_forest():
    a = branching(GrowthParams(branch_angle=40.0), generations=3)
    b = branching({"branch_angle": 40.0}, generations=3)
    assert np.allclose(a.end, b.end)
    with pytest.raises(ParameterError, match=r"params\.bogus"):
        branching({"bogus": 1.0}, generations=2)
