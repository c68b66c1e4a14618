"""Shape measures used to state the papers' results as numbers (tests, experiments, docs)."""
from __future__ import annotations

import numpy as np


__all__ = ["crown_points", "crown_shift", "outward_shift", "flatness", "main_axis_length", "lean"]

def crown_points(tree) -> np.ndarray:
    """Crown points of a tree: its leaf-sphere centres, else its leaves, else its live segment ends.

    Leaf-sphere centres (``attrs["leaf_sphere_center"]``) if the tree has them, else leaf
    positions, else live segment ends (all segment ends if none is alive).

    Parameters
    ----------
    tree : mitsuba_veg.trees.structure.Tree
        The tree.

    Returns
    -------
    numpy.ndarray
        (k, 3) crown points [m].
    """
    c = tree.attrs.get("leaf_sphere_center")
    if c is not None and len(c):
        return np.asarray(c, float)
    if len(tree.leaves):
        return tree.leaves.position
    return tree.end[tree.alive] if tree.alive.any() else tree.end


def crown_shift(tree) -> np.ndarray:
    """Horizontal offset (x, z) [m] of the crown centroid from the tree's base.

    Parameters
    ----------
    tree : mitsuba_veg.trees.structure.Tree
        The tree; its base is the start of its first segment (:meth:`Tree.metrics`).

    Returns
    -------
    numpy.ndarray
        (2,) offset (x, z) of the crown centroid from the base [m].
    """
    m = tree.metrics()
    return (np.asarray(m["crown_centroid"]) - np.asarray(m["base"]))[[0, 2]]


def outward_shift(trees, centre=None) -> np.ndarray:
    """Crown shift of each tree projected on the outward direction from a centre.

    For each tree, its crown shift (:func:`crown_shift`) projected on the horizontal direction
    from ``centre`` to its base [m]; NaN for a tree at the centre (closer than 1e-9 m).

    Parameters
    ----------
    trees : sequence of mitsuba_veg.trees.structure.Tree
        The trees (a stand).
    centre : array_like, optional
        (2,) horizontal centre (x, z) [m]; default: the mean of the trees' bases.

    Returns
    -------
    numpy.ndarray
        (len(trees),) outward crown shift of every tree [m] (positive: away from the centre).
    """
    bases = np.array([t.metrics()["base"] for t in trees])[:, [0, 2]]
    c = bases.mean(0) if centre is None else np.asarray(centre, float)
    out = []
    for t, b in zip(trees, bases):
        v = b - c
        n = np.linalg.norm(v)
        out.append(float(crown_shift(t) @ (v / n)) if n > 1e-9 else float("nan"))
    return np.array(out)


def flatness(tree) -> float:
    """Flatness of the crown: sqrt(smaller / larger eigenvalue) of its horizontal covariance.

    Computed on the horizontal (x, z) covariance of the crown points (:func:`crown_points`):
    1 for a round crown, 0 for a crown in one vertical plane.

    Parameters
    ----------
    tree : mitsuba_veg.trees.structure.Tree
        The tree.

    Returns
    -------
    float
        Flatness [-] in [0, 1]; NaN with fewer than 3 crown points.
    """
    c = crown_points(tree)[:, [0, 2]]
    if len(c) < 3:
        return float("nan")
    ev = np.linalg.eigvalsh(np.cov((c - c.mean(0)).T))
    return float(np.sqrt(max(ev[0], 0.0) / max(ev[1], 1e-30)))


def main_axis_length(tree) -> float:
    """Mean length [m] of live main-axis segments (growth model; the trunk's first excluded).

    Main-axis segments are those not flagged in ``attrs["lateral"]`` (all segments when the tree
    has no such attribute) and having a parent.

    Parameters
    ----------
    tree : mitsuba_veg.trees.structure.Tree
        The tree (typically from :func:`mitsuba_veg.trees.growth.grow`).

    Returns
    -------
    float
        Mean segment length [m]; NaN when no segment qualifies.
    """
    lat = np.asarray(tree.attrs.get("lateral", np.zeros(len(tree), bool)), bool)
    sel = tree.alive & ~lat & (tree.parent >= 0)
    return float(tree.length[sel].mean()) if sel.any() else float("nan")


def lean(tree, reference) -> np.ndarray:
    """Horizontal displacement (x, z) [m] of a tree's crown centroid relative to a reference.

    Parameters
    ----------
    tree : mitsuba_veg.trees.structure.Tree
        The tree, e.g. after a deformation (:func:`mitsuba_veg.trees.nongrowth.deform`).
    reference : mitsuba_veg.trees.structure.Tree
        The same tree before the deformation.

    Returns
    -------
    numpy.ndarray
        (2,) displacement (x, z) of the crown centroid [m].
    """
    a = np.asarray(tree.metrics()["crown_centroid"])
    b = np.asarray(reference.metrics()["crown_centroid"])
    return (a - b)[[0, 2]]
