"""Bark and leaf meshes with smooth branch junctions (paper 004, section 4).

:func:`tree_mesh` turns a :class:`~mitsuba_veg.trees.structure.Tree` into one bark mesh (tubes
with UVs, welded along each stem, capped at the tips) and one leaf mesh. Where a branch leaves its
parent, the tube between the branch base and its first node is rebuilt from control points per
tube corner m (paper 004 §4.3):

- ``B`` - the original contact point: where the corner's line along the branch meets the parent's
  surface;
- ``P`` - the connection point on the parent, at the height (distance along the parent) of the
  nearest neighbouring branch base or parent node above (upper corners) or below (lower corners)
  the branch (§4.2.1); a node that coincides with the branch base is skipped;
- ``C`` - the corner at the branch's first node.

Rings d = 0..D follow eq 4.2,

    N_{d,m} = ((1 - d/D)^F (P - B) + (d/D)^F (C - B)) · (l_c r_c)/(l_p r_p) + B,

with F = Stretch on the upper side (tension wood) and F = Compress on the lower side
(compression wood), and D = D_u / level (eq 4.1). F = 2 gives a quadratic Bezier curve with B as
control point (tangent to the parent at d = 0 and to the branch at d = D), F < 1 a bulge (lumpy
knots), F = 1 a straight chamfer. Ring d = 0 lies on (just under) the parent's surface, so the
junction closes the gap between branch and parent without holes.

Everything is vectorised over segments, rings and junctions (NumPy); trees from other models
work too (stems are then inferred from the parent/level arrays).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .structure import Tree

__all__ = ["subdivisions", "eq42", "junction_rings", "contact_points", "BarkArrays",
           "tree_mesh", "leaf_mesh", "stem_structure"]

LEAF_OUTLINE = np.array([[-0.5, 0.0], [-0.25, 0.433], [0.25, 0.433], [0.5, 0.0],
                         [0.25, -0.433], [-0.25, -0.433]])   # (along, across), ellipse samples


def subdivisions(D_u, level):
    """Eq 4.1: junction subdivisions ``D = D_u / level`` (integer division, at least 1).

    Parameters
    ----------
    D_u : int
        ``Du``, subdivisions of a first-level junction [-]; >= 1.
    level : int or array_like
        Branching level of each branch (levels below 1 count as 1).

    Returns
    -------
    numpy.ndarray
        int64 ``D`` per branch (shape of ``level``), >= 1.

    Raises
    ------
    ParameterError
        If ``D_u < 1``.
    """
    D_u = int(D_u)
    if D_u < 1:
        raise ParameterError("Du", D_u, "an integer >= 1", "set junction.Du to 1 or more")
    level = np.asarray(level)
    return np.maximum(1, D_u // np.maximum(level, 1)).astype(np.int64)


def eq42(P, C, B, d, D, F, scale):
    """Eq 4.2 for one subdivision ``d`` (0..D): the junction vertex of each corner.

    ``N_{d,m} = ((1 - d/D)^F (P - B) + (d/D)^F (C - B)) · scale + B``.

    Parameters
    ----------
    P, C, B : array_like
        (..., 3) control points [m]: connection point on the parent, corner at the branch's first
        node, original contact point.
    d : int or array_like
        Subdivision index, 0..D.
    D : int or array_like
        Number of subdivisions (eq 4.1).
    F : float or array_like
        (...) exponent: Stretch (upper side) or Compress (lower side) [-].
    scale : float or array_like
        (...) ``(length_c radius_c)/(length_p radius_p)`` [-].

    Returns
    -------
    numpy.ndarray
        (..., 3) junction vertices [m].
    """
    P, C, B = (np.asarray(x, float) for x in (P, C, B))
    t = np.asarray(d, float) / np.asarray(D, float)
    F = np.asarray(F, float)[..., None]
    s = np.asarray(scale, float)[..., None]
    t = t[..., None] if np.ndim(t) else t
    return ((1.0 - t) ** F * (P - B) + t ** F * (C - B)) * s + B


def junction_rings(P, C, B, D, F, scale):
    """Rings d = 0..D (eq 4.2) for junctions with the same ``D``.

    Parameters
    ----------
    P, C, B : array_like
        (n, M, 3) control points [m] of n junctions with M ring corners each (see :func:`eq42`).
    D : int
        Number of subdivisions, shared by all n junctions.
    F : array_like
        (n, M) exponents (Stretch / Compress) [-].
    scale : array_like
        (n,) ``(length_c radius_c)/(length_p radius_p)`` [-].

    Returns
    -------
    numpy.ndarray
        (n, D+1, M, 3) ring vertices [m].
    """
    P, C, B = (np.asarray(x, float) for x in (P, C, B))
    t = (np.arange(D + 1) / D)[None, :, None, None]
    F = np.asarray(F, float)[:, None, :, None]
    s = np.asarray(scale, float)[:, None, None, None]
    return ((1.0 - t) ** F * (P - B)[:, None] + t ** F * (C - B)[:, None]) * s + B[:, None]


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _perp_unit(u, t, fallback=None):
    """``u`` made perpendicular to unit ``t`` and normalised (fallback where degenerate)."""
    w = u - np.sum(u * t, axis=-1, keepdims=True) * t
    n = np.linalg.norm(w, axis=-1, keepdims=True)
    if fallback is None:
        a = np.where(np.abs(t[..., 1:2]) < 0.9, np.array([0.0, 1.0, 0.0]),
                     np.array([1.0, 0.0, 0.0]))
        fallback = _unit(np.cross(t, a))
    return np.where(n > 1e-9, w / np.maximum(n, 1e-300), fallback)


def contact_points(S, O, a_c, a_p, e, r_c, r_p, s_max=None, slope=None):
    """Original contact points B: where the corner lines of a branch meet its parent's surface.

    The corner lines ``S + r_c e_m + s a_c`` meet the parent's surface, a cone around the axis
    through ``O`` along ``a_p`` with radius ``r_p + slope · h`` at height ``h`` above ``O``
    (``slope`` = 0: a cylinder). The outer intersection is taken (``s`` may be negative when a
    corner starts outside the parent); ``s`` is clamped to ``s_max`` so that B stays before the
    branch's first node. A corner line that misses the surface keeps ``s = 0``.

    Parameters
    ----------
    S : numpy.ndarray
        (n, 3) branch starts [m].
    O : numpy.ndarray
        (n, 3) the junction on the parent's axis [m].
    a_c : numpy.ndarray
        (n, 3) unit branch directions [-].
    a_p : numpy.ndarray
        (n, 3) unit parent directions [-].
    e : numpy.ndarray
        (n, M, 3) unit corner directions [-] (perpendicular to ``a_c``).
    r_c : numpy.ndarray
        (n,) branch radii [m].
    r_p : numpy.ndarray
        (n,) parent radii at ``O`` [m].
    s_max : array_like, optional
        (n,) or (n, M) upper bound on ``s`` [m]; default None: unbounded.
    slope : array_like, optional
        (n,) change of the parent's radius per unit height [-] (default None: 0, a cylinder).

    Returns
    -------
    B : numpy.ndarray
        (n, M, 3) contact points [m].
    s : numpy.ndarray
        (n, M) distance along ``a_c`` from each corner's start to B [m].
    """
    sl = np.zeros(len(S)) if slope is None else np.asarray(slope, float)
    w = (S - O)[:, None] + r_c[:, None, None] * e
    a0 = np.sum(w * a_p[:, None], -1)                       # height of the corner start
    q = w - a0[..., None] * a_p[:, None]
    ca = np.sum(a_c * a_p, -1)[:, None]
    g = a_c - ca * a_p
    R = r_p[:, None] + sl[:, None] * a0                      # surface radius at that height
    k = sl[:, None] * ca                                     # its change per unit s
    A = np.sum(g * g, -1)[:, None] - k * k
    Bq = np.sum(q * g[:, None], -1) - R * k
    Cq = np.sum(q * q, -1) - R * R
    disc = Bq * Bq - A * Cq
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where((np.abs(A) > 1e-12) & (disc >= 0),
                     (-Bq + np.sqrt(np.maximum(disc, 0.0))) / np.where(np.abs(A) > 1e-12, A, 1.0),
                     0.0)
    if s_max is not None:
        sm = np.asarray(s_max, float)
        s = np.minimum(s, sm[:, None] if sm.ndim == 1 else sm)
    B = S[:, None] + r_c[:, None, None] * e + s[..., None] * a_c[:, None]
    return B, s


def stem_structure(tree: Tree) -> dict:
    """Per-segment stem bookkeeping of a tree.

    Uses the Weber-Penn attributes when present, else infers them (a child continues its
    parent's stem when it is the parent's first child of the same level).

    Parameters
    ----------
    tree : Tree
        The tree.

    Returns
    -------
    dict
        Arrays over the n segments: ``stem`` (int stem ids), ``cont`` (bool, continues its
        parent's stem), ``nxt`` (next segment of the stem or -1), ``arc`` (distance from the stem
        base at the segment start [m]), ``frame_x`` ((n, 3) reference direction of the tube
        frame), ``clone`` (bool, a same-level fork of its parent), ``attach`` (position of the
        start on the parent, fraction 0..1 of its length [-]), ``stem_length`` [m],
        ``stem_radius`` (radius at the stem base [m]), ``length`` (segment lengths [m]) and
        ``dir`` ((n, 3) unit segment directions).
    """
    n = len(tree)
    at = tree.attrs
    par = tree.parent
    alive = tree.alive
    idx = np.arange(n)
    haspar = (par >= 0)
    pp = np.where(haspar, par, 0)
    d = tree.end - tree.start
    ln = np.linalg.norm(d, axis=1)
    if "stem" in at and len(at["stem"]) == n:
        stem = np.asarray(at["stem"], np.int64)
        cont = haspar & (stem[pp] == stem)
    else:
        same = haspar & (tree.level[pp] == tree.level)
        first = np.full(n, -1)
        cand = idx[same][::-1]
        first[par[cand]] = cand           # smallest index wins (written last)
        cont = same & (first[pp] == idx)
        stem = idx.copy()
        for _ in range(n):                # propagate along chains (vectorised per step)
            new = np.where(cont, stem[pp], stem)
            if np.array_equal(new, stem):
                break
            stem = new
    cont = cont & alive[pp] & alive
    nxt = np.full(n, -1)
    nxt[par[cont]] = idx[cont]
    if "arc" in at and len(at["arc"]) == n:
        arc = np.asarray(at["arc"], float)
    else:
        arc = np.zeros(n)
        for _ in range(n):
            new = np.where(cont, arc[pp] + ln[pp], 0.0)
            if np.allclose(new, arc):
                break
            arc = new
    if "frame_x" in at and len(at["frame_x"]) == n:
        fx = np.asarray(at["frame_x"], float)
    else:
        fx = np.zeros((n, 3))
        fx[:, 0] = 1.0
    clone = np.asarray(at["clone"], bool) if "clone" in at else (
        haspar & ~cont & (tree.level[pp] == tree.level))
    if "attach" in at and len(at["attach"]) == n:
        attach = np.asarray(at["attach"], float)
    else:
        dp = d[pp]
        attach = np.clip(np.sum((tree.start - tree.start[pp]) * dp, 1)
                         / np.maximum(np.sum(dp * dp, 1), 1e-300), 0.0, 1.0)
    if "stem_length" in at and "stem_radius" in at:
        slen = np.asarray(at["stem_length"], float)
        srad = np.asarray(at["stem_radius"], float)
    else:
        tot = np.zeros(stem.max() + 1 if n else 0)
        np.add.at(tot, stem, ln)
        slen = tot[stem]
        base = np.zeros_like(tot)
        heads = ~cont
        base[stem[heads]] = tree.radius_start[heads]
        srad = base[stem]
    return {"stem": stem, "cont": cont, "nxt": nxt, "arc": arc, "frame_x": fx, "clone": clone,
            "attach": attach, "stem_length": slen, "stem_radius": srad, "length": ln,
            "dir": _unit(d)}


def _sides_of(tree, sides, knot_sides):
    lv = np.minimum(tree.level, len(sides) - 1)
    s = np.asarray(sides, np.int64)[lv]
    s = np.where(tree.kind != 0, np.maximum(s, knot_sides), s)
    lobes = np.asarray(tree.attrs.get("lobes", np.zeros(len(tree))), np.int64)
    depth = np.asarray(tree.attrs.get("lobe_depth", np.zeros(len(tree))), float)
    s = np.where((lobes > 0) & (depth > 0), np.maximum(s, 4 * lobes), s)
    return s


def _ring_vertices(center, t, u, r, S, lobes, depth):
    """(R, S+1, 3) ring vertices (seam duplicated) for rings with ``S`` corners."""
    v = np.cross(t, u)
    th = 2 * np.pi * np.arange(S + 1) / S
    rr = r[:, None] * (1.0 + depth[:, None] * np.sin(lobes[:, None] * th[None, :]))
    return (center[:, None, :] + rr[..., None] * (np.cos(th)[None, :, None] * u[:, None, :]
                                                  + np.sin(th)[None, :, None] * v[:, None, :]))


def _tube_faces(oA, oB, S):
    """Faces between rings starting at vertex offsets ``oA`` -> ``oB`` (S corners, S+1 verts)."""
    k = np.arange(S)
    q = np.stack([np.stack([k, k + 1, (S + 1) + k + 1], 1),
                  np.stack([k, (S + 1) + k + 1, (S + 1) + k], 1)], 1).reshape(-1, 3)
    # local index: < S+1 -> ring A, else ring B
    a = q < (S + 1)
    out = np.where(a[None], oA[:, None, None] + q[None], oB[:, None, None] + (q[None] - (S + 1)))
    return out.reshape(-1, 3)


@dataclass
class BarkArrays:
    """A bark mesh as plain arrays (:func:`tree_mesh` with ``arrays=True``): ``vertices``
    (n, 3) [m], ``faces`` (f, 3), ``uv`` (n, 2) and ``metadata`` (as the trimesh's)."""

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    metadata: dict = field(default_factory=dict)


def tree_mesh(tree: Tree, *, smooth: bool = True, sides=(16, 8, 6, 4), knot_sides: int = 8,
              D_u=None, stretch=None, compress=None, gain=None, knot_gain=None,
              leaves: bool = True,
              leaf_shape: str = "oval", min_radius: float = 0.0, caps: bool = True,
              round_knots: bool = False, arrays: bool = False):
    """``(bark, leaves)`` trimesh meshes of ``tree``.

    The bark carries UVs (u around the stem, v along it in units of the stem's base
    circumference); ``bark.metadata`` holds ``junction_D`` (D per segment, 0 where not
    smoothed), ``segment`` (the tree segment of each face), ``vertex_ring`` (ring id of each
    vertex), ``ring_segment`` (segment of each ring) and ``top_ring`` (ring at each segment's
    end).

    Parameters
    ----------
    tree : Tree
        The tree (positions and radii [m]).
    smooth : bool, optional
        Rebuild branch bases with eq 4.2 (paper 004 §4); default True.
    sides : sequence of int, optional
        Tube corners per level, the last entry for all deeper levels (default (16, 8, 6, 4));
        each >= 3. The trunk gets at least 4 x Lobes for its lobes.
    knot_sides : int, optional
        Minimum corners of knot tubes (default 8).
    D_u : int, optional
        Junction subdivisions ``Du`` (eq 4.1); default None: the tree's Weber-Penn
        ``junction`` table, else 6.
    stretch : float, optional
        Exponent F on the upper side (tension wood) [-]; default None: the table, else 1.3.
    compress : float, optional
        Exponent F on the lower side (compression wood) [-]; default None: the table, else 2.0.
    gain : float, optional
        Extra factor on eq 4.2's scale for branches [-] (default None: the table's ``Gain``,
        else 1 = the paper); the scale is clipped to 1.
    knot_gain : float, optional
        The same for knots [-] (default None: the table's ``KnotGain``, else 1).
    leaves : bool, optional
        Build the leaf mesh (default True; else an empty mesh).
    leaf_shape : str, optional
        ``"oval"`` (6-gon, 4 triangles, the default) or ``"quad"``.
    min_radius : float, optional
        Lower bound on the drawn radii [m] (default 0).
    caps : bool, optional
        Close branch tips and roots with triangle fans (default True).
    round_knots : bool, optional
        Draw knots (kind ``KNOT``, paper 004 §3.3) as swellings of the bark: the rings of a knot's
        stem follow the half-ellipse r(s) = R sqrt(1 − (s / L)²) of its first radius R and its
        drawn length L (s: distance from the knot's base) instead of the segments' linear taper
        (a cone with a pointed tip); the knot keeps its length, base radius and junction.
        Default False (the light scene's mesh, unchanged).
    arrays : bool, optional
        Return the bark as :class:`BarkArrays` (the same vertices, faces, UVs and metadata)
        without importing trimesh (about half a second a process: the render and the world's
        trees need only the arrays); needs ``leaves=False``. Default False.

    Returns
    -------
    bark : trimesh.Trimesh or BarkArrays
        The bark mesh [m], with UVs and the metadata above.
    leaves : trimesh.Trimesh or None
        The leaf mesh [m] (:func:`leaf_mesh`); None with ``arrays``.

    Raises
    ------
    ParameterError
        For junction parameters out of range, an unknown ``leaf_shape``, ``sides`` < 3, or
        ``arrays`` with ``leaves``.
    """
    if arrays and leaves:
        raise ParameterError("arrays", arrays, "False when leaves=True",
                             "pass leaves=False for the bark's arrays")

    wp = getattr(tree, "weber_penn", None)
    jp = {"Du": 6, "Stretch": 1.3, "Compress": 2.0, "Gain": 1.0, "KnotGain": 1.0}
    if wp is not None:
        jp.update(wp.params.junction)
    D_u = int(jp["Du"] if D_u is None else D_u)
    stretch = float(jp["Stretch"] if stretch is None else stretch)
    compress = float(jp["Compress"] if compress is None else compress)
    gain = float(jp["Gain"] if gain is None else gain)
    knot_gain = float(jp["KnotGain"] if knot_gain is None else knot_gain)
    subdivisions(D_u, 1)
    check_range("stretch", stretch, 1e-3, 20.0, fix="use a positive exponent")
    check_range("compress", compress, 1e-3, 20.0, fix="use a positive exponent")
    check_range("gain", gain, 0.0, None, fix="use gain >= 0 (1 = paper 004 eq 4.2)")
    check_range("knot_gain", knot_gain, 0.0, None, fix="use knot_gain >= 0 (1 = paper 004)")
    if leaf_shape not in ("oval", "quad"):
        raise ParameterError("leaf_shape", leaf_shape, "'oval' or 'quad'")
    if len(sides) < 1 or min(sides) < 3:
        raise ParameterError("sides", sides, "corners per level, each >= 3")

    n = len(tree)
    st = stem_structure(tree)
    alive = tree.alive
    par = tree.parent
    pp = np.where(par >= 0, par, 0)
    dirs, ln = st["dir"], st["length"]
    cont, nxt = st["cont"], st["nxt"]
    Sg = _sides_of(tree, sides, knot_sides)
    r0 = np.maximum(tree.radius_start, min_radius)
    r1 = np.maximum(tree.radius_end, min_radius)
    if round_knots:          # a knot's stem as a half-ellipse of its base radius and length
        kn = tree.kind == 1                                 # KNOT (structure.KNOT)
        heads = ~st["cont"]                                 # R: the knot stem's first radius
        m = int(st["stem"].max()) + 1 if n else 0
        base, L_k = np.zeros(m), np.zeros(m)
        base[st["stem"][heads]] = tree.radius_start[heads]
        np.add.at(L_k, st["stem"], st["length"])            # lengths of the drawn geometry
        R_k, L_k = base[st["stem"]], np.maximum(L_k[st["stem"]], 1e-30)
        # distance from the stem's base along the segments (the attrs' arc may be of the
        # tree before a scaling)
        arc = np.zeros(n)
        for _ in range(int(kn.sum()) + 1):
            new = np.where(st["cont"] & kn, arc[pp] + st["length"][pp], 0.0)
            if np.array_equal(new, arc):
                break
            arc = new
        prof = lambda s: R_k * np.sqrt(np.clip(1.0 - (s / L_k) ** 2, 0.0, 1.0))  # noqa: E731
        r0 = np.where(kn, np.maximum(prof(arc), min_radius), r0)
        r1 = np.where(kn, np.maximum(prof(arc + st["length"]), min_radius), r1)
    lobes = np.asarray(tree.attrs.get("lobes", np.zeros(n)), float)
    depth = np.asarray(tree.attrs.get("lobe_depth", np.zeros(n)), float)
    circ = 2 * np.pi * np.maximum(st["stem_radius"], 1e-6)

    # top ring frames (bisector of the segment and the next one of its stem)
    hasn = nxt >= 0
    nn = np.where(hasn, nxt, 0)
    t_top = _unit(np.where(hasn[:, None], dirs + dirs[nn], dirs))
    fx = st["frame_x"]
    u_top = _perp_unit(np.where(hasn[:, None], fx + fx[nn], fx), t_top)
    u_bot = _perp_unit(fx, dirs)

    child = alive & (par >= 0) & ~cont & ~st["clone"] & alive[pp] & (tree.level >= 1)
    jmask = child & smooth
    own_bottom = alive & ~cont & ~jmask
    # own bottom rings of clones and unsmoothed branches are tucked inside the parent's tube
    # (clones: moved back along the parent by its radius), so forks leave no gaps
    tp = st["attach"]
    rp_in = ((r0[pp] + tp * (r1[pp] - r0[pp])) * np.cos(np.pi / Sg[pp]) * (1 - depth[pp]))
    inner = own_bottom & (par >= 0) & alive[pp]
    bot_r = np.where(inner, np.minimum(r0, 0.9 * rp_in), r0)
    bot_c = np.where((inner & st["clone"])[:, None],
                     tree.start - dirs[pp] * np.minimum(r1[pp], ln[pp])[:, None], tree.start)
    # a knot starting on the bark: its unsmoothed tube starts on the parent's axis instead
    on_axis = tree.start[pp] + (tp * ln[pp])[:, None] * dirs[pp]
    bot_c = np.where((inner & ~st["clone"] & (tree.kind != 0))[:, None], on_axis, bot_c)

    # ---- rings: top rings, own bottom rings, junction rings ---------------------------------
    ring_S, ring_verts, ring_uv, ring_seg = [], [], [], []
    ring_count = 0
    top_id = np.full(n, -1)
    bot_id = np.full(n, -1)

    def add_rings(ids_seg, verts, uv, S):
        nonlocal ring_count
        k = len(ids_seg)
        ring_S.append(np.full(k, S))
        ring_verts.append(verts.reshape(-1, 3))
        ring_uv.append(uv.reshape(-1, 2))
        ring_seg.append(ids_seg)
        r = np.arange(ring_count, ring_count + k)
        ring_count += k
        return r

    uu = {S: np.arange(S + 1) / S for S in np.unique(Sg)}
    for S in np.unique(Sg[alive]):
        sel = np.nonzero(alive & (Sg == S))[0]
        v = _ring_vertices(tree.end[sel], t_top[sel], u_top[sel], r1[sel], S, lobes[sel],
                           depth[sel])
        vv = (st["arc"][sel] + ln[sel]) / circ[sel]
        uv = np.stack(np.broadcast_arrays(uu[S][None, :], vv[:, None]), -1)
        top_id[sel] = add_rings(sel, v, uv, S)
        sel = np.nonzero(own_bottom & (Sg == S))[0]
        if len(sel):
            v = _ring_vertices(bot_c[sel], dirs[sel], u_bot[sel], bot_r[sel], S, lobes[sel],
                               depth[sel])
            vv = st["arc"][sel] / circ[sel]
            uv = np.stack(np.broadcast_arrays(uu[S][None, :], vv[:, None]), -1)
            bot_id[sel] = add_rings(sel, v, uv, S)
    bot_id[cont & alive] = top_id[par[cont & alive]]

    # ---- junctions (paper 004 §4) ------------------------------------------------------------
    junction_D = np.zeros(n, np.int64)
    jchains = []          # (segment ids, ring ids (k, D+1)) per group
    jc = np.nonzero(jmask)[0]
    if len(jc):
        Dj = subdivisions(D_u, tree.level[jc])
        junction_D[jc] = Dj
        pj = par[jc]
        scale = (st["stem_length"][jc] * st["stem_radius"][jc]
                 / np.maximum(st["stem_length"][pj] * st["stem_radius"][pj], 1e-300))
        scale = np.clip(scale * np.where(tree.kind[jc] != 0, knot_gain, gain), 0.0, 1.0)
        groups = _junction_control(tree, st, jc, Sg, r0, r1, depth, u_bot, top_id,
                                   ring_verts, ring_S, scale)
        for sel, P, C, B, cm, N0 in groups:
            S = int(Sg[jc[sel[0]]])
            F = 0.5 * (1 + cm) * stretch + 0.5 * (1 - cm) * compress
            for D in np.unique(Dj[sel]):
                w = np.nonzero(Dj[sel] == D)[0]
                segs = jc[sel[w]]
                D = int(D)
                rings = junction_rings(P[w], C[w], B[w], D, F[w], scale[sel[w]])
                rings[:, 0] = N0[w]                  # the base ring, kept under the bark
                proj = np.sum((rings - tree.start[segs][:, None, None])
                              * dirs[segs][:, None, None], -1)
                vv = (np.maximum(proj, 0.0) / circ[segs][:, None, None]
                      + st["arc"][segs][:, None, None])
                uv = np.stack(np.broadcast_arrays(uu[S][None, None, :], vv), -1)
                ids = add_rings(np.repeat(segs, D + 1), rings, uv, S).reshape(len(segs), D + 1)
                bot_id[segs] = ids[:, 0]
                jchains.append((segs, ids))

    ring_S = np.concatenate(ring_S) if ring_S else np.zeros(0, np.int64)
    ring_seg = np.concatenate(ring_seg) if ring_seg else np.zeros(0, np.int64)
    verts = np.concatenate(ring_verts) if ring_verts else np.zeros((0, 3))
    uvs = np.concatenate(ring_uv) if ring_uv else np.zeros((0, 2))
    ring_off = np.r_[0, np.cumsum(ring_S + 1)[:-1]] if len(ring_S) else np.zeros(0, np.int64)

    # ---- faces ----------------------------------------------------------------------------
    pairs_a, pairs_b, pairs_seg = [bot_id[alive]], [top_id[alive]], [np.nonzero(alive)[0]]
    for segs, ids in jchains:   # junction: N_0 -> ... -> N_D -> first node ring
        chain = np.concatenate([ids, top_id[segs][:, None]], 1)
        pairs_a.append(chain[:, :-1].ravel())
        pairs_b.append(chain[:, 1:].ravel())
        pairs_seg.append(np.repeat(segs, chain.shape[1] - 1))
    # the unsmoothed piece of a junction segment is replaced by the chain
    pa = np.concatenate(pairs_a)
    pb = np.concatenate(pairs_b)
    ps = np.concatenate(pairs_seg)
    keep = np.ones(len(pa), bool)
    if jchains:
        nal = int(alive.sum())
        keep[:nal] = ~jmask[np.nonzero(alive)[0]]
    pa, pb, ps = pa[keep], pb[keep], ps[keep]
    faces, fseg = [], []
    for S in np.unique(ring_S[pa]) if len(pa) else []:
        sel = ring_S[pa] == S
        faces.append(_tube_faces(ring_off[pa[sel]], ring_off[pb[sel]], S))
        fseg.append(np.repeat(ps[sel], 2 * S))
    extra_v, extra_uv = [], []
    nv = len(verts)
    if caps:
        tips = np.nonzero(alive & (nxt < 0) & (r1 > 0))[0]
        roots = np.nonzero(alive & ~cont & ((par < 0) | ~alive[pp]) & (r0 > 0))[0]
        for ids, centers, flip in ((tips, tree.end, False), (roots, tree.start, True)):
            if not len(ids):
                continue
            rid = top_id[ids] if not flip else bot_id[ids]
            for S in np.unique(ring_S[rid]):
                sel = ring_S[rid] == S
                o = ring_off[rid[sel]]
                apex = nv + np.arange(sel.sum())
                nv += int(sel.sum())
                extra_v.append(centers[ids[sel]])
                extra_uv.append(np.stack([np.full(sel.sum(), 0.5), uvs[o, 1]], 1))
                k = np.arange(S)
                a_ = o[:, None] + k[None]
                b_ = o[:, None] + k[None] + 1
                c_ = np.broadcast_to(apex[:, None], a_.shape)
                f = np.stack([b_, a_, c_], -1) if flip else np.stack([a_, b_, c_], -1)
                faces.append(f.reshape(-1, 3))
                fseg.append(np.repeat(ids[sel], S))
    if extra_v:
        verts = np.concatenate([verts] + extra_v)
        uvs = np.concatenate([uvs] + extra_uv)
    faces = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    fseg = np.concatenate(fseg) if fseg else np.zeros(0, np.int64)
    vring = np.full(len(verts), -1)
    if len(ring_S):
        vring[:int(ring_off[-1] + ring_S[-1] + 1)] = np.repeat(np.arange(len(ring_S)), ring_S + 1)
    meta = {"junction_D": junction_D, "segment": fseg, "vertex_ring": vring,
            "ring_segment": ring_seg, "top_ring": top_id, "part": "bark"}
    if arrays:
        return BarkArrays(verts, faces, uvs, meta), None
    import trimesh              # here: a render does not pay for its import (arrays=True)

    bark = trimesh.Trimesh(verts, faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uvs))
    bark.metadata.update(meta)
    leaf = leaf_mesh(tree, shape=leaf_shape) if leaves else _empty_mesh()
    return bark, leaf


def _junction_control(tree, st, jc, Sg, r0, r1, depth, u_bot, top_id, ring_verts, ring_S,
                      scale):
    """Control points of the junction segments ``jc``, grouped by corner count:
    ``[(sel, P, C, B, c_m, N0), ...]`` with ``sel`` indices into ``jc``, P/C/B (k, S+1, 3),
    ``c_m`` (k, S+1) in [-1, 1] (+1: upper side, towards the parent's tip) and ``N0`` the
    ring d = 0 of eq 4.2 (with the given ``scale``) pulled under the parent's bark where the
    parent's real surface (taper, flare, bends) lies inside it."""
    par = tree.parent
    dirs, ln = st["dir"], st["length"]
    stem, arc = st["stem"], st["arc"]
    p = par[jc]
    a_c, a_p = dirs[jc], dirs[p]
    t = st["attach"][jc]
    S0 = tree.start[jc]
    O = tree.start[p] + (t * ln[p])[:, None] * a_p          # the junction on the parent axis
    rp = r0[p] + t * (r1[p] - r0[p])
    Sp = Sg[p].astype(float)
    shrink = np.cos(np.pi / Sp) * (1.0 - depth[p]) * 0.98       # under the faceted, lobed skin
    rpe = rp * shrink
    slope = (r1[p] - r0[p]) / np.maximum(ln[p], 1e-300) * shrink   # the parent is a cone
    rc = np.minimum(r0[jc], 0.95 * rpe)
    # heights on the parent's stem: its nodes and the bases of all its branches
    alive = tree.alive
    h_c = arc[p] + t * ln[p]
    ps = stem[p]
    seg_all = np.nonzero(alive)[0]
    ev_stem = np.r_[stem[seg_all], stem[seg_all], ps]
    ev_h = np.r_[arc[seg_all], arc[seg_all] + ln[seg_all], h_c]
    W = float(np.max(ev_h)) * 2 + 1.0
    uniq = np.unique(ev_stem)
    keys = np.sort(np.searchsorted(uniq, ev_stem) * W + ev_h)
    base_k = np.searchsorted(uniq, ps) * W
    kc = base_k + h_c
    eps = np.maximum(1e-4 * ln[p], 1e-9)
    iu = np.minimum(np.searchsorted(keys, kc + eps, side="right"), len(keys) - 1)
    idn = np.maximum(np.searchsorted(keys, kc - eps, side="left") - 1, 0)
    h_up = keys[iu] - base_k
    h_up = np.where((h_up > h_c) & (h_up < W), h_up, h_c)     # none above: no stretch upwards
    h_dn = keys[idn] - base_k
    h_dn = np.where((h_dn < h_c) & (h_dn >= 0), h_dn, h_c)
    # segments of each stem, sorted by height, to place P on the parent stem
    sk = np.searchsorted(uniq, stem[seg_all]) * W + arc[seg_all]
    order = np.argsort(sk)
    sk_sorted, seg_sorted = sk[order], seg_all[order]
    verts_all = np.concatenate(ring_verts)
    ring_off = np.r_[0, np.cumsum(np.concatenate(ring_S) + 1)[:-1]]
    groups = []
    for S in np.unique(Sg[jc]):
        sel = np.nonzero(Sg[jc] == S)[0]
        th = 2 * np.pi * np.arange(S + 1) / S
        u = u_bot[jc[sel]]
        v = np.cross(a_c[sel], u)
        e = np.cos(th)[None, :, None] * u[:, None] + np.sin(th)[None, :, None] * v[:, None]
        # B stays before the branch's first node and within the parent segment (a bend of the
        # parent at its nodes would leave a B beyond them outside the bark)
        a0 = np.sum(((S0[sel] - O[sel])[:, None] + rc[sel, None, None] * e) * a_p[sel, None], -1)
        ca = np.sum(a_c[sel] * a_p[sel], -1)[:, None]
        hi = (1.0 - t[sel, None]) * ln[p[sel], None] * 0.999
        lo = -t[sel, None] * ln[p[sel], None] * 0.999
        with np.errstate(divide="ignore", invalid="ignore"):
            s_node = np.where(ca > 1e-9, (hi - a0) / ca,
                              np.where(ca < -1e-9, (lo - a0) / ca, np.inf))
        s_max = np.minimum(0.8 * ln[jc[sel], None], s_node)
        B, _ = contact_points(S0[sel], O[sel], a_c[sel], a_p[sel], e, rc[sel], rpe[sel],
                              s_max, slope[sel])
        uhat = a_p[sel] - np.sum(a_p[sel] * a_c[sel], 1, keepdims=True) * a_c[sel]
        nrm = np.linalg.norm(uhat, axis=1, keepdims=True)
        uhat = np.where(nrm > 1e-9, uhat / np.maximum(nrm, 1e-300), u)
        cm = np.clip(np.sum(e * uhat[:, None], -1), -1.0, 1.0)
        hB = h_c[sel, None] + np.sum((B - O[sel, None]) * a_p[sel, None], -1)
        hP = np.where(cm >= 0, hB + cm * np.maximum(h_up[sel, None] - hB, 0.0),
                      hB + cm * np.maximum(hB - h_dn[sel, None], 0.0))
        # the parent-stem segment holding hP
        qk = base_k[sel, None] + hP
        qi = np.clip(np.searchsorted(sk_sorted, qk, side="right") - 1, 0, len(sk_sorted) - 1)
        q = seg_sorted[qi]
        q = np.where(stem[q] == ps[sel, None], q, p[sel, None])
        hq = np.clip(hP - arc[q], 0.0, ln[q])
        axis = tree.start[q] + hq[..., None] * dirs[q]
        rq = (r0[q] + hq / np.maximum(ln[q], 1e-300) * (r1[q] - r0[q])) * shrink[sel, None]
        rel = B - O[sel, None]
        rho = rel - np.sum(rel * a_p[sel, None], -1, keepdims=True) * a_p[sel, None]
        rho = _unit(rho - np.sum(rho * dirs[q], -1, keepdims=True) * dirs[q])
        P = axis + rq[..., None] * rho
        same = (np.abs(hP - hB) < 1e-12)[..., None]
        P = np.where(same, B, P)
        o = ring_off[top_id[jc[sel]]]
        C = verts_all[o[:, None] + np.arange(S + 1)[None]]
        # ring d = 0 under the parent's bark: find the parent-stem segment at its height
        N0 = B + scale[sel, None, None] * (P - B)
        hN = h_c[sel, None] + np.sum((N0 - O[sel, None]) * a_p[sel, None], -1)
        qi = np.clip(np.searchsorted(sk_sorted, base_k[sel, None] + hN, side="right") - 1, 0,
                     len(sk_sorted) - 1)
        q = seg_sorted[qi]
        q = np.where(stem[q] == ps[sel, None], q, p[sel, None])
        hq = np.clip(np.sum((N0 - tree.start[q]) * dirs[q], -1), 0.0, ln[q])
        axis = tree.start[q] + hq[..., None] * dirs[q]
        rel = N0 - axis
        rad = rel - np.sum(rel * dirs[q], -1, keepdims=True) * dirs[q]
        dist = np.linalg.norm(rad, axis=-1)
        r_in = (r0[q] + hq / np.maximum(ln[q], 1e-300) * (r1[q] - r0[q])) * shrink[sel, None]
        f = np.where(dist > r_in, r_in / np.maximum(dist, 1e-300), 1.0)
        N0 = N0 + (f - 1.0)[..., None] * rad
        groups.append((sel, P, C, B, cm, N0))
    return groups


def leaf_mesh(tree: Tree, shape: str = "oval"):
    """One polygon per leaf with UVs (u across the blade, v from petiole to tip).

    Blade length is the leaf's ``size``, its width the leaf attr ``width`` (default 0.6 x size).

    Parameters
    ----------
    tree : Tree
        The tree whose leaves are meshed.
    shape : str, optional
        ``"oval"`` (6 vertices / 4 triangles, the default) or ``"quad"`` (4 / 2).

    Returns
    -------
    trimesh.Trimesh
        The leaf mesh [m]; ``metadata["leaf"]`` gives the leaf of each face.
    """
    import trimesh

    lv = tree.leaves
    m = len(lv)
    if m == 0:
        return _empty_mesh()
    nrm = _unit(lv.normal)
    up = lv.up if lv.up is not None else np.cross(nrm, [[1.0, 0.0, 0.0]])
    up = _perp_unit(up, nrm)
    side = np.cross(nrm, up)
    length = lv.size
    width = np.asarray(lv.attrs.get("width", 0.6 * lv.size), float)
    if shape == "oval":
        outline = LEAF_OUTLINE
        tri = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    else:
        outline = np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, 0.5], [0.5, -0.5]])
        tri = np.array([[0, 1, 2], [0, 2, 3]])
    k = len(outline)
    LU = length[:, None] * up
    WS = width[:, None] * side
    verts = np.empty((m, k, 3))
    for j, (a, b) in enumerate(outline):      # k contiguous (m, 3) passes: fast
        verts[:, j] = lv.position + a * LU + b * WS
    verts = verts.reshape(-1, 3)
    faces = (tri[None] + k * np.arange(m)[:, None, None]).reshape(-1, 3)
    uv = np.tile(np.stack([outline[:, 1] + 0.5, outline[:, 0] + 0.5], 1), (m, 1))
    mesh = trimesh.Trimesh(verts, faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv))
    mesh.metadata.update({"leaf": np.repeat(np.arange(m), len(tri)), "part": "leaves"})
    return mesh


def _empty_mesh():
    import trimesh
    return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), process=False)
