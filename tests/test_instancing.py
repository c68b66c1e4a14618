"""A stand as Mitsuba instances vs plain meshes (mitsuba_veg.trees.instancing)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees.instancing import (MemoryModel, build_variants, memory_estimate,
                                          merged_meshes, scene_dict, stand_memory,
                                          variant_mesh)
from mitsuba_veg.trees.stand import StandSpec, layout


def test_memory_estimate_by_hand():
    m = MemoryModel(vertex=10, face=20, accel_face=30, instance=1000, element=7, recorded=100,
                    plain_vertex=3, plain_face=5)
    sizes = {"a": (100, 200, 50), "b": (10, 20, 0)}
    e = memory_estimate(sizes, {"a": 3, "b": 2}, m)
    geo_a, geo_b = 100 * 10 + 200 * 50, 10 * 10 + 20 * 50            # 11000, 1100
    assert e.geometry_plain == 3 * geo_a + 2 * geo_b
    assert e.geometry_instanced == geo_a + geo_b + 5 * 1000
    ph = 3 * (200 * 7 + 100 * 100) + 2 * (20 * 7)                    # leaves: 2 x 50 rows
    assert e.photon_instanced == ph
    assert e.photon_plain == ph + 3 * (100 * 3 + 200 * 5) + 2 * (10 * 3 + 20 * 5)
    assert (e.trees, e.leaves, e.faces) == (5, 150, 640)
    assert e.per_leaf()["instanced"] == pytest.approx((geo_a + geo_b + 5000 + ph) / 150)
    all_ = memory_estimate(sizes, {"a": 3, "b": 2}, m, recorded="all")
    assert all_.photon_instanced == 3 * 200 * 107 + 2 * 20 * 107
    assert memory_estimate(sizes, {"a": 1}, m, recorded="none").photon_instanced == 1400
    with pytest.raises(ParameterError):
        memory_estimate(sizes, {"c": 1}, m)
    with pytest.raises(ParameterError):
        memory_estimate(sizes, {"a": 1}, m, recorded="bark")


@pytest.fixture(scope="module")
def small_stand():
    st = layout(StandSpec(plot=[0, 0, 24, 24], density=70, min_spacing=4.0, variants=2,
                          mix={"quaking_aspen": 1.0}, height_mean=6.0, seed=4))
    return st, build_variants(st)


def test_variants_are_grown_once_with_their_seeds(small_stand):
    st, var = small_stand
    assert len(st) == 4 and sorted(var) == [("quaking_aspen", 0), ("quaking_aspen", 1)]
    v0 = var[("quaking_aspen", 0)]
    assert v0.seed == st.variant_seed("quaking_aspen", 0)
    again = variant_mesh("quaking_aspen", 0, v0.seed)
    np.testing.assert_array_equal(again.leaves[0], v0.leaves[0])
    assert len(v0.leaves[1]) == 2 * v0.n_leaves and v0.bark[0][:, 1].min() >= -1.0
    assert v0.height == pytest.approx(max(v0.bark[0][:, 1].max(), v0.leaves[0][:, 1].max()))
    with pytest.raises(ParameterError):
        variant_mesh("growth", 0, 1)
    est = stand_memory(st, var)
    counts = {k: int(np.sum((st.species == k[0]) & (st.variants == k[1]))) for k in var}
    assert est.leaves == sum(counts[k] * var[k].n_leaves for k in var)
    m = MemoryModel()
    geo = {k: var[k].n_vertices * 12 + var[k].n_faces * (12 + m.accel_face) for k in var}
    assert est.geometry_plain == sum(counts[k] * geo[k] for k in var)
    assert est.geometry_instanced == sum(geo.values()) + 4 * m.instance


def test_instances_and_merged_meshes_are_the_same_geometry(small_stand):
    st, var = small_stand
    merged = merged_meshes(st, var)
    per_tree = [var[(str(s), int(v))] for s, v in zip(st.species, st.variants)]
    assert len(merged["leaves"][1]) == sum(len(p.leaves[1]) for p in per_tree)
    assert len(merged["bark"][0]) == sum(len(p.bark[0]) for p in per_tree)
    # each tree's top is at its height above its base
    n0 = len(per_tree[0].leaves[0]) + 0
    top0 = max(merged["leaves"][0][:n0, 1].max(), merged["bark"][0][:len(per_tree[0].bark[0]),
                                                                     1].max())
    assert top0 == pytest.approx(st.positions[0, 1] + st.heights[0], abs=1e-3)
    scenes = {}
    for inst in (True, False):
        d = {"type": "scene"}
        d.update(scene_dict(st, var, instanced=inst))
        scenes[inst] = mi.load_dict(d, optimize=False)
    ids = [s.id() for s in scenes[True].shapes()]
    assert sum(i.startswith("tree_") for i in ids) == 4
    assert sorted(s.id() for s in scenes[False].shapes()) == ["trees_bark", "trees_leaves"]
    rng = np.random.default_rng(0)
    n = 20000
    # straight down onto random leaf corners, from 20 m above (a few rays slip past)
    lv = merged["leaves"][0]
    o = lv[rng.integers(len(lv), size=n)] + [0.0, 20.0, 0.0] + rng.normal(0, 0.01, (n, 3))
    d = np.tile([0.0, -1.0, 0.0], (n, 1))
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, i].astype(np.float32)) for i in range(3)]),
                   mi.Vector3f(*[mi.Float(d[:, i].astype(np.float32)) for i in range(3)]))
    t = {k: np.asarray(s.ray_intersect_preliminary(ray).t) for k, s in scenes.items()}
    hit = {k: np.isfinite(v) for k, v in t.items()}
    assert hit[True].mean() > 0.5
    # the same rays hit the same surfaces (float32 transforms: a few grazing rays may differ)
    assert np.mean(hit[True] != hit[False]) < 0.002
    both = hit[True] & hit[False]
    assert np.median(np.abs(t[True][both] - t[False][both])) < 1e-4
    dr.eval()
