"""Leaf blades as the render draws them: species outlines, folded and cupped, as small meshes.

Every leaf of a tree is one copy of a **template**: a low-polygon blade (2 n + 2 triangles for
n margin points a side: 12 for the ovate, elliptic, lanceolate and deltoid blades, 14 for the
lobed oak and maple) in the leaf's own frame (x across the blade, y from the
petiole to the tip, z along the blade normal), scaled by the leaf's size and placed at its centre
along its ``normal`` and ``up`` (:class:`~mitsuba_veg.trees.structure.Leaves`). All leaves are
placed at once (NumPy, no loop per leaf).

**Outlines** (half outlines from the petiole to the tip, mirrored):

- ``"ovate"``: the growth model's broadleaf (paper 001 draws no shape; an ovate blade, widest at
  0.38 of its length, half width 0.3 length);
- ``"deltoid"``: quaking aspen (rounded-deltoid, about as wide as long, with a short point);
- ``"elliptic"``: black tupelo; ``"lanceolate"``: weeping willow; ``"oak"``: California black
  oak (three lobes a side);
- ``"maple"``: paper 003's IFS maple (Barnsley's maple leaf, table 2): the outline of the
  attractor drawn by the chaos game (:func:`mitsuba_veg.foliage.ifs.chaos_game`) seen from the
  petiole (the fixed point of w1), simplified to its lobe tips and sinuses (sassafras).

**Relief**: the two halves fold up about the midrib (margins raised by ``fold`` x their distance
from it), the blade cups across (``cup`` x², a little) and arches along its length (the tip and
the base a little below the middle); four variants (folds, cups and arches of different depth)
are spread over the leaves by their index, so neighbours differ.

**Area**: each template is scaled (uniformly, keeping its outline) so that its surface area, the
fold and cup included, is exactly :data:`LEAF_AREA` x size²: the one-sided area of the blade the
world's light pass traces (:func:`mitsuba_veg.trees.structure.leaf_quads`, a quad of length x 0.6
length: ``WorldTree.leaf_area`` = 0.6 size², :mod:`mitsuba_veg.world.canopy` divides the flux by
it). A blade drawn here therefore catches the light of the blade the simulation gave it (its
length differs from ``size`` by the outline's shape: 1.14 size for the ovate blade). The template
is centred on its area centroid, placed at the leaf's centre (the quad's centre).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..errors import ParameterError
from ..foliage.ifs import MAPLE_IFS, chaos_game, fixed_point

__all__ = ["LEAF_AREA", "VARIANTS", "PRESET_OUTLINE", "half_outline", "SHAPES", "leaf_template",
           "triangle_areas", "leaf_shape_of", "leaf_frames", "blade_mesh"]

#: one-sided blade area per size² [-]: the light pass's quad (length x 0.6 length)
LEAF_AREA = 0.6
#: variants of each template (fold, cup, arch) spread over the leaves by index
VARIANTS = 4
#: Weber-Penn preset -> outline
PRESET_OUTLINE = {"quaking_aspen": "deltoid", "black_tupelo": "elliptic",
                  "weeping_willow": "lanceolate", "ca_black_oak": "oak", "sassafras": "maple"}


def _halfwidth_outline(n, width, peak, tip_point=0.0):
    """n margin points (x >= 0) of a blade whose half width is ``width`` sin(pi t^p), widest
    at ``peak`` of the length; y in [0, 1] from the petiole to the tip."""
    p = np.log(0.5) / np.log(peak)
    # stations denser near the base and the tip (where the outline bends most)
    t = 0.5 - 0.5 * np.cos(np.pi * (np.arange(1, n + 1) / (n + 1)))
    w = width * np.sin(np.pi * t ** p)
    if tip_point:        # a drawn-out point: the last stations pulled in
        w = w * (1.0 - tip_point * np.clip((t - 0.75) / 0.25, 0.0, 1.0))
    return np.stack([w, t], 1)


def _deltoid():
    """Quaking aspen: rounded-deltoid (broad, rounded base; sides meeting in a short point)."""
    return np.array([[0.26, -0.01], [0.48, 0.16], [0.47, 0.42], [0.30, 0.70], [0.09, 0.92]])


def _oak():
    """California black oak: three pointed lobes a side, deep sinuses."""
    return np.array([[0.30, 0.10], [0.13, 0.26], [0.42, 0.42], [0.17, 0.56], [0.32, 0.74],
                     [0.10, 0.86]])


@lru_cache(maxsize=1)
def _maple():
    """Paper 003's IFS maple: the attractor's outline seen from the petiole (fixed point of w1),
    simplified (Douglas-Peucker) to its lobe tips and sinuses; x across, y along, the petiole at
    (0, 0) and the top lobe's tip at (0, 1)."""
    pts, _ = chaos_game(120_000, seed=0)
    pet = fixed_point(MAPLE_IFS[0])                 # the petiole (0.5, 0.3)
    tip = fixed_point(MAPLE_IFS[1])                 # the top lobe's tip (0.5, 0.93)
    d = pts - pet
    ang = np.arctan2(d[:, 0], d[:, 1])              # 0 along the midrib, + to the right
    r = np.hypot(d[:, 0], d[:, 1])
    bins = np.linspace(0.0, np.pi * 0.97, 60)
    idx = np.digitize(ang, bins)
    half = []
    for k in range(1, len(bins)):
        m = idx == k
        if m.any():
            j = np.argmax(np.where(m, r, -1.0))
            half.append(d[j])
    half = np.array(half)[::-1]                      # from the petiole side up to the tip
    half = np.vstack([[0.0, 0.0], half[half[:, 0] > 0.01], [0.0, tip[1] - pet[1]]])
    keep = _douglas_peucker(half, 8)
    out = half[keep][1:-1] / (tip[1] - pet[1])
    return out


def _douglas_peucker(p, count):
    """Indices of ``count`` points of polyline ``p`` (its ends included) that keep its shape
    best (greedy: add the point farthest from the simplified line)."""
    keep = [0, len(p) - 1]
    while len(keep) < count:
        keep.sort()
        best, best_d = None, -1.0
        for a, b in zip(keep[:-1], keep[1:]):
            if b - a < 2:
                continue
            seg = p[b] - p[a]
            q = p[a + 1:b] - p[a]
            L = max(np.hypot(*seg), 1e-12)
            dist = np.abs(q[:, 0] * seg[1] - q[:, 1] * seg[0]) / L
            j = int(np.argmax(dist))
            if dist[j] > best_d:
                best, best_d = a + 1 + j, dist[j]
        if best is None:
            break
        keep.append(best)
    return sorted(keep)


def half_outline(shape: str) -> np.ndarray:
    """The right half of a blade's margin, petiole to tip (both left out).

    Parameters
    ----------
    shape : str
        ``"ovate"``, ``"deltoid"``, ``"elliptic"``, ``"lanceolate"``, ``"oak"`` or ``"maple"``.

    Returns
    -------
    numpy.ndarray
        (n, 2) margin points (x across >= 0, y along), the petiole at (0, 0) and the tip at
        (0, 1) [-, per blade length].

    Raises
    ------
    ParameterError
        For an unknown shape.
    """
    if shape == "ovate":
        return _halfwidth_outline(5, 0.30, 0.38)
    if shape == "elliptic":
        return _halfwidth_outline(5, 0.24, 0.5)
    if shape == "lanceolate":
        return _halfwidth_outline(5, 0.11, 0.3, tip_point=0.3)
    if shape == "deltoid":
        return _deltoid()
    if shape == "oak":
        return _oak()
    if shape == "maple":
        return _maple()
    raise ParameterError("leaf shape", shape, "one of " + ", ".join(SHAPES))


#: the leaf outlines (:func:`leaf_template`)
SHAPES = ("ovate", "deltoid", "elliptic", "lanceolate", "oak", "maple")


def _zipper(margin, rib):
    """Triangles between a half's margin points (petiole and tip left out) and the midrib
    (petiole ... tip): the strip from the edge petiole-first margin point to the edge last
    margin point-tip, at each step the shorter diagonal; (n − 1) + (len(rib) − 1) triangles
    (local indices: ("m", i) margin, ("r", j) midrib)."""
    nm, nr = len(margin), len(rib)
    i = j = 0
    tris = []
    while i < nm - 1 or j < nr - 1:
        adv_m = j == nr - 1 or (i < nm - 1 and
                                np.linalg.norm(margin[i + 1] - rib[j]) <=
                                np.linalg.norm(margin[i] - rib[j + 1]))
        if adv_m:
            tris.append((("m", i), ("m", i + 1), ("r", j)))
            i += 1
        else:
            tris.append((("m", i), ("r", j + 1), ("r", j)))
            j += 1
    return tris


@lru_cache(maxsize=64)
def leaf_template(shape: str = "ovate", variant: int = 0,
                  curl: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One blade of unit size: vertices and faces in the leaf's frame (module docstring).

    The half outline (:func:`half_outline`) and its mirror image are joined to the midrib
    (petiole, a station at 0.45 of the length, tip) by strips of triangles; the relief of the
    variant is added (fold about the midrib, cup, arch) and the blade scaled to the area
    :data:`LEAF_AREA` and centred on its area centroid.

    Parameters
    ----------
    shape : str, optional
        The outline (:data:`SHAPES`; default ``"ovate"``).
    variant : int, optional
        0..:data:`VARIANTS` − 1: the relief (default 0).
    curl : float, optional
        More cup and arch (a leaf drying on the ground curls): added to the variant's cup and
        twice to its arch [-] (default 0).

    Returns
    -------
    vertices : numpy.ndarray
        (k, 3) float64 [per size]: x across, y from the petiole to the tip, z along the normal.
    faces : numpy.ndarray
        (t, 3) int64, counter-clockwise seen from +z (normals along the leaf's normal).
    """
    half = half_outline(shape)
    v = int(variant) % VARIANTS
    # relief of the variant: fold [per unit distance from the midrib], cup [per x^2], arch
    fold, cup, arch = ((0.22, 0.25, 0.10), (0.32, 0.10, 0.16), (0.14, 0.45, 0.06),
                       (0.26, 0.30, 0.20))[v]
    cup, arch = cup + float(curl), arch + 2.0 * float(curl)
    rib = np.array([[0.0, 0.0], [0.0, 0.45], [0.0, 1.0]])     # petiole, midrib, tip
    nr = len(rib)
    n = len(half)
    # vertices: midrib (nr), right margin (n), left margin (n)
    verts2 = np.vstack([rib, half, half * [-1.0, 1.0]])
    faces = []
    for side, off in (("right", nr), ("left", nr + n)):
        chain = half * ([1.0, 1.0] if side == "right" else [-1.0, 1.0])
        for tri in _zipper(chain, rib):
            faces.append([off + k if kind == "m" else k for kind, k in tri])
    faces = np.array(faces, np.int64)
    x, y = verts2[:, 0], verts2[:, 1]
    z = fold * np.abs(x) + cup * x * x - arch * 4.0 * (y - 0.5) ** 2
    V = np.stack([x, y, z], 1)
    # the right orientation (+z seen counter-clockwise) for every face
    nrm = np.cross(V[faces[:, 1]] - V[faces[:, 0]], V[faces[:, 2]] - V[faces[:, 0]])
    flip = nrm[:, 2] < 0
    faces[flip] = faces[flip][:, ::-1]
    area, centroid = _area_centroid(V, faces)
    V = (V - centroid) * np.sqrt(LEAF_AREA / area)
    return V, faces


def _area_centroid(V, F):
    p = V[F]
    a = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    c = p.mean(1)
    return float(a.sum()), (a[:, None] * c).sum(0) / a.sum()


def triangle_areas(vertices, faces) -> np.ndarray:
    """Areas of triangles.

    Parameters
    ----------
    vertices : numpy.ndarray
        (v, 3) vertices [m].
    faces : numpy.ndarray
        (f, 3) vertex indices.

    Returns
    -------
    numpy.ndarray
        (f,) areas [m2].
    """
    p = np.asarray(vertices, float)[np.asarray(faces)]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def leaf_shape_of(tree) -> str:
    """The outline of a tree's leaves: its Weber-Penn preset's (:data:`PRESET_OUTLINE`), else
    ``"ovate"`` (the growth model's broadleaf, the simple tree's).

    Parameters
    ----------
    tree : Tree
        The tree (``tree.weber_penn.params.name`` for a Weber-Penn tree).

    Returns
    -------
    str
        A name of :data:`SHAPES`.
    """
    wp = getattr(tree, "weber_penn", None)
    name = getattr(getattr(wp, "params", None), "name", None) if wp is not None else None
    return PRESET_OUTLINE.get(str(name), "ovate")


def leaf_frames(normal, up):
    """Orthonormal frames (side, up, normal) of blades.

    Parameters
    ----------
    normal : numpy.ndarray
        (m, 3) blade normals.
    up : numpy.ndarray or None
        (m, 3) blade axes (petiole -> tip), made perpendicular to the normal; None: an axis
        perpendicular to the normal and to x (or z).

    Returns
    -------
    side, up, normal : numpy.ndarray
        (m, 3) unit vectors each, side = up x normal (a right-handed frame: side x up =
        normal).
    """
    nrm = np.asarray(normal, float)
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    if up is None:
        ref = np.where((np.abs(nrm[:, 0]) < 0.9)[:, None], [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
        u = np.cross(nrm, ref)
    else:
        u = np.asarray(up, float)
        u = u - (u * nrm).sum(1, keepdims=True) * nrm
    bad = np.linalg.norm(u, axis=1) < 1e-9
    if bad.any():
        ref = np.where((np.abs(nrm[bad, 0]) < 0.9)[:, None], [[1.0, 0.0, 0.0]],
                       [[0.0, 0.0, 1.0]])
        u[bad] = np.cross(nrm[bad], ref)
    u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-30)
    return np.cross(u, nrm), u, nrm


def blade_mesh(position, normal, up, size, shape: str = "ovate", variant=None,
               dtype=np.float32, curl: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Meshes of many leaves of one outline: a template copy per leaf (module docstring).

    Parameters
    ----------
    position : numpy.ndarray
        (m, 3) leaf centres [m].
    normal : numpy.ndarray
        (m, 3) blade normals.
    up : numpy.ndarray or None
        (m, 3) blade axes (petiole -> tip), or None.
    size : numpy.ndarray
        (m,) blade sizes [m]: each blade's area is :data:`LEAF_AREA` size² [m2].
    shape : str, optional
        The outline (:data:`SHAPES`).
    variant : numpy.ndarray, optional
        (m,) relief variant of each leaf; default: the leaf's index modulo :data:`VARIANTS`
        (scrambled).
    dtype : numpy dtype, optional
        Of the vertices (default float32).
    curl : float, optional
        Extra curl of every blade (:func:`leaf_template`; default 0).

    Returns
    -------
    vertices : numpy.ndarray
        (m k, 3) vertices [m], leaf i's k vertices consecutive.
    faces : numpy.ndarray
        (m t, 3) uint32 faces, leaf i's t faces consecutive.
    """
    m = len(size)
    tmpl = [leaf_template(shape, v, float(curl)) for v in range(VARIANTS)]
    k, t = len(tmpl[0][0]), len(tmpl[0][1])
    if m == 0:
        return np.zeros((0, 3), dtype), np.zeros((0, 3), np.uint32)
    if variant is None:
        variant = (np.arange(m, dtype=np.uint64) * np.uint64(2654435761) >> np.uint64(7)) \
            % np.uint64(VARIANTS)
    variant = np.asarray(variant, np.int64)
    T = np.stack([v for v, _ in tmpl]).astype(np.float32)          # (V, k, 3)
    side, u, nrm = leaf_frames(normal, up)
    s = np.asarray(size, np.float32)[:, None]
    # per leaf: centre + size (x side + y up + z normal); (m, k, 3) built in k passes
    verts = np.empty((m, k, 3), dtype)
    pos = np.asarray(position, np.float32)
    side, u, nrm = (a.astype(np.float32) * s for a in (side, u, nrm))
    for j in range(k):
        Tj = T[:, j][variant]                                      # (m, 3): no (m, k, 3) copy
        verts[:, j] = pos + Tj[:, 0:1] * side + Tj[:, 1:2] * u + Tj[:, 2:3] * nrm
    # the templates' faces are the same for every variant (same outline)
    F = tmpl[0][1]
    faces = (F[None].astype(np.uint32) + (k * np.arange(m, dtype=np.uint32))[:, None, None])
    return verts.reshape(-1, 3), faces.reshape(-1, 3)
