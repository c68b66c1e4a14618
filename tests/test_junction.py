"""Paper 004 §4: smooth branch junctions (eqs 4.1-4.2) and the bark / leaf meshes."""
from __future__ import annotations

import numpy as np
import pytest

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees import junction as J
from mitsuba_veg.trees import weber_penn as wp
from mitsuba_veg.trees.structure import Tree


# ---- synthetic trees -------------------------------------------------------------------------
def chain_tree(angle=90.0, rp=0.3, rc=(0.1, 0.08, 0.0), h=1.0, grand=False):
    """A straight vertical trunk (2 segments, y 0..4, constant radius ``rp``) with one branch
    at height ``h`` leaving at ``angle`` degrees from the trunk (2 segments of 1 m, radii
    ``rc``), optionally with a level-2 twig on the branch and a level-3 twig on that."""
    start = [[0, 0, 0], [0, 2, 0]]
    end = [[0, 2, 0], [0, 4, 0]]
    r0, r1 = [rp, rp], [rp, rp]
    par, lvl, stem = [-1, 0], [0, 0], [0, 0]
    attach, arc, slen, srad, fx = [0.0, 1.0], [0.0, 2.0], [4.0, 4.0], [rp, rp], [[0, 0, 1]] * 2
    a = np.radians(angle)
    d = np.array([np.sin(a), np.cos(a), 0.0])
    o = np.array([0.0, h, 0.0])
    for j in range(2):
        start.append(o + j * d)
        end.append(o + (j + 1) * d)
        r0.append(rc[j])
        r1.append(rc[j + 1])
        par.append(0 if j == 0 else 2)
        lvl.append(1)
        stem.append(1)
        attach.append(h / 2.0 if j == 0 else 1.0)
        arc.append(float(j))
        slen.append(2.0)
        srad.append(rc[0])
        fx.append([0, 0, 1])
    if grand:
        # level 2 on the branch's second segment, level 3 on the level-2 twig
        base = o + 1.5 * d
        d2 = np.array([0.0, 0.0, 1.0])
        for lv_, (b, dd, pr, r) in enumerate([(base, d2, 3, 0.04), (base + 0.45 * d2, d,
                                                                       5, 0.015)]):
            for j in range(2):
                start.append(b + j * 0.3 * dd)
                end.append(b + (j + 1) * 0.3 * dd)
                r0.append(r * (1 - j / 2))
                r1.append(r * (1 - (j + 1) / 2))
                par.append(pr if j == 0 else len(start) - 2)
                lvl.append(2 + lv_)
                stem.append(2 + lv_)
                attach.append(0.5 if j == 0 else 1.0)
                arc.append(0.3 * j)
                slen.append(0.6)
                srad.append(r)
                fx.append([1, 0, 0] if lv_ == 0 else [0, 0, 1])
    n = len(start)
    attrs = {"stem": np.array(stem), "attach": np.array(attach), "arc": np.array(arc),
             "stem_length": np.array(slen), "stem_radius": np.array(srad),
             "frame_x": np.array(fx, float), "clone": np.zeros(n, bool)}
    return Tree(start, end, r0, r1, par, lvl, attrs=attrs)


def junction_rings_of(bark, seg):
    """Vertices (D+1, S+1, 3) of the junction rings of segment ``seg`` (they follow its top
    ring in the ring order)."""
    md = bark.metadata
    rings = np.nonzero(md["ring_segment"] == seg)[0][1:]
    vr = md["vertex_ring"]
    return np.stack([bark.vertices[vr == r] for r in rings])


# ---- eqs 4.1 - 4.2 -----------------------------------------------------------------------------
def test_eq42_hand_values():
    P, C, B = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.zeros(3)
    # F = 2, scale 0.5, D = 2: d = 1 -> ((1/2)^2 P + (1/2)^2 C) / 2
    np.testing.assert_allclose(J.eq42(P, C, B, 1, 2, 2.0, 0.5), [0.125, 0.125, 0.0])
    np.testing.assert_allclose(J.eq42(P, C, B, 2, 2, 2.0, 0.5), [0.5, 0.0, 0.0])
    np.testing.assert_allclose(J.eq42(P, C, B, 0, 2, 2.0, 0.5), [0.0, 0.5, 0.0])
    # F = 1 is the chord, F = 0.5 bulges beyond it
    np.testing.assert_allclose(J.eq42(P, C, B, 1, 2, 1.0, 1.0), [0.5, 0.5, 0.0])
    np.testing.assert_allclose(J.eq42(P, C, B, 1, 2, 0.5, 1.0), [np.sqrt(0.5)] * 2 + [0.0])
    # B is the origin of the curve: shifting everything shifts the result
    sh = np.array([3.0, -1.0, 2.0])
    np.testing.assert_allclose(J.eq42(P + sh, C + sh, B + sh, 1, 3, 1.7, 0.3),
                               J.eq42(P, C, B, 1, 3, 1.7, 0.3) + sh)
    # the batch form gives the same rings
    Pn, Cn, Bn = (np.tile(x, (2, 3, 1)) for x in (P, C, B))
    rings = J.junction_rings(Pn, Cn, Bn, 4, np.full((2, 3), 2.0), np.array([0.5, 0.5]))
    for d in range(5):
        np.testing.assert_allclose(rings[0, d, 0], J.eq42(P, C, B, d, 4, 2.0, 0.5))


def test_eq41_subdivisions_per_level():
    np.testing.assert_array_equal(J.subdivisions(6, np.arange(1, 8)), [6, 3, 2, 1, 1, 1, 1])
    np.testing.assert_array_equal(J.subdivisions(7, [1, 2, 3]), [7, 3, 2])
    with pytest.raises(ParameterError, match="Du"):
        J.subdivisions(0, 1)


def test_mesh_ring_counts_follow_du_over_level():
    t = chain_tree(grand=True)
    for Du in (6, 4, 2):
        bark, _ = J.tree_mesh(t, D_u=Du, sides=(8, 6, 5, 4), leaves=False)
        D = bark.metadata["junction_D"]
        assert D[2] == Du and D[4 + 0] == max(1, Du // 2) and D[6] == max(1, Du // 3)
        assert D[[0, 1, 3, 5, 7]].sum() == 0                # trunk and continuations
        for seg, S in ((2, 6), (4, 5), (6, 4)):
            rings = junction_rings_of(bark, seg)
            assert rings.shape == (D[seg] + 1, S + 1, 3)
    unsmoothed, _ = J.tree_mesh(t, smooth=False, leaves=False)
    assert unsmoothed.metadata["junction_D"].sum() == 0


def test_junction_vertices_match_hand_computed_eq42():
    # perpendicular branch on a straight cylinder: B, P and C in closed form
    rp, h, S_p = 0.3, 1.0, 16
    t = chain_tree(angle=90.0, rp=rp, rc=(0.1, 0.08, 0.0), h=h)
    stretch, compress, Du = 1.5, 2.5, 4
    bark, _ = J.tree_mesh(t, D_u=Du, stretch=stretch, compress=compress, sides=(S_p, 4),
                          leaves=False)
    got = junction_rings_of(bark, 2)                                   # (5, 5, 3)
    rpe = rp * np.cos(np.pi / S_p) * 0.98
    k = (2.0 * 0.1) / (4.0 * 0.3)                                      # l_c r_c / (l_p r_p)
    th = 2 * np.pi * np.arange(5) / 4
    # corner directions: u = z (frame_x), v = x-axis cross z = -y; c_m = -sin(theta)
    cm = -np.sin(th)
    B = np.stack([np.sqrt(rpe ** 2 - (0.1 * np.cos(th)) ** 2), h - 0.1 * np.sin(th),
                  0.1 * np.cos(th)], 1)
    h_up, h_dn = 2.0, 0.0                                              # the trunk's nodes
    hB = B[:, 1]
    hP = np.where(cm >= 0, hB + cm * (h_up - hB), hB + cm * (hB - h_dn))
    P = B.copy()
    P[:, 1] = hP
    C = np.stack([np.ones(5), h - 0.08 * np.sin(th), 0.08 * np.cos(th)], 1)
    F = 0.5 * (1 + cm) * stretch + 0.5 * (1 - cm) * compress
    for d in range(Du + 1):
        s = d / Du
        want = ((1 - s) ** F[:, None] * (P - B) + s ** F[:, None] * (C - B)) * k + B
        np.testing.assert_allclose(got[d], want, atol=1e-9)
    # upper corner (theta = 270 deg) uses Stretch and reaches up towards the node above,
    # the lower corner (90 deg) uses Compress and reaches down
    assert got[0, 3, 1] > h + 0.1 and got[0, 1, 1] < h - 0.1


# ---- mesh quality ------------------------------------------------------------------------------
def _merged_ids(v, digits=9):
    """Index of each vertex among the distinct positions (seam duplicates merged)."""
    q = np.ascontiguousarray(np.round(np.asarray(v, float), digits) + 0.0)
    _, inv = np.unique(q.view(np.dtype((np.void, q.dtype.itemsize * 3))).ravel(),
                       return_inverse=True)
    return inv.ravel()


def _heads(t):
    a = t.attrs
    return (t.parent >= 0) & (a["stem"][np.maximum(t.parent, 0)] != a["stem"]) & ~a["clone"]


def _seg_tri(p0, p1, a, b, c, eps=1e-7):
    d = p1 - p0
    e1, e2 = b - a, c - a
    hh = np.cross(d, e2)
    det = np.sum(e1 * hh, -1)
    ok = np.abs(det) > 1e-14
    f = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = p0 - a
    u = f * np.sum(s * hh, -1)
    q = np.cross(s, e1)
    v = f * np.sum(d * q, -1)
    tt = f * np.sum(e2 * q, -1)
    return ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (tt > eps) & (tt < 1 - eps)


def self_intersections(V, F):
    """Number of pairs of faces (sharing no vertex) that cross each other."""
    ids = _merged_ids(V)[F]
    i, j = np.triu_indices(len(F), 1)
    share = (ids[i][:, :, None] == ids[j][:, None, :]).any((1, 2))
    i, j = i[~share], j[~share]
    T1, T2 = V[F[i]], V[F[j]]
    hit = np.zeros(len(i), bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        hit |= _seg_tri(T1[:, a], T1[:, b], T2[:, 0], T2[:, 1], T2[:, 2])
        hit |= _seg_tri(T2[:, a], T2[:, b], T1[:, 0], T1[:, 1], T1[:, 2])
    return int(hit.sum())


def boundary_vertices(mesh):
    ids = _merged_ids(mesh.vertices)
    f = ids[mesh.faces]
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    ue, cnt = np.unique(e, axis=0, return_counts=True)
    bids = np.unique(ue[cnt == 1])
    first = np.full(ids.max() + 1, -1)
    first[ids[::-1]] = np.arange(len(ids))[::-1]
    return first[bids]


def inside_parent(tree, bark, sides0=16):
    """For each boundary vertex: (distance from its parent's axis) / (inradius of the parent's
    faceted tube there); < 1 means the open end is covered by the parent's bark."""
    md = bark.metadata
    bv = boundary_vertices(bark)
    seg = md["ring_segment"][md["vertex_ring"][bv]]
    x = bark.vertices[bv]
    out = np.full(len(bv), np.inf)
    st = J.stem_structure(tree)
    S = J._sides_of(tree, (sides0, 8, 6, 4), 8)
    ld = np.asarray(tree.attrs.get("lobe_depth", np.zeros(len(tree))))
    p = tree.parent[seg]
    # the parent segment and its neighbours on the same stem (a junction near a node spans it)
    cands = [p, np.where((tree.parent[p] >= 0) & st["cont"][p], tree.parent[p], p),
             np.where(st["nxt"][p] >= 0, st["nxt"][p], p)]
    for q in cands:
        d = tree.end[q] - tree.start[q]
        tq = np.clip(np.sum((x - tree.start[q]) * d, 1) / np.sum(d * d, 1), 0, 1)
        dist = np.linalg.norm(x - (tree.start[q] + tq[:, None] * d), axis=1)
        r = (tree.radius_start[q] + tq * (tree.radius_end[q] - tree.radius_start[q])) \
            * np.cos(np.pi / S[q]) * (1 - ld[q])
        out = np.minimum(out, dist / r)
    return seg, out


@pytest.mark.parametrize("angle", [25.0, 45.0, 60.0, 90.0, 120.0, 150.0])
@pytest.mark.parametrize("kw", [dict(), dict(gain=5.0), dict(stretch=0.6, compress=0.6),
                                dict(stretch=3.0, compress=1.0, D_u=2)])
def test_smoothed_junction_has_no_holes_and_no_overlaps(angle, kw):
    t = chain_tree(angle=angle, rc=(0.12, 0.1, 0.0))
    bark, _ = J.tree_mesh(t, sides=(16, 8), leaves=False, **kw)
    # the only open edges are the junction's base ring, lying under the parent's bark
    seg, ratio = inside_parent(t, bark)
    assert set(seg.tolist()) == {2}
    assert ratio.max() < 1.0
    # the junction surface (rings N_0 .. N_D and the piece to the first node) does not fold
    fj = bark.faces[bark.metadata["segment"] == 2]
    assert self_intersections(bark.vertices, fj) == 0
    assert bark.is_winding_consistent


def test_preset_mesh_has_no_holes_at_junctions_and_forks():
    t = wp.generate("ca_black_oak", seed=2)          # knots, clones (splits) and junctions
    bark, _ = wp.mesh(t, leaves=False)
    seg, ratio = inside_parent(t, bark)
    assert len(seg) > 0
    assert ratio.max() < 1.0                          # every open end is under a parent's bark
    assert np.all(t.parent[seg] >= 0)                 # the trunk base and the tips are closed
    # sample of junctions (branches and knots, with a large gain too): no folded rings
    rng = np.random.default_rng(0)
    jd = np.nonzero(bark.metadata["junction_D"] > 0)[0]
    for kw in (dict(), dict(gain=4.0, knot_gain=300.0)):
        b, _ = wp.mesh(t, leaves=False, **kw)
        for c in rng.choice(jd, 25, replace=False):
            fj = b.faces[b.metadata["segment"] == c]
            assert self_intersections(b.vertices, fj) == 0, c


def test_smoothing_only_changes_the_junctions():
    t = wp.generate({"preset": "quaking_aspen", "Levels": 2, "Leaves": 0}, seed=4)
    a, _ = J.tree_mesh(t, smooth=False, leaves=False)
    b, _ = J.tree_mesh(t, smooth=True, leaves=False)
    # the ring at every segment's end is the same; only the branch bases differ
    for m_ in (a, b):
        off = np.r_[0, np.cumsum(np.bincount(m_.metadata["vertex_ring"][
            m_.metadata["vertex_ring"] >= 0]))]
        m_.top = np.concatenate([m_.vertices[off[r]:off[r + 1]] for r in m_.metadata["top_ring"]])
    np.testing.assert_array_equal(a.top, b.top)
    assert len(b.vertices) > len(a.vertices)
    assert (b.metadata["junction_D"] > 0).sum() == (_heads(t) & (t.level > 0)).sum()


def test_bark_uvs_and_leaf_mesh():
    t = wp.generate({"preset": "sassafras", "Levels": 2, "Leaves": 5}, seed=1)
    bark, leaves = J.tree_mesh(t, leaves=True)
    uv = bark.visual.uv
    assert uv.shape == (len(bark.vertices), 2)
    assert np.isfinite(uv).all() and uv[:, 0].min() >= 0 and uv[:, 0].max() <= 1
    # v grows along the trunk: v = distance / base circumference
    r = bark.metadata["vertex_ring"]
    top0 = uv[r == 0, 1]
    top_last = uv[r == int(np.nonzero(t.level == 0)[0][-1]), 1]
    assert top_last.mean() > top0.mean() > 0
    m = len(t.leaves)
    assert len(leaves.faces) == 4 * m and len(leaves.vertices) == 6 * m
    assert leaves.visual.uv.shape == (6 * m, 2)
    # blades: length LeafScale along `up`, width LeafScale * LeafScaleX
    v = leaves.vertices.reshape(m, 6, 3)
    np.testing.assert_allclose(np.linalg.norm(v[:, 3] - v[:, 0], axis=1), t.leaves.size)
    _, quads = J.tree_mesh(t, leaf_shape="quad")
    assert len(quads.faces) == 2 * m
    # the bark as plain arrays (what the render and the world's trees take): the same mesh
    arr, none = J.tree_mesh(t, leaves=False, arrays=True, round_knots=True)
    ref, _ = J.tree_mesh(t, leaves=False, round_knots=True)
    assert none is None and isinstance(arr, J.BarkArrays)
    np.testing.assert_array_equal(arr.vertices, ref.vertices)
    np.testing.assert_array_equal(arr.faces, ref.faces)
    np.testing.assert_array_equal(arr.uv, ref.visual.uv)
    assert "vertex_ring" in arr.metadata and set(arr.metadata) <= set(ref.metadata)
    for k, val in arr.metadata.items():
        np.testing.assert_array_equal(val, ref.metadata[k])


def test_mesh_of_trees_without_weber_penn_attributes():
    # a bare Tree (e.g. from the growth model): stems are inferred, junctions still close
    t0 = chain_tree(angle=60.0)
    t = Tree(t0.start, t0.end, t0.radius_start, t0.radius_end, t0.parent, t0.level)
    bark, _ = J.tree_mesh(t, leaves=False, sides=(16, 8))
    assert bark.metadata["junction_D"][2] == 6
    seg, ratio = inside_parent(t, bark)
    assert set(seg.tolist()) == {2} and ratio.max() < 1.0


def test_bad_mesh_options():
    t = chain_tree()
    with pytest.raises(ParameterError):
        J.tree_mesh(t, D_u=0)
    with pytest.raises(ParameterError):
        J.tree_mesh(t, stretch=-1.0)
    with pytest.raises(ParameterError):
        J.tree_mesh(t, leaf_shape="star")
    with pytest.raises(ParameterError):
        J.tree_mesh(t, sides=(16, 2))
    with pytest.raises(ParameterError, match="arrays"):
        J.tree_mesh(t, arrays=True)              # the leaves have no arrays form
