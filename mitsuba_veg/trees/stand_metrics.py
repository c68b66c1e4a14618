"""Tree metrics for a stand's table: height, crown radius, leaf area and live branches per tree.

Works on the world's trees (``mitsuba_veg.world.trees.WorldTree``: ``name``, ``model``,
``position``, ``bark``, ``leaf_vertices``, ``leaf_area``, ``tree``) and on bare
:class:`~mitsuba_veg.trees.structure.Tree` objects (read by their attributes, so this module
does not import the world). Definitions:

- **height** [m]: highest point of the tree above its base: the live segment ends of its branch
  structure and the corners of its leaf blades on the tree (a user's mesh tree without a
  structure: its wood's vertices and its leaf corners);
- **crown radius** [m]: the 90th percentile of the horizontal distances of the leaf blades'
  centres (on the tree) from their mean, as ``WorldTree.crown_radius``; a tree without leaves
  on it takes the ends of its live segments instead (bare crown); 0 with neither;
- **leaf area** [m2]: one-sided blade area of the leaves on the tree (``WorldTree.leaf_area``;
  for a bare ``Tree`` the area of the quads the package draws, 0.6 x size², see
  :func:`~mitsuba_veg.trees.structure.leaf_quads`);
- **live branches**, **dead branches**: segments of the branch structure alive or dead (the
  count of ``Tree.metrics``; knots included); None for a mesh tree.

The base is ``position`` for a world tree, the start of the first segment for a ``Tree``.
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .structure import leaf_quads

#: the columns of a row, in order
COLUMNS = ("tree", "name", "model", "x", "y", "z", "height", "crown_radius", "leaf_area",
           "leaves", "live_branches", "dead_branches")


def crown_radius(points) -> float:
    """90th percentile of horizontal distances of crown points from their mean [m].

    Parameters
    ----------
    points : array_like
        (k, 3) crown points (x, y, z) [m].

    Returns
    -------
    float
        The radius [m] (0 without points).
    """
    p = np.asarray(points, float).reshape(-1, 3)
    if len(p) == 0:
        return 0.0
    c = p[:, [0, 2]].mean(axis=0)
    return float(np.percentile(np.hypot(p[:, 0] - c[0], p[:, 2] - c[1]), 90))


def tree_metrics(tree, on_tree=None) -> dict:
    """The metrics of one tree (module docstring).

    Parameters
    ----------
    tree : WorldTree or Tree
        A world tree (with ``leaf_vertices``, ``leaf_area``, ``position`` and optionally a
        branch structure ``tree``) or a bare branch structure.
    on_tree : array_like of bool, optional
        (m,) which leaves are on the tree (the phenology's state); default None: all.

    Returns
    -------
    dict
        ``name``, ``model``, ``x``, ``y``, ``z`` (base) [m], ``height`` [m], ``crown_radius``
        [m], ``leaf_area`` [m2], ``leaves`` (on the tree), ``live_branches``,
        ``dead_branches`` (None without a branch structure).

    Raises
    ------
    ParameterError
        When ``on_tree`` does not have one value per leaf.
    """
    if hasattr(tree, "leaf_vertices"):                 # a world tree
        struct = getattr(tree, "tree", None)
        corners = np.asarray(tree.leaf_vertices, float)
        area = np.asarray(tree.leaf_area, float)
        base = np.asarray(tree.position, float)
        name, model = str(tree.name), str(tree.model)
        wood = None if struct is not None else np.asarray(tree.bark[0], float).reshape(-1, 3)
    else:                                              # a bare Tree
        struct = tree
        lv = tree.leaves
        if len(lv):
            v, _ = leaf_quads(lv)
            corners = np.asarray(v, float).reshape(-1, 4, 3)
        else:
            corners = np.zeros((0, 4, 3))
        area = 0.6 * np.asarray(lv.size, float) ** 2
        base = tree.start[0] if len(tree) else np.zeros(3)
        name, model, wood = str(tree.name), "tree", None
    n = len(area)
    on = np.ones(n, bool) if on_tree is None else np.asarray(on_tree, bool).ravel()
    if len(on) != n:
        raise ParameterError("on_tree", f"{len(on)} values", f"one per leaf ({n})")
    corners = corners[on]
    tops = [corners[..., 1].ravel()]
    live = dead = None
    if struct is not None and len(struct):
        alive = np.asarray(struct.alive, bool)
        live, dead = int(alive.sum()), int((~alive).sum())
        tops.append(np.asarray(struct.end, float)[alive, 1])
        ends = np.asarray(struct.end, float)[alive]
    else:
        ends = np.zeros((0, 3))
    if wood is not None:
        tops.append(wood[:, 1])
    top = np.concatenate(tops)
    height = float(top.max() - base[1]) if len(top) else 0.0
    crown = corners.mean(axis=1) if len(corners) else ends
    return {"name": name, "model": model, "x": float(base[0]), "y": float(base[1]),
            "z": float(base[2]), "height": height, "crown_radius": crown_radius(crown),
            "leaf_area": float(area[on].sum()), "leaves": int(on.sum()),
            "live_branches": live, "dead_branches": dead}


def stand_table(trees, on_tree=None, **extra) -> list[dict]:
    """One row of metrics per tree (:func:`tree_metrics`), e.g. one year of a forest run.

    Parameters
    ----------
    trees : sequence of WorldTree or Tree
        The trees.
    on_tree : sequence, optional
        Per tree, the leaves on it (bool arrays, or None for all); default None: all leaves.
    **extra : dict
        Columns added to every row first (e.g. ``year=3``).

    Returns
    -------
    list of dict
        Rows with ``extra``'s keys, then :data:`COLUMNS` (``tree`` is the index) — ready for
        ``pandas.DataFrame(rows)`` or ``csv.DictWriter``.

    Raises
    ------
    ParameterError
        When ``on_tree`` does not have one entry per tree.
    """
    trees = list(trees)
    if on_tree is not None and len(on_tree) != len(trees):
        raise ParameterError("on_tree", f"{len(on_tree)} entries", f"one per tree "
                             f"({len(trees)})")
    rows = []
    for i, t in enumerate(trees):
        m = tree_metrics(t, None if on_tree is None else on_tree[i])
        rows.append({**extra, "tree": i, **{k: m[k] for k in COLUMNS[1:]}})
    return rows


__all__ = ["COLUMNS", "crown_radius", "tree_metrics", "stand_table"]
