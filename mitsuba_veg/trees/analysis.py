"""Shape measures used to state the papers' results as numbers (tests, experiments, docs)."""
from __future__ import annotations

import numpy as np


def crown_points(tree) -> np.ndarray:
    """Leaf-sphere centres if the tree has them, else leaf positions, else live segment ends."""
    c = tree.attrs.get("leaf_sphere_center")
    if c is not None and len(c):
        return np.asarray(c, float)
    if len(tree.leaves):
        return tree.leaves.position
    return tree.end[tree.alive] if tree.alive.any() else tree.end


def crown_shift(tree) -> np.ndarray:
    """Horizontal offset (x, z) [m] of the crown centroid from the tree's base."""
    m = tree.metrics()
    return (np.asarray(m["crown_centroid"]) - np.asarray(m["base"]))[[0, 2]]


def outward_shift(trees, centre=None) -> np.ndarray:
    """For each tree, its crown shift projected on the horizontal direction from ``centre``
    (default: the mean of the bases) to its base [m]; NaN for a tree at the centre."""
    bases = np.array([t.metrics()["base"] for t in trees])[:, [0, 2]]
    c = bases.mean(0) if centre is None else np.asarray(centre, float)
    out = []
    for t, b in zip(trees, bases):
        v = b - c
        n = np.linalg.norm(v)
        out.append(float(crown_shift(t) @ (v / n)) if n > 1e-9 else float("nan"))
    return np.array(out)


def flatness(tree) -> float:
    """sqrt(smaller / larger eigenvalue) of the horizontal covariance of the crown points:
    1 for a round crown, 0 for a crown in one vertical plane."""
    c = crown_points(tree)[:, [0, 2]]
    if len(c) < 3:
        return float("nan")
    ev = np.linalg.eigvalsh(np.cov((c - c.mean(0)).T))
    return float(np.sqrt(max(ev[0], 0.0) / max(ev[1], 1e-30)))


def main_axis_length(tree) -> float:
    """Mean length [m] of live main-axis segments (growth model; the trunk's first excluded)."""
    lat = np.asarray(tree.attrs.get("lateral", np.zeros(len(tree), bool)), bool)
    sel = tree.alive & ~lat & (tree.parent >= 0)
    return float(tree.length[sel].mean()) if sel.any() else float("nan")


def lean(tree, reference) -> np.ndarray:
    """Horizontal displacement (x, z) [m] of ``tree``'s crown centroid relative to
    ``reference`` (the same tree before a deformation)."""
    a = np.asarray(tree.metrics()["crown_centroid"])
    b = np.asarray(reference.metrics()["crown_centroid"])
    return (a - b)[[0, 2]]
