"""Non-growth model of environmental effects on trees (paper 002, Noma).

Instead of simulating growth, user-placed sample trees are deformed into the shape their light
environment would give them, by rules applied to the finished trees:

- **Light**: voxel space (:mod:`mitsuba_veg.trees.voxel`): every branch tip carries a leaf that
  adds shading to its voxel, obstacles are opaque voxels, light at a point = 36 sky rays
  attenuated voxel by voxel (vectorised 3D-DDA).
- **Branch death** (§5.1): for every subtree, T/N < threshold → the subtree dies, with T the
  total light at its tips and N its number of tips (``death_count="tips"``: T/N is the mean
  light of the subtree's leaves, comparable between a twig and a whole tree) or, as printed,
  its number of branches (``death_count="branches"``; see docs/deviations.md).
- **Heliotropism** (§5.2): for every branch, root first, its whole subtree is rotated about the
  branch's base: (1a) brightness gradient at each tip of the subtree by finite differences on
  the voxel lattice, (1b) times the tip's distance from the rotation centre, (2) averaged over
  the tips, (3) projected onto the plane perpendicular to the branch, (4) rotated about the axis
  perpendicular to the branch and that vector, by ``constant x sqrt(L / N)`` (L the vector's
  length, N the subtree's tip count; capped at ``max_angle``).

Rules run in the order given; the light is re-evaluated before each rule (dead subtrees no
longer shade). The gradient field of one rule is computed once, from the trees as they enter
the rule; the root-first rotations then sample it at the moved tips (see docs/deviations.md).
All trees of the stand are processed together, level by level, with NumPy.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .environment import Environment
from .structure import Tree, segment_depth
from .voxel import VoxelSpace, gradient_sampler

__all__ = ["RULES", "DeformResult", "TIP_SHADING", "deform", "death_by_leaf_light"]

#: the deformation rules of paper 002
RULES = ("death", "heliotropism")


@dataclass
class DeformResult:
    """What :func:`deform` did: trees, per-rule statistics and timings."""

    trees: object                 # the deformed Tree, or list of Trees, as deform was given
    stats: list = field(default_factory=list)
    seconds: float = 0.0


class _Stand:
    """All trees' segments in one parents-first array set (views back into the trees)."""

    def __init__(self, trees):
        self.trees = trees
        self.off = np.concatenate([[0], np.cumsum([len(t) for t in trees])])
        self.parent = np.concatenate([np.where(t.parent >= 0, t.parent + o, -1)
                                      for t, o in zip(trees, self.off[:-1])])
        self.start = np.concatenate([t.start for t in trees])
        self.end = np.concatenate([t.end for t in trees])
        self.alive = np.concatenate([t.alive for t in trees])
        self.tree_of = np.repeat(np.arange(len(trees)), np.diff(self.off))
        self.depth = segment_depth(self.parent)
        # attachments: leaves (position, normal, up) and leaf-sphere centres, by global segment
        self.leaf_off = np.concatenate([[0], np.cumsum([len(t.leaves) for t in trees])])
        self.leaf_seg = np.concatenate([t.leaves.segment + o for t, o in
                                        zip(trees, self.off[:-1])]).astype(np.int64)
        self.leaf_pos = np.concatenate([t.leaves.position for t in trees]).reshape(-1, 3)
        self.leaf_nrm = np.concatenate([t.leaves.normal for t in trees]).reshape(-1, 3)
        self.leaf_up = np.concatenate([t.leaves.up if t.leaves.up is not None
                                       else np.zeros((len(t.leaves), 3)) for t in trees])
        self.leaf_up = self.leaf_up.reshape(-1, 3)
        sph = [(np.asarray(t.attrs.get("leaf_sphere_center", np.zeros((0, 3))), float)
                .reshape(-1, 3), np.asarray(t.attrs.get("leaf_sphere_segment", np.zeros(0)),
                                             np.int64)) for t in trees]
        ok = [len(c) == len(sg) for c, sg in sph]
        sph = [(c, sg) if k else (np.zeros((0, 3)), np.zeros(0, np.int64))
               for (c, sg), k in zip(sph, ok)]
        self.sph_off = np.concatenate([[0], np.cumsum([len(c) for c, _ in sph])])
        self.sph_pos = np.concatenate([c for c, _ in sph]).reshape(-1, 3)
        self.sph_seg = np.concatenate([sg + o for (_, sg), o in zip(sph, self.off[:-1])]) \
            .astype(np.int64)
        self.moved = False

    def rotate_attachments(self, seg_rot, pivots, axes, angles):
        """Rotate leaves and leaf-sphere centres whose segment has rotation ``seg_rot[seg]``
        (index into pivots/axes/angles, -1: none)."""
        for seg, pts, vecs in ((self.leaf_seg, self.leaf_pos, (self.leaf_nrm, self.leaf_up)),
                               (self.sph_seg, self.sph_pos, ())):
            if not len(seg):
                continue
            j = seg_rot[seg]
            m = j >= 0
            if not m.any():
                continue
            k = j[m]
            pts[m] = _rotate_about(pts[m], pivots[k], axes[k], angles[k])
            for v in vecs:
                v[m] = _rotate_about(v[m], 0.0 * pivots[k], axes[k], angles[k])
        self.moved = True

    def tips(self):
        has = np.zeros(len(self.parent), bool)
        par = self.parent[self.alive & (self.parent >= 0)]
        has[par] = True
        return np.nonzero(self.alive & ~has)[0]

    def unit_start(self, alive=None):
        """Segments that start a branch unit (node to node): roots and children of a segment
        with two or more live children. A chain of single-child segments (a curved Weber-Penn
        stem between two branchings) is one branch; in binary trees every segment is one."""
        alive = self.alive if alive is None else alive
        nkids = np.zeros(len(self.parent), np.int64)
        m = alive & (self.parent >= 0)
        np.add.at(nkids, self.parent[m], 1)
        return (self.parent < 0) | (nkids[np.maximum(self.parent, 0)] >= 2)

    def ancestor_at(self, level):
        """Ancestor of every segment at depth ``level`` (-1 where depth < level)."""
        a = np.arange(len(self.parent))
        a = np.where(self.depth >= level, a, -1)
        for _ in range(int(self.depth.max()) - level if len(a) else 0):
            deeper = (a >= 0) & (self.depth[np.maximum(a, 0)] > level)
            a[deeper] = self.parent[a[deeper]]
        return a

    def write_back(self):
        for i, (t, o, e) in enumerate(zip(self.trees, self.off[:-1], self.off[1:])):
            t.start = self.start[o:e].copy()
            t.end = self.end[o:e].copy()
            t.alive = self.alive[o:e].copy()
            if self.moved:
                a, b = self.leaf_off[i], self.leaf_off[i + 1]
                if b > a:
                    t.leaves.position = self.leaf_pos[a:b].copy()
                    t.leaves.normal = self.leaf_nrm[a:b].copy()
                    if t.leaves.up is not None:
                        t.leaves.up = self.leaf_up[a:b].copy()
                a, b = self.sph_off[i], self.sph_off[i + 1]
                if b > a:
                    t.attrs["leaf_sphere_center"] = self.sph_pos[a:b].copy()


#: shading of one tip leaf per voxel when ``shading="auto"`` and ``shade_from="tips"``
TIP_SHADING = 0.3


def _leaf_points(stand, shade_from, shading, size):
    """Shading points and their shading: tips (paper) or leaf blades (area-based)."""
    tips = stand.tips()
    auto = isinstance(shading, str)
    if shade_from == "tips":
        return stand.end[tips], (TIP_SHADING if auto else shading), tips
    pts, sh = [], []
    for t, o in zip(stand.trees, stand.off[:-1]):
        if len(t.leaves):
            ok = stand.alive[o + t.leaves.segment]
            pts.append(t.leaves.position[ok])
            # a blade (length l, width 0.6 l as drawn) of random orientation blocks on average
            # half its area of a voxel face
            area = 0.6 * t.leaves.size[ok] ** 2
            sh.append(np.minimum(0.5 * area / size ** 2, 0.99) if auto else
                      np.full(ok.sum(), float(shading)))
    if not pts:
        return stand.end[tips], (TIP_SHADING if auto else shading), tips
    return np.concatenate(pts), np.concatenate(sh), tips


def deform(trees, obstacles=None, rules=("death", "heliotropism"), voxel_size: float = 0.5,
           shading="auto", death_threshold: float = 0.5, helio_constant: float = 1.0,
           max_angle: float = 30.0, shade_from: str = "tips", iterations: int = 1,
           death_order: str = "bottom_up", death_count: str = "tips",
           copy: bool = True) -> DeformResult:
    """Deform placed sample ``trees`` (a Tree or a list) by the rules of paper 002.

    Rules run in the order given, ``iterations`` times; the light is re-evaluated before each
    rule (see the module docstring). Leaves on dead segments are dropped at the end.

    Parameters
    ----------
    trees : Tree or list of Tree
        The placed sample trees (positions [m]).
    obstacles : optional
        None (the default) or anything :meth:`Environment.coerce` takes; obstacles are opaque
        voxels.
    rules : str or sequence of str, optional
        Rules to apply, from ``RULES`` (default ("death", "heliotropism")).
    voxel_size : float, optional
        Voxel side [m] (default 0.5).
    shading : float or str, optional
        Fraction [-] of the light crossing its voxel (along a voxel edge) that one tip / leaf
        removes, in [0, 1), or "auto" (the default): 0.3 per tip (``shade_from="tips"``, the
        paper's fixed amount), half the blade area over the voxel face area per leaf
        (``"leaves"``).
    death_threshold : float, optional
        T/N below which a subtree dies [light units, open sky = 1] (default 0.5). With N = tips
        it is the subtree's mean leaf light (0.5 = half the open sky; the paper's 0.25 with N =
        branches is about the same, since a binary subtree has 2 x tips - 1 branches).
    helio_constant : float, optional
        The constant of the rotation angle constant x sqrt(L/N) [rad] (default 1).
    max_angle : float, optional
        Cap of one rotation [deg] (default 30), in [0, 180].
    shade_from : str, optional
        "tips" (the paper, the default) or "leaves" (a tree's leaf blades, e.g. Weber-Penn
        trees).
    iterations : int, optional
        How often the whole rule list is applied (default 1).
    death_order : str, optional
        "bottom_up" (the default: deepest subtrees first, T and N over what is still alive) or
        "simultaneous" (every subtree judged on the intact tree).
    death_count : str, optional
        N of T/N: "tips" (the default: the subtree's live tips, T/N is their mean light) or
        "branches" (its branches, as printed; a whole tree's T/N is then about half its mean tip
        light, so trees die whole).
    copy : bool, optional
        Work on copies of the input trees (default True); False deforms them in place.

    Returns
    -------
    DeformResult
        The deformed trees (one Tree when a single Tree was given, else a list), per-rule
        statistics (``rule``, ``iteration``, ``voxels``, ``voxel_shape``, ``seconds`` [s], ...)
        and the total time [s].

    Raises
    ------
    ParameterError
        For no tree or a non-Tree item, an unknown rule, option value or a parameter out of
        range.
    """
    t0 = time.perf_counter()
    single = isinstance(trees, Tree)
    trees = [trees] if single else list(trees)
    if not trees:
        raise ParameterError("trees", trees, "one or more Tree objects")
    for t in trees:
        if not isinstance(t, Tree):
            raise ParameterError("trees", type(t).__name__, "Tree objects "
                                 "(mitsuba_veg.trees.Tree)")
    rules = (rules,) if isinstance(rules, str) else tuple(rules)
    for r in rules:
        if r not in RULES:
            raise ParameterError("rules", r, f"names from {RULES}")
    check_range("death_threshold", death_threshold, 0.0, None)
    if isinstance(shading, str) and shading != "auto":
        raise ParameterError("shading", shading, "'auto' or a fraction in [0, 1)")
    check_range("helio_constant", helio_constant, 0.0, None)
    check_range("max_angle", max_angle, 0.0, 180.0)
    if death_order not in ("bottom_up", "simultaneous"):
        raise ParameterError("death_order", death_order, "'bottom_up' or 'simultaneous'")
    if death_count not in ("tips", "branches"):
        raise ParameterError("death_count", death_count, "'tips' or 'branches'")
    if shade_from not in ("tips", "leaves"):
        raise ParameterError("shade_from", shade_from, "'tips' or 'leaves'")
    env = Environment.coerce(obstacles)
    if copy:
        trees = [t.copy() for t in trees]
    stats = []
    for it in range(int(iterations)):
        for rule in rules:
            t1 = time.perf_counter()
            stand = _Stand(trees)
            pts, sh, tips = _leaf_points(stand, shade_from, shading, voxel_size)
            bounds = (np.minimum(stand.start.min(0), stand.end.min(0)),
                      np.maximum(stand.start.max(0), stand.end.max(0)))
            vs = _voxels(pts, voxel_size, sh, env, bounds)
            if rule == "death":
                st = _death(stand, vs, tips, death_threshold, death_order, death_count)
            else:
                st = _heliotropism(stand, vs, helio_constant, math.radians(max_angle))
            stand.write_back()
            st.update({"rule": rule, "iteration": it, "voxels": vs.stats["voxels"],
                       "voxel_shape": list(vs.shape), "seconds": time.perf_counter() - t1})
            stats.append(st)
    for t in trees:
        t.drop_dead_leaves()
    return DeformResult(trees[0] if single else trees, stats, time.perf_counter() - t0)


def _voxels(pts, size, shading, env, bounds):
    return VoxelSpace.build(pts, size, shading, env, bounds)


def _death(stand, vs, tips, threshold, order="bottom_up", count="tips"):
    light = vs.light(stand.end[tips])
    n = len(stand.parent)
    tip_light = np.zeros(n)
    tip_light[tips] = light
    before = stand.alive.copy()
    if count == "tips":
        units = np.zeros(n)
        units[tips] = 1.0                 # N = the subtree's tips (its leaves)
    else:
        units = stand.unit_start(before).astype(float)  # branches as the rule starts
    died = _death_rule(stand, tip_light, units, threshold, order)
    per_tree = np.bincount(stand.tree_of[died], minlength=len(stand.trees))
    return {"tips": int(len(tips)), "tip_light_mean": float(light.mean()) if len(light) else 0.0,
            "died": int(died.sum()), "died_per_tree": per_tree.tolist(), "order": order,
            "count": count,
            "rays": vs.stats.get("rays", 0), "dda_steps": vs.stats.get("dda_steps", 0),
            "light_s": vs.stats.get("light_s", 0.0)}


def _death_rule(stand, light, units, threshold, order="bottom_up"):
    """Paper 002's branch death on ``stand`` (§5.1): a subtree dies where T < threshold x N,
    T the sum of ``light`` and N the sum of ``units`` over its live segments (N = 0: nothing
    left to carry it, it dies). Sets ``stand.alive``; returns the segments that died."""
    n = len(stand.parent)
    before = stand.alive.copy()
    alive = stand.alive.copy()
    if order == "simultaneous":
        T = _subtree_sum(stand, light, alive)
        N = _subtree_sum(stand, units * alive, alive)
        alive &= ~((T < threshold * N) | (N == 0))
    else:
        # deepest subtrees first; a subtree's T and N count only what is still alive
        for d in range(int(stand.depth.max()) if n else -1, -1, -1):
            T = _subtree_sum(stand, light * alive, alive)
            N = _subtree_sum(stand, units * alive, alive)
            idx = np.nonzero((stand.depth == d) & alive)[0]
            alive[idx[(T[idx] < threshold * N[idx]) | (N[idx] == 0)]] = False
    # a dead subtree root kills its descendants (parents first, level by level)
    for d in range(1, int(stand.depth.max()) + 1 if n else 0):
        idx = np.nonzero(stand.depth == d)[0]
        alive[idx] &= alive[stand.parent[idx]]
    stand.alive = alive
    return before & ~alive


def death_by_leaf_light(trees, leaf_light, threshold: float = 0.5,
                        order: str = "bottom_up") -> DeformResult:
    """Paper 002's branch-death rule (§5.1) with a light given per leaf instead of the voxel
    space: a tree that knows the light each of its leaves received (the world's daily photon
    passes over a year) drops the subtrees whose leaves got too little.

    Each leaf is a tip carrying a leaf (the paper's unit): for every subtree T is the sum of
    its live leaves' light and N their number, so T/N is their mean light; it dies where
    T/N < ``threshold`` or where no live leaf is left on it (N = 0), deepest subtrees first
    (``order="bottom_up"``) or all judged on the intact trees (``"simultaneous"``). A tree
    whose whole crown falls below the threshold dies whole: it leaves its place empty.

    Parameters
    ----------
    trees : Tree or list of Tree
        The trees (copies are changed, not these).
    leaf_light : array_like or list of array_like
        Per tree, one value per leaf (in ``tree.leaves`` order) [-]: relative to the open
        (1 = the open's light).
    threshold : float
        T/N below which a subtree dies [-], >= 0.
    order : str
        ``"bottom_up"`` (default) or ``"simultaneous"``.

    Returns
    -------
    DeformResult
        The trees without their dead subtrees and those subtrees' leaves (one Tree when one was
        given), and one statistics row (``rule`` "death", ``died`` segments, ``died_per_tree``,
        ``leaf_light_mean``, ``seconds``).

    Raises
    ------
    ParameterError
        For a leaf-light array whose length is not the tree's leaves, a negative threshold or
        an unknown order.
    """
    t0 = time.perf_counter()
    single = isinstance(trees, Tree)
    trees = [trees] if single else list(trees)
    lights = [leaf_light] if single else list(leaf_light)
    check_range("threshold", threshold, 0.0, None)
    if order not in ("bottom_up", "simultaneous"):
        raise ParameterError("order", order, "'bottom_up' or 'simultaneous'")
    if len(lights) != len(trees):
        raise ParameterError("leaf_light", f"{len(lights)} arrays", f"one per tree "
                             f"({len(trees)})")
    for i, (t, x) in enumerate(zip(trees, lights)):
        if np.shape(x) != (len(t.leaves),):
            raise ParameterError(f"leaf_light[{i}]", f"shape {np.shape(x)}",
                                 f"({len(t.leaves)},): one value per leaf of the tree")
    trees = [t.copy() for t in trees]     # (a Weber-Penn tree stays one: Tree.copy)
    stand = _Stand(trees)
    n = len(stand.parent)
    x = np.concatenate([np.asarray(v, float) for v in lights]) if n else np.zeros(0)
    light = np.bincount(stand.leaf_seg, weights=x, minlength=n)
    units = np.bincount(stand.leaf_seg, minlength=n).astype(float)
    died = _death_rule(stand, light, units, float(threshold), order)
    stand.moved = False
    stand.write_back()
    for t in trees:
        t.drop_dead_leaves()
    st = {"rule": "death", "died": int(died.sum()),
          "died_per_tree": np.bincount(stand.tree_of[died], minlength=len(trees)).tolist(),
          "leaf_light_mean": float(x.mean()) if len(x) else 0.0,
          "seconds": time.perf_counter() - t0}
    return DeformResult(trees[0] if single else trees, [st], time.perf_counter() - t0)


def _subtree_sum(stand, values, alive):
    acc = np.array(values, float)
    for d in range(int(stand.depth.max()) if len(acc) else 0, 0, -1):
        idx = np.nonzero((stand.depth == d) & alive)[0]
        np.add.at(acc, stand.parent[idx], acc[idx])
    return acc


def _rotate_about(p, pivot, axis, angle):
    v = p - pivot
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    v = v * c + np.cross(axis, v) * s + axis * (axis * v).sum(1, keepdims=True) * (1 - c)
    return pivot + v


def _heliotropism(stand, vs, constant, max_angle):
    field = vs.light_field()
    grad = gradient_sampler(field, vs.origin, vs.size)
    n = len(stand.parent)
    rotated = 0
    angles = []
    for level in range(int(stand.depth.max()) + 1 if n else 0):
        tips = stand.tips()
        anc = stand.ancestor_at(level)
        roots = np.nonzero((stand.depth == level) & stand.alive & stand.unit_start())[0]
        if not len(roots) or not len(tips):
            continue
        ta = anc[tips]
        ok = ta >= 0
        tips, ta = tips[ok], ta[ok]
        g = grad(stand.end[tips])                                     # (1a)
        lever = np.linalg.norm(stand.end[tips] - stand.start[ta], axis=1)
        g = g * lever[:, None]                                        # (1b)
        acc = np.zeros((n, 3))
        np.add.at(acc, ta, g)
        cnt = np.bincount(ta, minlength=n).astype(float)
        r = roots[cnt[roots] > 0]
        v = acc[r] / cnt[r, None]                                     # (2)
        d = stand.end[r] - stand.start[r]
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
        v = v - (v * d).sum(1, keepdims=True) * d                     # (3)
        L = np.linalg.norm(v, axis=1)
        ang = np.minimum(constant * np.sqrt(L / cnt[r]), max_angle)   # (4)
        axis = np.cross(d, v)
        an = np.linalg.norm(axis, axis=1)
        go = (an > 1e-12) & (ang > 1e-9)
        if not go.any():
            continue
        r, ang = r[go], ang[go]
        axis = axis[go] / an[go, None]
        # rotate every segment whose ancestor at this level is a rotating root
        rot_id = np.full(n, -1)
        rot_id[r] = np.arange(len(r))
        seg_rot = np.where(anc >= 0, rot_id[np.maximum(anc, 0)], -1)
        m = seg_rot >= 0
        k = seg_rot[m]
        pivot = stand.start[r][k]
        stand.end[m] = _rotate_about(stand.end[m], pivot, axis[k], ang[k])
        # starts: all but the roots themselves (they are the pivots)
        ms = m & (stand.depth > level)
        ks = seg_rot[ms]
        stand.start[ms] = _rotate_about(stand.start[ms], stand.start[r][ks], axis[ks], ang[ks])
        # leaves and leaf spheres turn with their segments
        stand.rotate_attachments(seg_rot, stand.start[r], axis, ang)
        rotated += len(r)
        angles.append(ang)
    allang = np.degrees(np.concatenate(angles)) if angles else np.zeros(0)
    return {"rotations": int(rotated),
            "angle_mean_deg": float(allang.mean()) if len(allang) else 0.0,
            "angle_max_deg": float(allang.max()) if len(allang) else 0.0,
            "rays": vs.stats.get("rays", 0), "dda_steps": vs.stats.get("dda_steps", 0),
            "light_s": vs.stats.get("light_s", 0.0)}
