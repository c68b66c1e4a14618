"""The tree structure shared by every tree model (growth 001, non-growth 002, Weber-Penn 004).

A tree is a set of straight branch *segments* stored as a structure of arrays (NumPy), so models
and the renderer work on whole arrays, never on Python objects per branch:

- ``start``, ``end`` (n, 3) [m]: segment end points (+y up);
- ``radius_start``, ``radius_end`` (n,) [m]: radii at both ends (pipe model, taper ...);
- ``parent`` (n,) int: index of the parent segment, -1 for a root; parents come before their
  children (topological order), which lets subtree sums run as one reverse pass;
- ``level`` (n,) int: branching order (0 = trunk);
- ``alive`` (n,) bool: dead branches are kept (to report them) but not drawn;
- ``kind`` (n,) int8: 0 normal branch, 1 knot (paper 004), 2 sprouted knot;
- ``leaves``: a :class:`Leaves` set (positions, normals, sizes, the segment each hangs on, and
  free per-leaf attributes such as autumn state).

Models add their own per-segment arrays in ``attrs`` (e.g. received light). Keys with a
meaning shared by several modules:

- ``leaf_sphere_center`` (k, 3) [m], ``leaf_sphere_radius`` [m]: the leaf spheres of the growth
  model (paper 001); when present they are the crown points of :meth:`Tree.metrics` (the leaf
  blades drawn in them are random) and move with the tree (:meth:`Tree.translated`,
  :meth:`Tree.transform_points`).
"""
from __future__ import annotations

import copy as _copy
from dataclasses import dataclass, field

import numpy as np

from mitsuba_veg.errors import ParameterError

__all__ = ["POINT_ATTRS", "LEAF_SPHERE_ATTRS", "Leaves", "Tree", "scaled_tree", "DIRECTION_ATTRS",
           "placed_tree", "segment_depth", "subtree_sum", "tube_mesh", "leaf_quads"]

NORMAL, KNOT, SPROUTED_KNOT = 0, 1, 2
#: attrs holding points [m] that move with the tree
POINT_ATTRS = ("leaf_sphere_center",)
#: per-leaf-sphere attrs (one row per sphere, aligned with ``leaf_sphere_segment``)
LEAF_SPHERE_ATTRS = ("leaf_sphere_center", "leaf_sphere_segment", "light", "red_far_red",
                     "light_vector", "tip_u")


@dataclass
class Leaves:
    """Leaves of a tree: one row per leaf."""

    position: np.ndarray                    # (m, 3) [m] leaf centre
    normal: np.ndarray                      # (m, 3) unit blade normal
    size: np.ndarray                        # (m,) [m] blade length
    segment: np.ndarray                     # (m,) int: segment the leaf hangs on
    up: np.ndarray | None = None            # (m, 3) unit blade axis (petiole -> tip)
    attrs: dict = field(default_factory=dict)

    @staticmethod
    def empty() -> "Leaves":
        """An empty leaf set (no rows).

        Returns
        -------
        Leaves
            A leaf set with zero leaves.
        """
        return Leaves(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.size)

    def subset(self, mask) -> "Leaves":
        """The leaves selected by a mask (or index array), their ``attrs`` included.

        Parameters
        ----------
        mask : array_like
            (m,) boolean mask over the leaves, or integer indices of the leaves to keep.

        Returns
        -------
        Leaves
            A new leaf set holding the selected rows (arrays are indexed copies).
        """
        mask = np.asarray(mask)
        return Leaves(self.position[mask], self.normal[mask], self.size[mask], self.segment[mask],
                      None if self.up is None else self.up[mask],
                      {k: np.asarray(v)[mask] for k, v in self.attrs.items()})


@dataclass
class Tree:
    """A tree as arrays of straight segments (see module docstring)."""

    start: np.ndarray
    end: np.ndarray
    radius_start: np.ndarray
    radius_end: np.ndarray
    parent: np.ndarray
    level: np.ndarray
    alive: np.ndarray | None = None
    kind: np.ndarray | None = None
    leaves: Leaves | None = None
    attrs: dict = field(default_factory=dict)
    name: str = "tree"

    def __post_init__(self):
        self.start = np.asarray(self.start, dtype=np.float64).reshape(-1, 3)
        self.end = np.asarray(self.end, dtype=np.float64).reshape(-1, 3)
        n = len(self.start)
        self.radius_start = np.asarray(self.radius_start, dtype=np.float64).reshape(n)
        self.radius_end = np.asarray(self.radius_end, dtype=np.float64).reshape(n)
        self.parent = np.asarray(self.parent, dtype=np.int64).reshape(n)
        self.level = np.asarray(self.level, dtype=np.int64).reshape(n)
        self.alive = np.ones(n, bool) if self.alive is None else np.asarray(self.alive, bool)
        self.kind = np.zeros(n, np.int8) if self.kind is None else np.asarray(self.kind, np.int8)
        if self.leaves is None:
            self.leaves = Leaves.empty()
        if len(self.end) != n:
            raise ParameterError("Tree.end", f"{len(self.end)} rows", f"{n} rows (as start)")
        if n and np.any(self.parent >= np.arange(n)):
            raise ParameterError("Tree.parent", "a parent after its child",
                                 "parent[i] < i (parents first) or -1 for roots")

    # ---- structure ---------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.start)

    @property
    def length(self) -> np.ndarray:
        """Segment lengths [m]."""
        return np.linalg.norm(self.end - self.start, axis=1)

    @property
    def direction(self) -> np.ndarray:
        """Unit direction (n, 3) [-] of every segment, start to end (0 if zero-length)."""
        d = self.end - self.start
        return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)

    def depth(self) -> np.ndarray:
        """Number of ancestors of every segment (0 for roots).

        Returns
        -------
        numpy.ndarray
            (n,) int ancestor count per segment.
        """
        return segment_depth(self.parent)

    def subtree_sum(self, values) -> np.ndarray:
        """Sum of ``values`` over each segment's subtree (itself included).

        One vectorised pass per depth level, deepest first (:func:`subtree_sum`).

        Parameters
        ----------
        values : array_like
            (n,) per-segment values (any unit, e.g. leaf area [m2] or light).

        Returns
        -------
        numpy.ndarray
            (n,) float64 subtree sums, in the unit of ``values``.
        """
        return subtree_sum(self.parent, values)

    def subtree_mask(self, root: int) -> np.ndarray:
        """Boolean mask of the segments in ``root``'s subtree (itself included).

        Parameters
        ----------
        root : int
            Index of the segment at the root of the subtree.

        Returns
        -------
        numpy.ndarray
            (n,) bool, True for ``root`` and its descendants.
        """
        m = np.zeros(len(self), bool)
        m[root] = True
        for i in range(root + 1, len(self)):
            p = self.parent[i]
            if p >= 0 and m[p]:
                m[i] = True
        return m

    def tips(self, alive_only: bool = True) -> np.ndarray:
        """Indices of terminal segments (no live child).

        Parameters
        ----------
        alive_only : bool, optional
            If True (default), consider live segments only: a tip is a live segment with no live
            child. If False, every segment with no child.

        Returns
        -------
        numpy.ndarray
            int indices of the terminal segments, ascending.
        """
        keep = self.alive if alive_only else np.ones(len(self), bool)
        has_child = np.zeros(len(self), bool)
        par = self.parent[keep & (self.parent >= 0)]
        has_child[par] = True
        return np.nonzero(keep & ~has_child)[0]

    def drop_dead_leaves(self) -> "Tree":
        """Remove leaves (and leaf spheres) hanging on dead segments, in place.

        The per-leaf-sphere attrs (``LEAF_SPHERE_ATTRS``) are filtered with the spheres, and the
        leaves' ``"sphere"`` attribute is renumbered to match.

        Returns
        -------
        Tree
            ``self`` (modified in place), for chaining.
        """
        if len(self.leaves):
            self.leaves = self.leaves.subset(self.alive[self.leaves.segment])
        seg = self.attrs.get("leaf_sphere_segment")
        if seg is not None:
            seg = np.asarray(seg, np.int64)
            keep = self.alive[seg] if len(seg) else np.zeros(0, bool)
            n = len(seg)
            for k in LEAF_SPHERE_ATTRS:
                v = self.attrs.get(k)
                if v is not None and len(np.asarray(v)) == n:
                    self.attrs[k] = np.asarray(v)[keep]
            if "sphere" in self.leaves.attrs and len(self.leaves):
                remap = np.cumsum(keep) - 1
                self.leaves.attrs["sphere"] = remap[self.leaves.attrs["sphere"]]
        return self

    def copy(self) -> "Tree":
        """A deep copy of the tree (arrays, leaves and ``attrs`` copied).

        Returns
        -------
        Tree
            An independent copy.
        """
        lv = self.leaves
        leaves = Leaves(lv.position.copy(), lv.normal.copy(), lv.size.copy(), lv.segment.copy(),
                        None if lv.up is None else lv.up.copy(),
                        {k: np.array(v, copy=True) for k, v in lv.attrs.items()})
        t = Tree(self.start.copy(), self.end.copy(), self.radius_start.copy(),
                 self.radius_end.copy(), self.parent.copy(), self.level.copy(),
                 self.alive.copy(), self.kind.copy(), leaves, _copy.deepcopy(self.attrs),
                 self.name)
        return self._keep_record(t)

    def _keep_record(self, t: "Tree") -> "Tree":
        """``t`` with this tree's Weber-Penn generation record (``weber_penn``), if it has one:
        a copy of a Weber-Penn tree stays one (its wood is meshed as such, it ages by its
        preset). The record is shared (parameters and counts, not geometry)."""
        if getattr(self, "weber_penn", None) is not None:
            t.weber_penn = self.weber_penn
        return t

    def translated(self, offset) -> "Tree":
        """A copy of the tree moved by ``offset``.

        Segments, leaves and the point attrs (``POINT_ATTRS``, e.g. leaf-sphere centres) move;
        radii, normals and other arrays are shared with the original, ``alive`` and ``kind`` copied.

        Parameters
        ----------
        offset : array_like
            (3,) translation (x, y, z) [m].

        Returns
        -------
        Tree
            The translated tree.
        """
        o = np.asarray(offset, float)
        lv = self.leaves
        leaves = Leaves(lv.position + o, lv.normal, lv.size, lv.segment, lv.up, dict(lv.attrs))
        attrs = dict(self.attrs)
        for k in POINT_ATTRS:
            if k in attrs:
                attrs[k] = np.asarray(attrs[k], float) + o
        return self._keep_record(Tree(self.start + o, self.end + o, self.radius_start,
                                      self.radius_end, self.parent, self.level,
                                      self.alive.copy(), self.kind.copy(), leaves, attrs,
                                      self.name))

    # ---- metrics -----------------------------------------------------------------------------
    def metrics(self) -> dict:
        """Shape numbers of the tree.

        Height [m], crown centroid (x, y, z) [m], crown radius [m] (mean horizontal distance of the
        crown points from the crown's vertical axis through the centroid), branch and leaf counts.
        Crown points are the leaf spheres when the tree has them (growth model), else the leaves,
        else the live segment ends.

        Returns
        -------
        dict
            ``height`` (float) [m] from the base to the highest live segment end or crown point;
            ``crown_centroid`` (list of 3 floats) [m]; ``crown_radius`` (float) [m];
            ``live_branches``, ``dead_branches``, ``leaves``, ``leaf_spheres`` (int) counts;
            ``base`` (list of 3 floats) [m], the start of the first segment.
        """
        live = self.alive
        base = self.start[0] if len(self) else np.zeros(3)
        spheres = self.attrs.get("leaf_sphere_center")
        if spheres is not None and len(spheres):
            pts = np.asarray(spheres, float).reshape(-1, 3)
        else:
            pts = self.leaves.position if len(self.leaves) else (self.end[live] if live.any()
                                                                  else self.end)
        if len(pts) == 0:
            pts = np.zeros((1, 3))
        top = max(float(self.end[live, 1].max()) if live.any() else base[1],
                  float(pts[:, 1].max()))
        cen = pts.mean(axis=0)
        rad = float(np.mean(np.hypot(pts[:, 0] - cen[0], pts[:, 2] - cen[2])))
        return {"height": top - float(base[1]), "crown_centroid": cen.tolist(),
                "crown_radius": rad, "live_branches": int(live.sum()),
                "dead_branches": int((~live).sum()), "leaves": int(len(self.leaves)),
                "leaf_spheres": 0 if spheres is None else int(len(spheres)),
                "base": base.tolist()}

    # ---- geometry ----------------------------------------------------------------------------
    def to_mesh(self, sides: int = 8, leaves: bool = True, min_radius: float = 0.0):
        """A ``trimesh.Trimesh`` of the live branches plus, optionally, the leaves.

        Branches are open tapered tubes with ``sides`` corners; when ``leaves``, one quad per leaf
        (two triangles, :func:`leaf_quads`). Face attribute ``part`` (in ``mesh.metadata``):
        0 bark, 1 leaf.

        Parameters
        ----------
        sides : int, optional
            Corners of each tube's cross-section (default 8).
        leaves : bool, optional
            Add the leaf quads (default True).
        min_radius : float, optional
            Lower bound on the drawn branch radii [m] (default 0: the tree's radii).

        Returns
        -------
        trimesh.Trimesh
            The mesh (vertices in [m]), with ``metadata["part"]`` (one int8 per face).
        """
        import trimesh

        bark_v, bark_f = tube_mesh(self.start[self.alive], self.end[self.alive],
                                   np.maximum(self.radius_start[self.alive], min_radius),
                                   np.maximum(self.radius_end[self.alive], min_radius), sides)
        verts, faces, part = [bark_v], [bark_f], [np.zeros(len(bark_f), np.int8)]
        if leaves and len(self.leaves):
            lv, lf = leaf_quads(self.leaves)
            faces.append(lf + len(bark_v))
            verts.append(lv)
            part.append(np.ones(len(lf), np.int8))
        mesh = trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=False)
        mesh.metadata["part"] = np.concatenate(part)
        return mesh

    def export(self, path, **kw) -> str:
        """Write the mesh to PLY / OBJ / GLB / glTF / STL (by extension).

        Parameters
        ----------
        path : str or pathlib.Path
            Output file; its extension picks the format.
        **kw : dict
            Keyword arguments of :meth:`to_mesh` (``sides``, ``leaves``, ``min_radius``).

        Returns
        -------
        str
            The path written.

        Raises
        ------
        ParameterError
            If the extension is not .ply, .obj, .glb, .gltf or .stl.
        """
        path = str(path)
        ext = path.rsplit(".", 1)[-1].lower()
        if ext not in ("ply", "obj", "glb", "gltf", "stl"):
            raise ParameterError("path", path, "a .ply, .obj, .glb, .gltf or .stl file name")
        self.to_mesh(**kw).export(path)
        return path


def scaled_tree(tree, factor: float, offset=(0.0, 0.0, 0.0)):
    """A copy of ``tree`` scaled about its base by ``factor`` and moved by ``offset`` [m].

    Positions, radii, leaf sizes (and leaf ``width`` attrs) and leaf-sphere centres scale; a
    Weber-Penn parameter set attached as ``tree.weber_penn`` is carried over.

    Parameters
    ----------
    tree : Tree
        The tree; its base is the start of its first segment.
    factor : float
        Scale factor [-].
    offset : array_like, optional
        (3,) translation applied after scaling [m] (default none).

    Returns
    -------
    Tree
        The scaled copy.
    """
    # a copy (Tree.copy's) whose scaled arrays are made once, not copied and then replaced
    base = tree.start[0].copy() if len(tree) else np.zeros(3)
    o = np.asarray(offset, float)
    lv = tree.leaves
    lattrs = {k: (np.asarray(v) * factor if k == "width" else np.array(v, copy=True))
              for k, v in lv.attrs.items()}
    leaves = Leaves((lv.position - base) * factor + base + o, lv.normal.copy(),
                    lv.size * factor, lv.segment.copy(),
                    None if lv.up is None else lv.up.copy(), lattrs)
    attrs = {k: (v if k == "leaf_sphere_center" else _copy.deepcopy(v))
             for k, v in tree.attrs.items()}
    for k in ("leaf_sphere_center",):
        if k in attrs:
            attrs[k] = (np.asarray(attrs[k]) - base) * factor + base + o
    t = Tree((tree.start - base) * factor + base + o, (tree.end - base) * factor + base + o,
             tree.radius_start * factor, tree.radius_end * factor, tree.parent.copy(),
             tree.level.copy(), tree.alive.copy(), tree.kind.copy(), leaves, attrs, tree.name)
    return tree._keep_record(t)


#: attrs holding unit directions that turn with the tree
DIRECTION_ATTRS = ("frame_x", "light_vector", "tip_u")


def placed_tree(tree, factor: float = 1.0, yaw: float = 0.0, position=None):
    """A copy of ``tree`` turned by ``yaw`` about +y through its base, scaled about its base by
    ``factor`` and moved so that its base is at ``position`` [m].

    The placement of a stand's tree (:meth:`mitsuba_veg.trees.stand.Stand.transforms`:
    ``p' = position + factor R_y(yaw) (p - base)``, with ``x' = cos(yaw) x + sin(yaw) z``,
    ``z' = -sin(yaw) x + cos(yaw) z``). Points (segments, leaves, ``POINT_ATTRS``) move;
    directions (leaf normals and axes, ``DIRECTION_ATTRS``) turn; lengths scale as in
    :func:`scaled_tree`.

    Parameters
    ----------
    tree : Tree
        The tree; its base is the start of its first segment.
    factor : float
        Scale factor [-].
    yaw : float
        Turn about +y [deg].
    position : array_like, optional
        (3,) new base [m]; default None: the base stays.

    Returns
    -------
    Tree
        The placed copy.
    """
    t = tree.copy()
    base = t.start[0].copy() if len(t) else np.zeros(3)
    a = np.radians(float(yaw))
    c, s = np.cos(a), np.sin(a)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    def point(p):
        return (np.asarray(p, float) - base) @ R.T + base

    t.start, t.end = point(t.start), point(t.end)
    lv = t.leaves
    lv.position = point(lv.position)
    lv.normal = np.asarray(lv.normal, float) @ R.T
    if lv.up is not None:
        lv.up = np.asarray(lv.up, float) @ R.T
    for k in POINT_ATTRS:
        if k in t.attrs and np.ndim(t.attrs[k]) == 2:
            t.attrs[k] = point(t.attrs[k])
    for k in DIRECTION_ATTRS:
        if k in t.attrs and np.ndim(t.attrs[k]) == 2:
            t.attrs[k] = np.asarray(t.attrs[k], float) @ R.T
    offset = np.zeros(3) if position is None else np.asarray(position, float) - base
    return scaled_tree(t, factor, offset)


def segment_depth(parent) -> np.ndarray:
    """Ancestor count per segment for a parents-first ``parent`` array.

    Parameters
    ----------
    parent : array_like
        (n,) int parent index of every segment, -1 for roots.

    Returns
    -------
    numpy.ndarray
        (n,) int64 number of ancestors (0 for roots).
    """
    parent = np.asarray(parent, np.int64)
    n = len(parent)
    depth = np.zeros(n, np.int64)
    cur = parent.copy()
    while True:
        m = cur >= 0
        if not m.any():
            return depth
        depth[m] += 1
        cur[m] = parent[cur[m]]


def subtree_sum(parent, values) -> np.ndarray:
    """Sum of ``values`` over every segment's subtree (itself included).

    One vectorised pass per depth level, deepest first.

    Parameters
    ----------
    parent : array_like
        (n,) int parent index of every segment (parents first), -1 for roots.
    values : array_like
        (n,) per-segment values (any unit).

    Returns
    -------
    numpy.ndarray
        (n,) float64 subtree sums, in the unit of ``values``.
    """
    parent = np.asarray(parent, np.int64)
    acc = np.array(values, dtype=np.float64, copy=True)
    if len(parent) == 0:
        return acc
    depth = segment_depth(parent)
    for d in range(int(depth.max()), 0, -1):
        idx = np.nonzero(depth == d)[0]
        np.add.at(acc, parent[idx], acc[idx])
    return acc


def _frames(d):
    """Two unit vectors perpendicular to each row of unit vectors ``d``."""
    a = np.where(np.abs(d[:, 1:2]) < 0.9, np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]))
    u = np.cross(d, a)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    return u, v


def tube_mesh(start, end, r0, r1, sides=8):
    """Vertices/faces of open tapered tubes, one per segment (vectorised over segments).

    Parameters
    ----------
    start, end : array_like
        (n, 3) segment end points [m].
    r0, r1 : array_like
        (n,) radii at ``start`` and ``end`` [m].
    sides : int, optional
        Corners of each cross-section (default 8).

    Returns
    -------
    verts : numpy.ndarray
        (2 * sides * n, 3) vertices [m].
    faces : numpy.ndarray
        (2 * sides * n, 3) int64 triangle vertex indices.
    """
    start, end = np.asarray(start, float), np.asarray(end, float)
    n = len(start)
    if n == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    d = end - start
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
    u, v = _frames(d)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(ang)[None, :, None] * u[:, None, :] + np.sin(ang)[None, :, None] * v[:, None, :]
    bottom = start[:, None, :] + np.asarray(r0)[:, None, None] * ring
    top = end[:, None, :] + np.asarray(r1)[:, None, None] * ring
    verts = np.concatenate([bottom, top], axis=1).reshape(-1, 3)
    k = np.arange(sides)
    k1 = (k + 1) % sides
    quad = np.stack([np.stack([k, k1, sides + k1], 1), np.stack([k, sides + k1, sides + k], 1)],
                    1).reshape(-1, 3)
    faces = (quad[None, :, :] + (2 * sides * np.arange(n))[:, None, None]).reshape(-1, 3)
    return verts, faces


def leaf_quads(leaves: Leaves):
    """Vertices/faces of one quad (blade length x 0.6 blade length wide) per leaf.

    The quad lies in the blade plane (normal ``leaves.normal``), its long axis along
    ``leaves.up`` (made perpendicular to the normal) or an arbitrary in-plane axis when the
    leaves have no ``up``.

    Parameters
    ----------
    leaves : Leaves
        The leaves (centre, normal, size [m]).

    Returns
    -------
    verts : numpy.ndarray
        (4 m, 3) vertices [m].
    faces : numpy.ndarray
        (2 m, 3) int triangle vertex indices.
    """
    n = len(leaves)
    nrm = leaves.normal / np.maximum(np.linalg.norm(leaves.normal, axis=1, keepdims=True), 1e-30)
    if leaves.up is not None:
        up = leaves.up - (leaves.up * nrm).sum(1, keepdims=True) * nrm
        up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-30)
    else:
        up, _ = _frames(nrm)
    side = np.cross(nrm, up)
    h = 0.5 * leaves.size[:, None]
    w = 0.3 * leaves.size[:, None]
    c = leaves.position
    verts = np.stack([c - h * up - w * side, c - h * up + w * side, c + h * up + w * side,
                      c + h * up - w * side], 1).reshape(-1, 3)
    base = 4 * np.arange(n)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return verts, faces
