"""Leaf geometry for Mitsuba: trees' leaves and branches as meshes, random leaf clouds, test trees.

- :func:`leaves_mesh_arrays` / :func:`bark_mesh_arrays`: vertices and faces of leaf quads and
  bark tubes (via :mod:`mitsuba_veg.trees.structure`), two triangles per leaf, leaf ``i`` owning
  triangles ``2i`` and ``2i + 1``.
- :func:`random_leaf_cloud`: leaves scattered uniformly in a box with isotropic ("spherical")
  normals, for Beer–Lambert checks (G = 0.5).
- :func:`sphere_crown_tree`: a simple test tree (trunk, a few branches, a spherical crown of
  leaves); the growth and Weber–Penn models give real ones.
- :func:`class_meshes`: split leaves into classes (e.g. autumn stages) so each class gets its
  own ``veg_leaf`` BSDF in a scene.
"""
from __future__ import annotations

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range
from mitsuba_veg.meshes import make_mesh
from mitsuba_veg.trees.structure import Leaves, Tree, leaf_quads, tube_mesh

__all__ = ["LEAF_AREA_FACTOR", "leaf_area", "random_unit_vectors", "random_leaf_cloud",
           "leaf_layer_triangles", "sphere_crown_tree", "leaves_mesh_arrays", "bark_mesh_arrays",
           "class_meshes", "mesh"]

#: a leaf quad is size x (2 * 0.3 size) (mitsuba_veg.trees.structure.leaf_quads)
LEAF_AREA_FACTOR = 0.6


def leaf_area(leaves: Leaves) -> np.ndarray:
    """One-sided area of each leaf quad [m2].

    A quad is size x (2 × 0.3 size): area = :data:`LEAF_AREA_FACTOR` size².

    Parameters
    ----------
    leaves : Leaves
        The leaves (``size``: blade length [m]).

    Returns
    -------
    numpy.ndarray
        (n,) one-sided leaf areas [m2].
    """
    return LEAF_AREA_FACTOR * np.asarray(leaves.size, float) ** 2


def random_unit_vectors(n: int, rng) -> np.ndarray:
    """Isotropically distributed unit vectors (normalised Gaussian vectors).

    Parameters
    ----------
    n : int
        Number of vectors.
    rng : numpy.random.Generator
        Random generator.

    Returns
    -------
    numpy.ndarray
        (n, 3) unit vectors [-].
    """
    v = rng.standard_normal((n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_leaf_cloud(lai: float, box_min, box_max, leaf_size: float = 0.05, seed=0,
                      normals: str = "spherical") -> Leaves:
    """Leaves with uniformly random centres in a box and random orientations.

    As many leaves as make the one-sided leaf area per horizontal ground area (x-z) of the box
    equal ``lai``.

    Parameters
    ----------
    lai : float
        Leaf area index [m2 m-2] in (0, 50].
    box_min, box_max : array_like
        (3,) opposite corners of the box [m] (x, y, z; min < max).
    leaf_size : float
        Blade length of every leaf [m] (default 0.05).
    seed : int
        Random seed (default 0).
    normals : str
        ``"spherical"`` (isotropic: G = 0.5 for every direction, default) or ``"horizontal"``
        (all normals +y: G = ``|cos θ|``).

    Returns
    -------
    Leaves
        The leaves (segment -1: they hang on no branch).

    Raises
    ------
    ParameterError
        When the box is empty, ``normals`` is unknown, or ``lai`` / ``leaf_size`` is out of range.
    """
    check_range("lai", lai, 0.0, 50.0, lo_open=True)
    check_range("leaf_size", leaf_size, 0.0, 10.0, lo_open=True)
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    if lo.shape != (3,) or hi.shape != (3,) or (hi <= lo).any():
        raise ParameterError("box", (box_min, box_max), "min < max in x, y, z")
    ground = (hi[0] - lo[0]) * (hi[2] - lo[2])
    n = int(round(lai * ground / (LEAF_AREA_FACTOR * leaf_size ** 2)))
    rng = np.random.default_rng(seed)
    pos = lo + rng.random((n, 3)) * (hi - lo)
    if normals == "spherical":
        nrm = random_unit_vectors(n, rng)
    elif normals == "horizontal":
        nrm = np.tile([0.0, 1.0, 0.0], (n, 1))
    else:
        raise ParameterError("normals", normals, "'spherical' or 'horizontal'")
    up = np.cross(nrm, random_unit_vectors(n, rng))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    return Leaves(pos, nrm, np.full(n, float(leaf_size)), np.full(n, -1, np.int64), up)


def leaf_layer_triangles(half: float, y_range=(1.0, 2.5), lai: float = 6.0,
                         leaf_area: float = 4.9e-3, seed=0) -> np.ndarray:
    """A horizontally unbounded-looking leaf layer: equilateral triangles with uniformly random
    centres in a (2 half) x (2 half) m square between two heights and isotropic (spherical)
    orientations, as many as give the leaf area index ``lai``.

    Parameters
    ----------
    half : float
        Half the side of the square [m].
    y_range : (float, float)
        Lowest and highest leaf centre [m].
    lai : float
        One-sided leaf area per ground area [m2 m-2].
    leaf_area : float
        Area of one leaf triangle [m2].
    seed : int
        Random seed.

    Returns
    -------
    numpy.ndarray
        (n, 3, 3) triangle vertices [m], n = int(lai (2 half)^2 / leaf_area).
    """
    check_range("half", half, 0.0, 1e4, lo_open=True)
    check_range("lai", lai, 0.0, 50.0, lo_open=True)
    check_range("leaf_area", leaf_area, 0.0, 100.0, lo_open=True)
    rng = np.random.default_rng(seed)
    n = int(lai * (2 * half) ** 2 / leaf_area)
    c = np.column_stack([rng.uniform(-half, half, n), rng.uniform(y_range[0], y_range[1], n),
                         rng.uniform(-half, half, n)])
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    a = np.cross(nrm, rng.normal(size=(n, 3)))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(nrm, a)
    r = np.sqrt(leaf_area / (0.75 * np.sqrt(3)))     # circumradius of the equilateral leaf
    return np.stack([c + r * a, c + r * (-0.5 * a + 0.866 * b), c + r * (-0.5 * a - 0.866 * b)],
                    1)


def sphere_crown_tree(n_leaves: int = 2000, crown_radius: float = 1.5, crown_height: float = 3.0,
                      trunk_radius: float = 0.08, leaf_size: float = 0.08, seed=0,
                      branches: int = 12) -> Tree:
    """A test tree with a spherical crown of leaves.

    A vertical trunk to the crown centre, ``branches`` straight branches out to the crown surface,
    and ``n_leaves`` leaves uniformly in the crown sphere (random normals tilted upwards:
    normal·up >= 0), each hanging on its nearest branch.

    Parameters
    ----------
    n_leaves : int
        Number of leaves (default 2000).
    crown_radius : float
        Radius of the crown sphere [m] (default 1.5).
    crown_height : float
        Height of the crown centre above the trunk base (origin) [m] (default 3.0).
    trunk_radius : float
        Trunk radius at its base [m] (default 0.08; branches start at 0.4 of it).
    leaf_size : float
        Blade length of every leaf [m] (default 0.08).
    seed : int
        Random seed (default 0).
    branches : int
        Number of branches (default 12).

    Returns
    -------
    Tree
        The tree (``name="sphere_crown"``) with its leaves.
    """
    check_range("n_leaves", n_leaves, 0, 10_000_000)
    rng = np.random.default_rng(seed)
    c = np.array([0.0, crown_height, 0.0])
    starts = [np.zeros(3)]
    ends = [c.copy()]
    dirs = random_unit_vectors(branches, rng)
    dirs[:, 1] = np.abs(dirs[:, 1]) * 0.6 + 0.2
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for d in dirs:
        starts.append(c.copy())
        ends.append(c + 0.85 * crown_radius * d)
    starts, ends = np.array(starts), np.array(ends)
    r0 = np.r_[trunk_radius, np.full(branches, trunk_radius * 0.4)]
    r1 = np.r_[trunk_radius * 0.7, np.full(branches, trunk_radius * 0.1)]
    parent = np.r_[-1, np.zeros(branches, np.int64)]
    level = np.r_[0, np.ones(branches, np.int64)]
    # leaves uniform in the ball
    u = rng.random(n_leaves) ** (1 / 3)
    pos = c + crown_radius * u[:, None] * random_unit_vectors(n_leaves, rng)
    nrm = random_unit_vectors(n_leaves, rng)
    nrm[:, 1] = np.abs(nrm[:, 1])
    up = np.cross(nrm, random_unit_vectors(n_leaves, rng))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    # nearest branch (by distance to segment end)
    d2 = ((pos[:, None, :] - ends[None, 1:, :]) ** 2).sum(-1) if branches else None
    seg = (1 + np.argmin(d2, axis=1)) if branches else np.zeros(n_leaves, np.int64)
    leaves = Leaves(pos, nrm, np.full(n_leaves, float(leaf_size)), seg.astype(np.int64), up)
    return Tree(starts, ends, r0, r1, parent, level, leaves=leaves, name="sphere_crown")


def leaves_mesh_arrays(leaves: Leaves):
    """(vertices, faces) of the leaf quads: leaf i owns triangles 2i, 2i + 1.

    Parameters
    ----------
    leaves : Leaves
        The leaves.

    Returns
    -------
    vertices : numpy.ndarray
        (4 n, 3) quad corners [m].
    faces : numpy.ndarray
        (2 n, 3) int vertex indices.
    """
    if len(leaves) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return leaf_quads(leaves)


def bark_mesh_arrays(tree: Tree, sides: int = 6):
    """(vertices, faces) of the live branches as tapered tubes.

    Parameters
    ----------
    tree : Tree
        The tree (its ``alive`` segments).
    sides : int
        Sides of each tube (default 6).

    Returns
    -------
    vertices : numpy.ndarray
        (n, 3) tube vertices [m].
    faces : numpy.ndarray
        (f, 3) int vertex indices.
    """
    a = tree.alive
    return tube_mesh(tree.start[a], tree.end[a], tree.radius_start[a], tree.radius_end[a], sides)


def class_meshes(leaves: Leaves, classes) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Split leaves by integer class (e.g. autumn stages), one mesh per class.

    Parameters
    ----------
    leaves : Leaves
        The leaves.
    classes : array_like
        (n,) integer class of each leaf.

    Returns
    -------
    dict
        ``{class: (vertices [m], faces, leaf_indices)}``; leaf ``leaf_indices[j]`` owns triangles
        2j, 2j + 1 of its class's mesh.

    Raises
    ------
    ParameterError
        When ``classes`` does not have one value per leaf.
    """
    classes = np.asarray(classes)
    if classes.shape != (len(leaves),):
        raise ParameterError("classes", classes.shape, f"one class per leaf ({len(leaves)},)")
    out = {}
    for k in np.unique(classes):
        idx = np.flatnonzero(classes == k)
        v, f = leaves_mesh_arrays(leaves.subset(classes == k))
        out[int(k)] = (v, f, idx)
    return out


def mesh(name: str, vertices, faces, bsdf=None):
    """A Mitsuba mesh with id ``name``.

    Parameters
    ----------
    name : str
        The shape id.
    vertices : array_like
        (n, 3) positions [m].
    faces : array_like
        (f, 3) vertex indices.
    bsdf : dict or mi.BSDF, optional
        Its material (default: Mitsuba's default BSDF).

    Returns
    -------
    mitsuba.Mesh
        The mesh (:func:`mitsuba_veg.meshes.make_mesh`).
    """
    return make_mesh(name, vertices, faces, bsdf=bsdf)
