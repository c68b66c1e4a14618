"""Trees and leaves for the render.

- **bark**: for Weber-Penn trees the smooth mesh with junctions (:func:`mitsuba_veg.trees.junction.
  tree_mesh`, paper 004) with its knots drawn as rounded swellings (``round_knots``), for the
  other trees (growth model, paper 001) smooth swept tubes through the branches' joints
  (:func:`mitsuba_veg.render.bark.swept_tubes`); all trees merged into one ``bark`` mesh with
  UVs and vertex normals, its textured, bump-mapped bark BSDF (:func:`mitsuba_veg.render.bark.
  bark_bsdf`).
- **leaves**: one folded, cupped blade of the tree's leaf outline per leaf
  (:mod:`mitsuba_veg.render.leaves`: 14-16 triangles, the area of the light pass's blade),
  binned by autumn logical time tau (leaf attr ``autumn_tau``, paper 003; 0 when absent) into
  ``leaf_bins`` meshes, each with the leaf BSDF of its bin's tau
  (:func:`mitsuba_veg.render.materials.leaf_bsdf`: PROSPECT-D spectra in the two-sided
  ``veg_leaf`` BSDF). Leaves with ``fallen`` set are not drawn on the tree (the litter draws
  them, :mod:`mitsuba_veg.render.litter`); an optional ``leaf_scale`` attr (0..1) shrinks
  leaves about their centre (spring leaf-out).

:func:`scenario_trees` builds the trees a scenario asks for in ``[[render.trees]]``::

    [[render.trees]]
    preset = "quaking_aspen"      # Weber-Penn preset (mitsuba_veg.trees.weber_penn.PRESETS)
    seed = 3
    position = [1.7, 0.0, -1.6]   # trunk base [m]
    height = 3.5                  # scale the tree to this height [m] (optional)
    autumn = true                 # leaves turn and fall over the run's days (default true)

``model = "growth"`` grows the tree with paper 001's model (``generations``, ``[growth]``
parameters of :class:`mitsuba_veg.trees.GrowthParams`) under an open sky. Without
:mod:`mitsuba_veg.trees.weber_penn` (or with ``model = "simple"``) a small procedural tree made
with the :class:`~mitsuba_veg.trees.Tree` constructor stands in.
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..meshes import make_mesh
from ..trees import weber_penn
from ..trees.entries import check_render_tree
from ..trees.growth import GrowthParams, grow
from ..trees.junction import tree_mesh
from ..trees.structure import Leaves, Tree, leaf_quads, scaled_tree
from . import materials as mat
from .bark import bark_bsdf, swept_tubes
from .leaves import blade_mesh, leaf_shape_of

__all__ = ["tree_geometry", "far_trees", "leaf_bin_arrays", "tree_shapes", "simple_tree",
           "make_tree", "scenario_trees"]


# ---- meshes -------------------------------------------------------------------------------------
def _smooth_normals(v, f, vring):
    """Area-weighted vertex normals; a ring's seam vertex (its last, a copy of its first) shares
    the first's normal (``vring``: the ring of each vertex, -1 for a cap's apex)."""
    p = v[f]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n = np.stack([sum(np.bincount(f[:, j], fn[:, k], len(v)) for j in range(3))
                  for k in range(3)], 1)
    vring = np.asarray(vring)
    first = np.nonzero((vring >= 0) & (np.r_[-2, vring[:-1]] != vring))[0]
    last = np.nonzero((vring >= 0) & (np.r_[vring[1:], -2] != vring))[0]
    both = n[first] + n[last]
    n[first], n[last] = both, both
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def _bark_and_leaf_geometry(tree, far: bool = False):
    """(bark (v, f, uv, normals), leaves (v, f, k vertices per leaf) or None).

    ``far``: the tree's level of detail for a distant view (:func:`far_trees`): Weber-Penn bark
    as the model's tubes and cones (no smooth junctions), each leaf the light pass's blade, a
    quad of the same area (2 triangles instead of 12-14)."""
    if getattr(tree, "weber_penn", None) is not None:
        b, _ = tree_mesh(tree, smooth=not far, leaves=False, round_knots=not far, arrays=True)
        v, f = np.asarray(b.vertices, np.float32), np.asarray(b.faces, np.int64)
        uv = np.asarray(b.uv, np.float32)
        bark = (v, f, uv, _smooth_normals(v, f, b.metadata["vertex_ring"]))
    else:
        bark = swept_tubes(tree)
    leaves = None
    if len(tree.leaves):
        lv = tree.leaves
        if far:
            v, f = leaf_quads(lv)
            v, f = v.astype(np.float32), f.astype(np.uint32)
        else:
            v, f = blade_mesh(lv.position, lv.normal, lv.up, lv.size, leaf_shape_of(tree))
        leaves = (v, f, len(v) // len(lv))
    return bark, leaves


def _geometry(t, cache, far: bool = False):
    """(bark, leaves) of one tree (:func:`_bark_and_leaf_geometry`), from the cache."""
    key = (id(t), bool(far))
    if cache is not None and key in cache and cache[key][0] is t:
        return cache[key][1], cache[key][2]
    bark, leaves = _bark_and_leaf_geometry(t, far)
    if cache is not None:
        # the tree itself is kept in the entry: while the cache lives, its id cannot be
        # reused by another object
        cache[key] = (t, bark, leaves)
    return bark, leaves


def far_trees(trees, camera: dict | None, width: int, pixels: float) -> np.ndarray:
    """Which trees a view sees so small that they are drawn at their distant level of detail.

    A tree is far when its median leaf, seen from the camera at the distance of the tree's leaf
    centroid, spans fewer than ``pixels`` pixels (its blade's side sqrt(0.6) size x the focal
    length in pixels / the distance): its leaves are then quads of the same area and its
    Weber-Penn bark the model's tubes, which cuts a hectare's triangles about five-fold where no
    pixel can tell.

    Parameters
    ----------
    trees : list of Tree
        The trees.
    camera : dict or None
        The camera preset (``origin`` [m], ``fov`` [degrees], ``fov_axis``); None: no tree is
        far.
    width : int
        Image width [px] (the field of view is taken along it).
    pixels : float
        Threshold [px]; 0 draws every tree in full.

    Returns
    -------
    numpy.ndarray
        (len(trees),) bool.
    """
    far = np.zeros(len(trees), bool)
    if camera is None or pixels <= 0 or not trees:
        return far
    o = np.asarray(camera["origin"], float)
    focal = 0.5 * float(width) / np.tan(np.radians(float(camera.get("fov", 45.0))) / 2.0)
    for i, t in enumerate(trees):
        if len(t.leaves) == 0:
            continue
        c = np.asarray(t.leaves.position, float).mean(0)
        d = max(float(np.linalg.norm(c - o)), 1e-6)
        side = np.sqrt(0.6) * float(np.median(t.leaves.size))
        far[i] = side * focal / d < pixels
    return far


def _leaf_state(t):
    """Per leaf: tau [-], drawn (not fallen, leaf-out size > 1e-3), leaf-out size [-]."""
    m, attrs = len(t.leaves), t.leaves.attrs
    tau = np.asarray(attrs.get("autumn_tau", np.zeros(m)), float)
    scale = np.asarray(attrs.get("leaf_scale", np.ones(m)), float)
    keep = ~np.asarray(attrs.get("fallen", np.zeros(m, bool)), bool) & (scale > 1e-3)
    return tau, keep, scale


def tree_geometry(trees, cache=None, far=None):
    """Merged bark and per-leaf geometry of several trees (cached per tree object id).

    Parameters
    ----------
    trees : list of Tree
        The trees; leaves may carry ``autumn_tau``, ``fallen`` and ``leaf_scale`` attrs.
    cache : dict, optional
        ``{(id(tree), far): (tree, bark, leaves)}``, filled on first use and reused (the geometry
        of a tree object is assumed not to change).
    far : array_like of bool, optional
        Trees drawn at their distant level of detail (:func:`far_trees`); default none.

    Returns
    -------
    bark : tuple of numpy.ndarray or None
        ``(vertices (v, 3) [m], faces (f, 3), uv (v, 2), normals (v, 3))`` of all trees, None
        without trees.
    leaves : dict or None
        ``v`` vertices [m] (float32), ``f`` faces, ``vleaf`` leaf index per vertex (int32; a
        leaf's vertices and faces are consecutive), and per leaf ``tau`` (autumn logical time
        [-], 0 when absent), ``keep`` (drawn: not fallen, leaf-out size > 1e-3), ``scale``
        (leaf-out size factor [-], 1 when absent) and ``centre`` (position [m]); None without
        leaves.
    """
    bark_parts, lv, lf, vleaf, ltau, lkeep, lscale, lcentre = ([] for _ in range(8))
    nb = nl = nleaf = 0
    far = np.zeros(len(trees), bool) if far is None else np.asarray(far, bool)
    for t, ft in zip(trees, far):
        bark, leaves = _geometry(t, cache, ft)
        bark_parts.append((bark[0], bark[1] + nb, bark[2], bark[3]))
        nb += len(bark[0])
        if leaves is not None:
            m = len(t.leaves)
            v, f, k = leaves
            tau, keep, scale = _leaf_state(t)
            lv.append(v)
            lf.append(f + np.uint32(nl))
            vleaf.append((np.arange(m, dtype=np.int32) + nleaf).repeat(k))
            ltau.append(tau)
            lkeep.append(keep)
            lscale.append(scale)
            lcentre.append(np.asarray(t.leaves.position, float))
            nl += len(v)
            nleaf += m
    bark = tuple(np.concatenate([p[j] for p in bark_parts]) for j in range(4)) \
        if bark_parts else None
    if not lv:
        return bark, None
    return bark, {"v": np.concatenate(lv), "f": np.concatenate(lf),
                  "vleaf": np.concatenate(vleaf), "tau": np.concatenate(ltau),
                  "keep": np.concatenate(lkeep), "scale": np.concatenate(lscale),
                  "centre": np.concatenate(lcentre)}


_EMPTY_V = np.full((3, 3), -1e4, np.float32)
_EMPTY_F = np.array([[0, 1, 2]], np.uint32)


def leaf_bin_arrays(trees, options, cache=None, far=None) -> dict:
    """The leaves binned by autumn logical time, one mesh per bin.

    Leaf-out scales each leaf about its centre; fallen leaves and leaves with ``leaf_scale``
    <= 1e-3 are left out. An empty bin is one degenerate triangle far away, so that the scene keeps
    its structure. Built tree by tree (the selected leaves' copies only: a hectare's millions of
    leaves are not concatenated first).

    Parameters
    ----------
    trees : list of Tree
        The trees.
    options : RenderOptions
        Gives ``leaf_bins``, the number of bins over tau in [0, 1].
    cache : dict, optional
        Geometry cache of :func:`tree_geometry`.
    far : array_like of bool, optional
        Trees drawn at their distant level of detail (:func:`far_trees`); default none.

    Returns
    -------
    dict
        ``{"leaves_KK": (vertices (v, 3) float32 [m], faces (f, 3) uint32)}`` for all
        ``options.leaf_bins`` bins.
    """
    K = int(options.leaf_bins)
    parts = {b: [] for b in range(K)}
    far = np.zeros(len(trees), bool) if far is None else np.asarray(far, bool)
    for t, ft in zip(trees, far):
        leaves = _geometry(t, cache, ft)[1]
        if leaves is None:
            continue
        v, f, k = leaves
        m = len(t.leaves)
        nt = len(f) // m
        tau, keep, scale = _leaf_state(t)
        bins = np.where(keep, np.minimum((np.clip(tau, 0, 1) * K).astype(np.int64), K - 1), -1)
        V = v.reshape(m, k, 3)
        F0 = f[:nt].astype(np.uint32)                   # leaf 0's faces: local indices
        for b in np.unique(bins[bins >= 0]):
            sel = np.nonzero(bins == b)[0]
            vb = V[sel]
            s = scale[sel]
            if np.any(s != 1.0):                        # leaf-out: about the leaf's centre
                c = t.leaves.position[sel].astype(np.float32)[:, None, :]
                vb = c + s.astype(np.float32)[:, None, None] * (vb - c)
            parts[int(b)].append((vb.reshape(-1, 3), F0, k, len(sel)))
    out = {}
    for b in range(K):
        if not parts[b]:
            out[f"leaves_{b:02d}"] = (_EMPTY_V, _EMPTY_F)
            continue
        n = sum(len(p[0]) for p in parts[b])
        verts = np.empty((n, 3), np.float32)
        faces = np.empty((sum(len(p[1]) * p[3] for p in parts[b]), 3), np.uint32)
        o = of = 0
        for vb, F0, k, cnt in parts[b]:
            verts[o:o + len(vb)] = vb
            fb = faces[of:of + len(F0) * cnt].reshape(cnt, len(F0), 3)
            fb[:] = F0[None]
            fb += (np.uint32(o) + k * np.arange(cnt, dtype=np.uint32))[:, None, None]
            o += len(vb)
            of += len(F0) * cnt
        parts[b] = None
        out[f"leaves_{b:02d}"] = (verts, faces)
    return out


def tree_shapes(trees, options, cache=None, far=None) -> tuple[dict, dict]:
    """Mitsuba meshes (bark + one leaf mesh per autumn bin) and counts.

    The bark is one mesh with the textured, bump-mapped bark BSDF
    (:func:`mitsuba_veg.render.bark.bark_bsdf`); leaf bin k of K gets the leaf BSDF of
    tau = (k + 0.5) / K (:func:`mitsuba_veg.render.materials.leaf_bsdf`).

    Parameters
    ----------
    trees : list of Tree
        The trees.
    options : RenderOptions
        Gives ``leaf_bins``.
    cache : dict, optional
        Geometry cache of :func:`tree_geometry`.
    far : array_like of bool, optional
        Trees drawn at their distant level of detail (:func:`far_trees`); default none.

    Returns
    -------
    shapes : dict
        ``{id: mesh}`` for ``mi.load_dict``.
    info : dict
        ``trees``, ``far_trees``, ``leaves`` (drawn) and ``tree_triangles`` counts.
    """
    out = {}
    far = np.zeros(len(trees), bool) if far is None else np.asarray(far, bool)
    info = {"trees": len(trees), "far_trees": int(far.sum()), "leaves": 0, "tree_triangles": 0}
    parts = [_geometry(t, cache, ft)[0] for t, ft in zip(trees, far)]
    if parts:
        bark, n = [], 0
        for p in parts:
            bark.append((p[0], p[1] + n, p[2], p[3]))
            n += len(p[0])
        bark = [np.concatenate([p[j] for p in bark]) for j in range(4)]
        if len(bark[1]):
            out["bark"] = make_mesh("bark", bark[0], bark[1], bark_bsdf(), uv=bark[2],
                                    normals=bark[3])
            info["tree_triangles"] += len(bark[1])
        del bark
    info["leaves"] = int(sum(_leaf_state(t)[1].sum() for t in trees if len(t.leaves)))
    K = int(options.leaf_bins)
    for sid, (v, f) in leaf_bin_arrays(trees, options, cache, far).items():
        b = int(sid.split("_")[1])
        out[sid] = make_mesh(sid, v, f, mat.leaf_bsdf((b + 0.5) / K if K > 1 else 0.0))
        if f is not _EMPTY_F:
            info["tree_triangles"] += len(f)
    return out, info


# ---- trees of a scenario ------------------------------------------------------------------------
def simple_tree(height: float = 3.0, seed: int = 0, leaves_per_twig: int = 12):
    """A small deciduous tree made directly with the Tree constructor (no growth model).

    Trunk, 3 levels of branches, leaves on the last level; sizes scale with ``height``.

    Parameters
    ----------
    height : float, optional
        Nominal tree height [m] (default 3; the trunk is 0.45 of it).
    seed : int, optional
        Random seed (default 0).
    leaves_per_twig : int, optional
        Leaves per last-level branch (default 12).

    Returns
    -------
    Tree
        The tree, trunk base at the origin, named ``"simple"``.
    """
    rng = np.random.default_rng(seed)
    start, end, r0, r1, parent, level = [], [], [], [], [], []

    def add(p0, p1, ra, rb, par, lv):
        start.append(p0)
        end.append(p1)
        r0.append(ra)
        r1.append(rb)
        parent.append(par)
        level.append(lv)
        return len(start) - 1

    trunk_h = 0.45 * height
    n_seg = 4
    prev = -1
    base = np.zeros(3)
    tips = []
    for i in range(n_seg):
        top = base + np.array([rng.normal(0, 0.02), trunk_h / n_seg, rng.normal(0, 0.02)])
        rad = 0.045 * height / 3.0 * (1 - 0.5 * i / n_seg)
        prev = add(base, top, rad, rad * 0.9, prev, 0)
        base = top
    stems = [(prev, base, np.array([0.0, 1.0, 0.0]), 0.55 * height, 0.02 * height / 3.0)]
    for lv in range(1, 4):
        new = []
        for par, p, d, length, rad in stems:
            k = 5 if lv == 1 else 3
            for j in range(k):
                phi = 2.4 * j + rng.random()
                tilt = np.radians(35 + 20 * rng.random()) if lv > 1 else np.radians(40 + 25 * j / k)
                u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 0.0, 1.0])
                u /= np.linalg.norm(u)
                w = np.cross(d, u)
                nd = np.cos(tilt) * d + np.sin(tilt) * (np.cos(phi) * u + np.sin(phi) * w)
                nd += np.array([0, 0.25, 0])
                nd /= np.linalg.norm(nd)
                L = length * (0.55 + 0.2 * rng.random())
                q = p + L * nd
                idx = add(p, q, rad, rad * 0.6, par, lv)
                new.append((idx, q, nd, L, rad * 0.6))
        stems = new
        tips = new
    # leaves around the last-level stems
    pos, nrm, size, seg, up = [], [], [], [], []
    for idx, q, d, L, _ in tips:
        p0 = np.asarray(start[idx])
        for j in range(leaves_per_twig):
            t = rng.random()
            c = p0 + t * (q - p0) + rng.normal(0, 0.06 * height / 3.0, 3)
            n = rng.normal(0, 1, 3) + np.array([0, 1.5, 0])
            n /= np.linalg.norm(n)
            a = rng.normal(0, 1, 3)
            a -= a.dot(n) * n
            a /= np.linalg.norm(a)
            pos.append(c)
            nrm.append(n)
            up.append(a)
            size.append(0.07 * height / 3.0 * (0.8 + 0.4 * rng.random()))
            seg.append(idx)
    leaves = Leaves(np.array(pos), np.array(nrm), np.array(size), np.array(seg), np.array(up))
    return Tree(np.array(start), np.array(end), np.array(r0), np.array(r1), np.array(parent),
                np.array(level), leaves=leaves, name="simple")


def make_tree(cfg: dict, source: str | None = None):
    """One tree from a ``[[render.trees]]`` entry (module docstring).

    Parameters
    ----------
    cfg : dict
        The entry: ``preset``, ``model`` (``"weber_penn"`` (default), ``"growth"`` or
        ``"simple"``), ``seed``, ``position`` (trunk base [m]), ``height`` [m] (0.05-200),
        ``autumn``, ``overrides`` (Weber-Penn parameters), ``generations`` and ``growth``
        (:class:`~mitsuba_veg.trees.GrowthParams` fields).
    source : str, optional
        Where the entry comes from (the scenario path), for error messages.

    Returns
    -------
    Tree
        The tree, scaled to ``height`` (when given) about its base and moved so that its base is
        at ``position``.

    Raises
    ------
    ParameterError
        On an unknown field, a malformed position, a height out of range or an unknown model.
    """
    check_render_tree(cfg, source)    # fields, model, preset, overrides, growth fields
    pos = cfg.get("position", [0.0, 0.0, 0.0])
    if not (isinstance(pos, list) and len(pos) == 3):
        raise ParameterError("render.trees.position", pos, "[x, y, z] in metres", None, source)
    seed = int(cfg.get("seed", 0))
    height = cfg.get("height")
    if height is not None and not (isinstance(height, (int, float)) and 0.05 <= height <= 200):
        raise ParameterError("render.trees.height", height, "[0.05, 200] metres", None, source)
    model = cfg.get("model", "weber_penn")
    tree = None
    if model == "weber_penn":
        tree = weber_penn.generate(cfg.get("preset", "quaking_aspen"), seed=seed,
                                   overrides=cfg.get("overrides"))
    elif model == "growth":   # paper 001's light-driven growth model (open sky)
        params = GrowthParams(**(cfg.get("growth") or {}))
        tree = grow(params, generations=int(cfg.get("generations", 8)), seed=seed)
    elif model != "simple":
        raise ParameterError("render.trees.model", model, "'weber_penn', 'growth' or 'simple'",
                             None, source)
    if tree is None:
        tree = simple_tree(float(height or 3.0), seed)
    h = tree.metrics()["height"]
    f = float(height) / h if height and h > 0 else 1.0
    base = tree.start[0] if len(tree) else np.zeros(3)
    return scaled_tree(tree, f, np.asarray(pos, float) - base)


def scenario_trees(scn) -> list:
    """The trees of ``[[render.trees]]`` (empty list when there are none).

    Parameters
    ----------
    scn : Scenario
        The scenario.

    Returns
    -------
    list of Tree
        One tree per entry (:func:`make_tree`).
    """
    cfgs = scn.get("render.trees", []) or []
    if isinstance(cfgs, dict):
        cfgs = [cfgs]
    return [make_tree(c, str(scn.path)) for c in cfgs]
