"""Weber & Penn (1995) generator: ShapeRatio, parameters and presets, branch and leaf counts,
pruning, reproducibility, the shared Tree structure, export and errors."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees import weber_penn as wp
from mitsuba_veg.trees.structure import NORMAL, Tree, placed_tree, scaled_tree

S8 = math.sin(math.pi / 4)

# (shape, ratio, value) computed by hand from the 1995 definitions
SHAPE_TABLE = [
    (0, 0.0, 0.2), (0, 0.5, 0.6), (0, 1.0, 1.0),                          # conical
    (1, 0.0, 0.2), (1, 0.25, 0.2 + 0.8 * S8), (1, 0.5, 1.0), (1, 1.0, 0.2),  # spherical
    (2, 0.0, 0.2), (2, 0.5, 0.2 + 0.8 * S8), (2, 1.0, 1.0),                  # hemispherical
    (3, 0.0, 1.0), (3, 0.37, 1.0), (3, 1.0, 1.0),                            # cylindrical
    (4, 0.0, 0.5), (4, 0.4, 0.7), (4, 1.0, 1.0),                             # tapered cyl.
    (5, 0.0, 0.0), (5, 0.35, 0.5), (5, 0.7, 1.0), (5, 0.85, 0.5), (5, 1.0, 0.0),  # flame
    (6, 0.0, 1.0), (6, 0.5, 0.6), (6, 1.0, 0.2),                             # inverse conical
    (7, 0.0, 0.5), (7, 0.35, 0.75), (7, 0.7, 1.0), (7, 0.85, 0.75), (7, 1.0, 0.5),  # tend flame
    (8, 0.0, 0.0), (8, 0.25, math.sqrt(0.5)), (8, 0.5, 1.0), (8, 0.75, math.sqrt(0.5)),
    (8, 1.0, 0.0), (8, -0.1, 0.0), (8, 1.1, 0.0),                            # envelope
]


@pytest.mark.parametrize("shape,ratio,value", SHAPE_TABLE)
def test_shape_ratio_1995_definitions(shape, ratio, value):
    assert wp.shape_ratio(shape, ratio) == pytest.approx(value, abs=1e-12)


def test_shape_ratio_envelope_parameters_and_arrays():
    # weeping willow's envelope: peak 0.6, PowerHigh 0.5, PowerLow 0.001 (as printed, the lower
    # branch divides by 1 - PruneWidthPeak too, so it starts at (0.6/0.4)^0.001 = 1.000406)
    kw = dict(prune_width_peak=0.6, prune_power_low=0.001, prune_power_high=0.5)
    assert wp.shape_ratio(8, 0.2, **kw) == pytest.approx(math.sqrt(0.5))
    assert wp.shape_ratio(8, 0.4, **kw) == pytest.approx(1.5 ** 0.001)
    assert wp.shape_ratio(8, 0.9, **kw) == pytest.approx(0.25 ** 0.001)
    r = np.linspace(0, 1, 11)
    np.testing.assert_allclose(wp.shape_ratio(0, r), 0.2 + 0.8 * r)
    np.testing.assert_allclose(wp.shape_ratio(5, r), np.where(r <= 0.7, r / 0.7, (1 - r) / 0.3))
    assert isinstance(wp.shape_ratio(3, 0.5), float)


@pytest.mark.parametrize("bad", [-1, 9, 2.5, "x", None])
def test_shape_ratio_rejects_bad_shapes(bad):
    with pytest.raises(ParameterError, match="shape"):
        wp.shape_ratio(bad, 0.5)


# ---- parameters and presets -------------------------------------------------------------------
def test_presets_load_with_sources_and_1995_values():
    assert set(wp.PRESETS) == {"quaking_aspen", "black_tupelo", "weeping_willow",
                               "ca_black_oak", "sassafras"}
    for name in wp.PRESETS:
        p = wp.load_params(name)
        assert p.name == name and ("Weber" in p.source or "Arbaro" in p.source)
        assert set(p.levels) == set(wp.LEVEL_DEFAULTS)
        assert all(len(v) == 4 for v in p.levels.values())
    a = wp.load_params("quaking_aspen")
    assert (a["Shape"], a["BaseSize"], a["Scale"], a["Levels"]) == (7, 0.4, 13.0, 3)
    assert a.levels["Branches"] == [0, 50, 30, 10] and a.levels["CurveRes"] == [3, 5, 3, 1]
    w = wp.load_params("weeping_willow")
    assert (w["AttractionUp"], w["PruneRatio"], w["0BaseSplits"], w.lv("Branches", 3)) == (
        -3.0, 1.0, 2, 300)
    o = wp.load_params("ca_black_oak")
    assert (o["Shape"], o["ScaleV"], o.lv("Taper", 0), o.lv("SegSplits", 0)) == (2, 10.0, 0.95,
                                                                                   0.4)
    b = wp.load_params("black_tupelo")
    assert (b["Levels"], b["Leaves"], b.lv("Taper", 0)) == (4, 6, 1.1)


def test_levels_beyond_three_reuse_level_three():
    p = wp.load_params("black_tupelo")
    for key in wp.LEVEL_DEFAULTS:
        assert p.lv(key, 4) == p.lv(key, 3) == p.lv(key, 7)


def test_params_from_dicts_flat_and_sectioned(tmp_path):
    p = wp.load_params({"preset": "sassafras", "1Branches": 7, "Length": [1, 0.5],
                        "knots": {"KnotRate": [0, 0.1, 0.2, 0.3]}, "Du": 4})
    assert p.lv("Branches", 1) == 7 and p.levels["Length"] == [1, 0.5, 0.5, 0.5]
    assert p.kn("KnotRate", 2) == 0.2 and p.junction["Du"] == 4 and p["Shape"] == 2
    f = tmp_path / "tree.toml"
    f.write_text('model = "weber_penn"\npreset = "quaking_aspen"\n[params]\nShape = 1\n')
    q = wp.load_params(str(f))
    assert q["Shape"] == 1 and q["BaseSize"] == 0.4
    t = wp.generate(f, seed=0)
    assert isinstance(t, Tree) and len(t) > 0


@pytest.mark.parametrize("bad,match", [
    ("no_such_tree", "preset"),
    ({"Shape": 9}, "Shape"),
    ({"Levles": 3}, "Levles"),
    ({"Length": [1, 2, 3, 4, 5]}, "Length"),
    ({"Taper": [1, 3.5, 1, 1]}, "Taper"),
    ({"CurveRes": [3, 0, 3, 1]}, "CurveRes"),
    ({"BaseSize": 1.0}, "BaseSize"),
    ({"PruneRatio": -0.1}, "PruneRatio"),
    ({"Du": 0}, "Du"),
    ({"model": "growth"}, "model"),
    ({"Scale": "tall"}, "Scale"),
    (3.14, "preset_or_params"),
])
def test_bad_parameters_get_clear_errors(bad, match):
    with pytest.raises(ParameterError, match=match) as e:
        wp.generate(bad, seed=0)
    assert "allowed" in str(e.value)


def test_bad_seed_and_missing_file():
    with pytest.raises(ParameterError, match="seed"):
        wp.generate("quaking_aspen", seed=-3)
    with pytest.raises(ParameterError, match="toml"):
        wp.generate("/nonexistent/tree.toml")


# ---- generation --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def aspen():
    return wp.generate("quaking_aspen", seed=3, knots=False)


def _heads(t):
    a = t.attrs
    return (t.parent >= 0) & (a["stem"][np.maximum(t.parent, 0)] != a["stem"]) & ~a["clone"]


def test_branch_counts_follow_nbranches(aspen):
    st = aspen.weber_penn.stats["levels"]
    heads = _heads(aspen)
    # level 1: exactly 1Branches on the (unsplit) trunk
    assert st[0]["buds"] == 50 and (heads & (aspen.level == 1)).sum() == 50
    # level 2: stems = 2Branches (0.2 + 0.8 (length/parent length)/1Length) per branch,
    # rounded by error diffusion (each parent within 1, the total exact)
    a = aspen.attrs
    h1 = np.nonzero(heads & (aspen.level == 1))[0]
    L1 = a["stem_length"][h1]
    expect = 30 * (0.2 + 0.8 * (L1 / a["stem_length"][0]) / 0.3)
    np.testing.assert_allclose(np.sort(st[1]["weber_penn_per_row"]), np.sort(expect), rtol=1e-9)
    assert np.all(np.abs(st[1]["buds_per_row"] - st[1]["expected_per_row"]) < 1.0)
    assert st[1]["buds"] == round(expect.sum())
    # level-1 lengths: 1Length * ShapeRatio(7, (L0 - offset)/(L0 - base))
    L0 = a["stem_length"][0]
    p = aspen.parent[h1]
    off = a["arc"][p] + a["attach"][h1] * np.linalg.norm(aspen.end[p] - aspen.start[p], axis=1)
    np.testing.assert_allclose(L1, L0 * 0.3 * wp.shape_ratio(7, (L0 - off) / (L0 * 0.6)),
                               rtol=1e-9)
    assert off.min() >= 0.4 * L0 - 1e-9                      # nothing below BaseSize


def test_radii_follow_ratio_power_and_taper(aspen):
    a = aspen.attrs
    L0, r0 = a["stem_length"][0], a["stem_radius"][0]
    assert r0 == pytest.approx(L0 * 0.015)                   # Ratio * 0Scale
    h1 = np.nonzero(_heads(aspen) & (aspen.level == 1))[0]
    raw = r0 * (a["stem_length"][h1] / L0) ** 1.2
    assert np.all(a["stem_radius"][h1] <= raw * (1 + 1e-12))
    # taper 1: every stem ends in a point
    tips = np.nonzero(np.bincount(aspen.parent[aspen.parent >= 0], minlength=len(aspen)) == 0)[0]
    assert np.all(aspen.radius_end[tips] < 1e-9)
    # flare widens the trunk base: 1 + Flare (100 - 1)/100
    assert aspen.radius_start[0] == pytest.approx(r0 * (1 + 0.6 * 0.99))


def test_leaves_per_stem_follow_shape_4(aspen):
    st = aspen.weber_penn.stats
    a = aspen.attrs
    h2 = np.nonzero(_heads(aspen) & (aspen.level == 2))[0]
    p = aspen.parent[h2]
    off = a["arc"][p] + a["attach"][h2] * np.linalg.norm(aspen.end[p] - aspen.start[p], axis=1)
    expect = 25 * wp.shape_ratio(4, off / a["stem_length"][p])
    assert abs(st["leaves"] - expect.sum()) < 1.0
    assert len(aspen.leaves) == st["leaves"]
    lv = aspen.leaves
    assert np.all(aspen.level[lv.segment] == 2)
    np.testing.assert_allclose(lv.size, 0.17)
    np.testing.assert_allclose(lv.attrs["width"], 0.17)
    np.testing.assert_allclose(np.linalg.norm(lv.normal, axis=1), 1.0)


def test_tree_structure_is_consistent(aspen):
    t = aspen
    assert np.all(t.parent < np.arange(len(t)))
    assert np.all(t.radius_start >= 0) and np.all(t.radius_end >= 0)
    assert t.level.min() == 0 and t.level.max() == 2
    heads = _heads(t) & (t.kind == NORMAL)
    p = t.parent[heads]
    on_parent = t.start[p] + t.attrs["attach"][heads][:, None] * (t.end[p] - t.start[p])
    np.testing.assert_allclose(on_parent, t.start[heads], atol=1e-12)
    cont = (t.parent >= 0) & ~_heads(t)
    np.testing.assert_allclose(t.start[cont], t.end[t.parent[cont]], atol=1e-12)
    for k, v in t.attrs.items():
        assert len(v) == len(t), k
    m = t.metrics()
    assert 8.0 < m["height"] < 22.0                          # Scale 13 +- 3
    assert t.start[0, 1] == 0.0 and t.end[:, 1].max() > 0    # +y up, base at the origin


def test_seeded_generation_is_reproducible():
    for name in ("quaking_aspen", "ca_black_oak"):
        a = wp.generate(name, seed=11)
        b = wp.generate(name, seed=11)
        for key in ("start", "end", "radius_start", "radius_end", "parent", "level", "kind"):
            np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
        np.testing.assert_array_equal(a.leaves.position, b.leaves.position)
        c = wp.generate(name, seed=12)
        assert len(c) != len(a) or not np.allclose(c.end, a.end)
    # knots on or off: the trunk (level 0, drawn before any bud) is the same
    k0 = wp.generate("quaking_aspen", seed=5, knots=True)
    k1 = wp.generate("quaking_aspen", seed=5, knots=False)
    np.testing.assert_array_equal(k0.end[k0.level == 0], k1.end[k1.level == 0])


def test_splits_make_clones_and_pruning_keeps_the_envelope():
    t = wp.generate("weeping_willow", seed=2)
    a = t.attrs
    assert a["clone"].sum() > 0                              # 0BaseSplits 2 and SegSplits
    trunks = np.unique(a["stem"][t.level == 0])
    assert len(trunks) >= 3
    # every branch (level >= 1, not a knot) ends inside the pruning envelope (PruneRatio 1)
    g = t.weber_penn.params.params
    S = t.weber_penn.scale_tree
    m = (t.level >= 1) & (t.kind == NORMAL)
    e = t.end[m]
    ratio = (S - e[:, 1]) / (S * (1 - g["BaseSize"]))
    env = g["PruneWidth"] * wp.shape_ratio(8, ratio, prune_width_peak=g["PruneWidthPeak"],
                                           prune_power_low=g["PrunePowerLow"],
                                           prune_power_high=g["PrunePowerHigh"])
    assert np.all(np.hypot(e[:, 0], e[:, 2]) / S < env + 1e-9)
    # negative AttractionUp: the level-2 curtains hang down
    d = t.end - t.start
    assert np.mean(d[t.level == 2, 1] < 0) > 0.5


@pytest.mark.parametrize("name", ["black_tupelo", "sassafras", "ca_black_oak"])
def test_all_presets_grow_plausible_trees(name):
    t = wp.generate(name, seed=1)
    p = t.weber_penn.params
    m = t.metrics()
    scale = t.weber_penn.scale_tree
    assert 0.5 * scale < m["height"] < 1.6 * scale
    assert t.level.max() == p["Levels"] - 1
    assert len(t.leaves) > 1000
    assert np.isfinite(t.end).all() and np.isfinite(t.leaves.position).all()


def test_tree_mesh_export_formats(tmp_path):
    import trimesh
    t = wp.generate({"preset": "quaking_aspen", "Levels": 2, "Leaves": 4}, seed=0)
    out = []
    for ext in ("ply", "obj", "glb"):
        out += wp.export(t, tmp_path / f"aspen.{ext}")
    assert [Path(p).name for p in out] == ["aspen.ply", "aspen_leaves.ply", "aspen.obj",
                                           "aspen.glb"]
    assert "\nvt " in (tmp_path / "aspen.obj").read_text()
    scene = trimesh.load(tmp_path / "aspen.glb")
    assert len(scene.geometry) == 2
    bark = trimesh.load(tmp_path / "aspen.ply")
    assert len(bark.faces) > 0
    with pytest.raises(ParameterError, match="path"):
        wp.export(t, tmp_path / "aspen.fbx")
    # the shared structure's own mesh works on Weber-Penn trees too
    m = t.to_mesh(sides=6)
    assert len(m.faces) > 0


def test_copies_of_a_weber_penn_tree_keep_its_record(aspen):
    """A copy, a translated, scaled or placed copy of a Weber-Penn tree is still one: its
    generation record (parameters, seed) comes along, so its wood is meshed and it ages as
    its preset; a plain tree gets none."""
    assert aspen.weber_penn is not None
    for c in (aspen.copy(), aspen.translated((1.0, 0.0, 2.0)), scaled_tree(aspen, 1.3),
              placed_tree(aspen, 0.8, 30.0, (4.0, 0.0, 1.0))):
        assert c.weber_penn is aspen.weber_penn
        assert c is not aspen and len(c) == len(aspen)
    plain = Tree(np.zeros((1, 3)), np.ones((1, 3)), np.ones(1), np.ones(1), [-1], [0])
    assert getattr(plain.copy(), "weber_penn", None) is None
