"""Leaves as leaves and wood as wood in the render: leaf outlines with the light pass's blade
area, swept tubes with rounded joints, the bark's texture and relief, knots as swellings."""
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
import mitsuba as mi
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.render import bark as B
from mitsuba_veg.render import leaves as L
from mitsuba_veg.trees.structure import Leaves, Tree


def _leaf_areas(v, f, k_faces):
    a = L.triangle_areas(v, f)
    return a.reshape(-1, k_faces).sum(1)


# ---- leaves -------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", L.SHAPES)
def test_templates_have_the_light_pass_area_and_few_triangles(shape):
    for v in range(L.VARIANTS):
        for curl in (0.0, 0.35):
            V, F = L.leaf_template(shape, v, curl)
            assert L.triangle_areas(V, F).sum() == pytest.approx(L.LEAF_AREA, rel=1e-12)
            assert 12 <= len(F) <= 14
            # area centroid at the origin; folded towards +z (margins above the midrib)
            p = V[F]
            a = L.triangle_areas(V, F)
            assert np.allclose((a[:, None] * p.mean(1)).sum(0) / a.sum(), 0.0, atol=1e-12)
            n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            assert np.all(n[:, 2] > 0)                  # one side up, no flipped triangle
            # every variant has the same faces (one index buffer for all leaves)
            assert np.array_equal(F, L.leaf_template(shape, 0, curl)[1])
    V0, _ = L.leaf_template(shape, 0)
    V1, _ = L.leaf_template(shape, 1)
    assert not np.allclose(V0, V1)                       # the variants differ in relief


def test_maple_outline_is_paper_003s_ifs_attractor():
    from mitsuba_veg.foliage.ifs import MAPLE_IFS, chaos_game, fixed_point
    h = L.half_outline("maple")
    pet, tip = fixed_point(MAPLE_IFS[0]), fixed_point(MAPLE_IFS[1])
    pts, _ = chaos_game(50_000, seed=1)
    d = (pts - pet) / (tip[1] - pet[1])
    # the outline's points lie on the attractor's rim: each close to an attractor point and
    # at least as far from the petiole as 97 % of the attractor in its direction
    dist = np.min(np.hypot(d[:, None, 0] - h[None, :, 0], d[:, None, 1] - h[None, :, 1]), 0)
    assert dist.max() < 0.03
    # lobes: the radius from the petiole along the half outline has >= 2 local maxima
    r = np.hypot(h[:, 0], h[:, 1])
    peaks = np.sum((r[1:-1] > r[:-2]) & (r[1:-1] > r[2:]))
    assert peaks >= 2


def test_leaf_shapes_by_tree_model():
    from mitsuba_veg.render.trees import make_tree
    assert L.leaf_shape_of(make_tree({"model": "simple"})) == "ovate"
    aspen = make_tree({"preset": "quaking_aspen", "seed": 1, "height": 3.0})
    assert L.leaf_shape_of(aspen) == "deltoid"
    with pytest.raises(ParameterError):
        L.half_outline("fern")


def test_blades_are_placed_vectorised_with_the_world_blade_area():
    """Each drawn leaf's area equals the area the world's light pass divides its flux by
    (WorldTree.leaf_area: the quad of leaf_quads, 0.6 size²)."""
    from mitsuba_veg.trees.growth import GrowthParams, grow
    from mitsuba_veg.world.trees import world_tree
    tree = grow(GrowthParams(), generations=5, seed=2)
    wt = world_tree("t", "growth", tree, tree.start[0], {})
    lv = tree.leaves
    v, f = L.blade_mesh(lv.position, lv.normal, lv.up, lv.size, "ovate")
    k = len(f) // len(lv)
    area = _leaf_areas(v.astype(float), f.astype(np.int64), k)
    assert np.allclose(area, wt.leaf_area, rtol=2e-5)
    assert np.allclose(wt.leaf_area, 0.6 * lv.size ** 2)
    # centred on the leaf, facing its normal, long axis along its up
    kv = len(v) // len(lv)
    pv = v.reshape(len(lv), kv, 3).astype(float)
    pf = v[f].reshape(len(lv), k, 3, 3).astype(float)
    a = L.triangle_areas(v, f).reshape(len(lv), k)
    cen = (a[..., None] * pf.mean(2)).sum(1) / a.sum(1)[:, None]
    assert np.allclose(cen, lv.position, atol=1e-5)
    n = np.cross(pf[:, :, 1] - pf[:, :, 0], pf[:, :, 2] - pf[:, :, 0]).sum(1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    unit = lv.normal / np.linalg.norm(lv.normal, axis=1, keepdims=True)
    assert np.all((n * unit).sum(1) > 0.9)
    axis = pv[:, 2] - pv[:, 0]                            # petiole -> tip (midrib ends)
    side, up, _ = L.leaf_frames(lv.normal, lv.up)
    assert np.all((axis * up).sum(1) > 0.9 * np.linalg.norm(axis, axis=1))


def test_render_leaf_bins_keep_a_fixed_set_of_meshes_and_scale_for_leaf_out():
    from mitsuba_veg.render.scene import RenderOptions
    from mitsuba_veg.render.trees import leaf_bin_arrays, simple_tree
    t = simple_tree(2.0, seed=3)
    n = len(t.leaves)
    t.leaves.attrs["autumn_tau"] = np.linspace(0, 1, n)
    t.leaves.attrs["fallen"] = np.arange(n) % 4 == 0
    t.leaves.attrs["leaf_scale"] = np.full(n, 0.5)
    cache = {}
    out = leaf_bin_arrays([t], RenderOptions(leaf_bins=4), cache)
    assert sorted(out) == [f"leaves_{b:02d}" for b in range(4)]
    tri = sum(len(f) for v, f in out.values())
    kept = n - len(range(0, n, 4))
    k = len(L.leaf_template("ovate")[1])
    assert tri == kept * k
    area = sum(L.triangle_areas(v, f).sum() for v, f in out.values())
    keep = np.arange(n) % 4 != 0
    # half size: a quarter of the area
    assert area == pytest.approx(0.25 * 0.6 * np.sum(t.leaves.size[keep] ** 2), rel=1e-4)


# ---- wood -----------------------------------------------------------------------------------
def _kinked_tree(angle_deg=60.0):
    """A trunk of three segments with a kink of ``angle_deg`` at each joint and a side branch."""
    a = np.radians(angle_deg)
    p0 = np.zeros(3)
    p1 = np.array([0.0, 1.0, 0.0])
    p2 = p1 + np.array([np.sin(a), np.cos(a), 0.0])
    p3 = p2 + np.array([0.0, 1.0, 0.0])
    q = p1 + np.array([0.0, 0.3, 0.6])
    start = np.array([p0, p1, p2, p1])
    end = np.array([p1, p2, p3, q])
    return Tree(start, end, [0.10, 0.08, 0.06, 0.02], [0.08, 0.06, 0.04, 0.01],
                [-1, 0, 1, 0], [0, 0, 0, 1])


def test_swept_tubes_are_smooth_through_the_joints():
    t = _kinked_tree(60.0)
    V, F, uv, N = B.swept_tubes(t)
    assert F.max() < len(V) and len(uv) == len(V) == len(N)
    assert np.all((uv[:, 0] >= 0) & (uv[:, 0] <= 1))
    # outward faces: the face normal points the way of its vertices' normals
    p = V[F]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all((fn * N[F].sum(1)).sum(1) > 0)
    head, pos, _ = B._chains(t)
    assert head.tolist() == [0, 0, 0, 3] and pos.tolist() == [0, 1, 2, 0]
    # the trunk alone: 4 points -> 6 -> 10 rings after two rounds of corner cutting
    trunk = Tree(t.start[:3], t.end[:3], t.radius_start[:3], t.radius_end[:3], [-1, 0, 1],
                 [0, 0, 0])
    V, F, uv, N = B.swept_tubes(trunk)
    S = int(B._sides(np.array([0.10]))[0])
    assert len(V) == 10 * (S + 1) + 1                     # 10 rings and the tip's apex
    ring = V[:-1].reshape(10, S + 1, 3)[:, :S]
    centre = ring.mean(1)
    d = np.diff(centre, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    turn = np.degrees(np.arccos(np.clip((d[1:] * d[:-1]).sum(1), -1, 1)))
    # each 60 deg kink is spread over four turns of ~15 deg; the total turning stays
    assert turn.max() < 60.0 / 3 and turn.sum() == pytest.approx(120.0, abs=1.0)
    # the radius is continuous: at the ends the segments' radii, inside no jump
    rad = np.linalg.norm(ring - centre[:, None], axis=2).mean(1)
    assert rad[0] == pytest.approx(0.10, rel=0.03) and rad[-1] == pytest.approx(0.04, rel=0.03)
    assert np.all(np.diff(rad) < 1e-9) and np.all(np.abs(np.diff(rad)) < 0.012)
    # v along the stem in base circumferences, u around
    v = uv[:-1].reshape(10, S + 1, 2)[:, 0, 1]
    arc = np.r_[0, np.cumsum(np.linalg.norm(np.diff(centre, axis=0), axis=1))]
    assert np.allclose(v, arc / (2 * np.pi * 0.10), rtol=0.02, atol=1e-9)


def test_a_branch_starts_inside_its_parent():
    t = _kinked_tree(30.0)
    V, F, uv, N = B.swept_tubes(t, rounds=0)
    # the side branch's first ring: centred on its axis moved back by the parent's radius at
    # the joint (0.08), its radius at most 0.9 of the parent's (0.02 here)
    S = int(B._sides(np.array([0.02]))[0])
    d = (t.end[3] - t.start[3]) / np.linalg.norm(t.end[3] - t.start[3])
    base = t.start[3] - 0.08 * d
    dist = np.linalg.norm(V - base, axis=1)
    ring = np.argsort(dist)[:S + 1]
    assert np.allclose(dist[ring], 0.02, rtol=1e-6)


def test_bark_texture_tiles_and_its_relief_is_per_circumference():
    tone, h = B.bark_texture(64, furrows=6)
    assert tone.shape == h.shape == (64, 64)
    assert 0 <= tone.min() and tone.max() <= 1 and 0 <= h.min() and h.max() <= 1
    # periodic: the jump across the tile's edge is like the jumps inside it
    inner = np.abs(np.diff(h, axis=1)).mean()
    edge = np.abs(h[:, 0] - h[:, -1]).mean()
    assert edge < 3 * inner
    # furrows along v: the height varies more around (u) than along (v)
    assert np.abs(np.diff(h, axis=1)).mean() > 1.5 * np.abs(np.diff(h, axis=0)).mean()
    n = B.bark_normals(h, depth=0.02) * 2 - 1
    assert np.allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
    # the slope is depth x dh/du (tile units): check one pixel by hand
    i, j = 10, 20
    du = (h[i, j + 1] - h[i, j - 1]) * 64 / 2
    dv = (h[i + 1, j] - h[i - 1, j]) * 64 / 2
    e = np.array([-0.02 * du, -0.02 * dv, 1.0])
    assert np.allclose(n[i, j], e / np.linalg.norm(e), atol=1e-5)


def test_bark_bsdf_loads_and_blends_the_two_bark_spectra():
    from mitsuba_veg.render import materials as mat
    d = B.bark_bsdf()
    assert d["type"] == "twosided" and d["bsdf"]["type"] == "normalmap"
    blend = d["bsdf"]["bsdf"]
    assert blend["type"] == "blendbsdf"
    vals = [np.array([float(x) for x in blend[k]["reflectance"]["values"].split(",")])
            for k in ("bsdf_0", "bsdf_1")]
    assert np.allclose(vals[0], mat.SPECTRA["bark"], atol=1e-4)
    assert np.allclose(vals[1], mat.SPECTRA["bark_light"], atol=1e-4)
    assert mat.band_mean("bark_light", 500, 600) > mat.band_mean("bark", 500, 600)
    mi.load_dict(d)


def test_knots_are_drawn_as_swellings_and_the_light_mesh_is_unchanged():
    from mitsuba_veg.render.trees import make_tree
    from mitsuba_veg.trees.junction import stem_structure, tree_mesh
    # scaled to 5 m (the drawn geometry, not the generator's attrs, sets the knot's length)
    t = make_tree({"preset": "quaking_aspen", "seed": 3, "height": 5.0})
    assert t.weber_penn.knots
    before = {k: np.array(getattr(t, k)) for k in ("start", "end", "radius_start",
                                                    "radius_end")}
    plain, _ = tree_mesh(t, leaves=False)
    again, _ = tree_mesh(t, leaves=False, round_knots=False)
    assert np.array_equal(plain.vertices, again.vertices)       # the default: unchanged
    rnd, _ = tree_mesh(t, leaves=False, round_knots=True)
    for k, v in before.items():
        assert np.array_equal(getattr(t, k), v)                  # the model's numbers
    st = stem_structure(t)
    knot = np.nonzero((t.kind == 1) & ~st["cont"] & (st["nxt"] >= 0))[0][0]
    # the knot stem's segments: the drawn radius at each segment's end follows the ellipse
    j, seen, s = knot, 0, 0.0
    R = t.radius_start[knot]
    Lk = st["length"][st["stem"] == st["stem"][knot]].sum()
    vr = rnd.metadata["vertex_ring"]
    rs = rnd.metadata["ring_segment"]
    top = rnd.metadata["top_ring"]
    while j >= 0 and st["nxt"][j] >= 0:
        ring = np.nonzero(vr == top[j])[0]
        assert rs[top[j]] == j
        r = np.linalg.norm(rnd.vertices[ring] - t.end[j], axis=1).mean()
        s += st["length"][j]
        assert r == pytest.approx(R * np.sqrt(1 - (s / Lk) ** 2), rel=1e-3)
        assert r >= t.radius_end[j] - 1e-12                      # fuller than the cone
        j, seen = st["nxt"][j], seen + 1
    assert seen >= 2
