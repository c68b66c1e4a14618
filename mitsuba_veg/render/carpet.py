"""The moss carpet of the render: every living moss covers its spot-grid cell.

Paper 000's moss lives on a spot grid (:class:`mitsuba_veg.moss.spatial.SpotGrid`): cubic cells of
side ``size`` (the run's ``moss.size``) with at most one moss each, and the simulation's cover of
a triangle is ``min(n size² / area, 1)``. The render draws that cover exactly: each moss gets one
patch, the part of the surface under its cell seen along the axis closest to its normal (the
cell's square in the two other coordinates, lifted onto the surface). Patches of neighbouring
cells share their edges, so a closed population is a closed carpet without gaps or overlaps, an
isolated moss covers ``size²`` and a triangle's drawn cover equals its simulated cover.

Each patch is a 3 x 3 lattice (9 vertices, 8 triangles):

- the corners and edge midpoints are jittered in the plane by noise keyed on their grid
  position, so two patches that share an edge jitter it alike (no cracks) and an isolated
  patch is an irregular octagon of about ``size²`` (zero-mean jitter) rather than a square;
- every vertex is put on the terrain by a short ray cast along the cell's axis (the tangent plane
  of the moss where the ray finds nothing), then lifted off it along the normal: shared vertices
  by a small height keyed on their grid position (the carpet's relief), the centre by a cushion
  height that grows with the moss's total growth G_moss (eq 3.21);
- a per-vertex ``tone`` in [0, 1] (1/f noise over the carpet, the growth, lighter at the centre)
  blends the species' dark and light spectral reflectances, as for the tufts.

The tufts (:mod:`mitsuba_veg.render.moss`) stand on the carpet for the relief seen up close; the carpet gives the
cover seen from afar.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from .noise import pink_noise

__all__ = ["CarpetMesh", "grid_origin", "carpet_patches", "cell_keys", "patch_area",
           "moss_texture", "PATCH_VERTICES", "PATCH_FACES", "TEXTURE_TILE", "BUMP_SCALE"]

#: vertices of one patch: a 3 x 3 lattice in the cell's plane (i along a, j along b)
PATCH_VERTICES = 9
#: a fan around the centre (vertex 4): 8 triangles over the lattice's ring
_RING = [0, 1, 2, 5, 8, 7, 6, 3]
#: the patch's 8 triangles (vertex indices), a fan around the centre
PATCH_FACES = np.array([[4, _RING[k], _RING[(k + 1) % 8]] for k in range(8)], np.int64)
#: side of the carpet's shoot texture in the scene [m] (it repeats)
TEXTURE_TILE = 0.08
#: height of the carpet's bump map [m] at texture height 1: Mitsuba's ``bumpmap`` displaces
#: the surface by ``scale x h`` in the units of its position over texture coordinates, here
#: metres. Shoot tips ~1 mm high on ~1.1 mm radii tilt the shading normals by up to ~45 deg:
#: the carpet shows relief and, seen from above under the sun, reflects 0.97-1.04 times its
#: smooth blend (tests/test_render_carpet.py); a centimetre of relief would darken it to
#: half, as sunlit moss is not
BUMP_SCALE = 0.001
_LI = np.array([0, 1, 2, 0, 1, 2, 0, 1, 2])     # lattice step along a (half cells)
_LJ = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2])     # ... along b


@dataclass
class CarpetMesh:
    """The carpet patches of one species merged: vertices (v, 3) float32 [m], faces (f, 3)
    uint32, tone (v,) float32 in [0, 1], shading normals (v, 3) float32, texture coordinates
    (v, 2) float32 (the cell plane's coordinates / :data:`TEXTURE_TILE`), and the number of
    patches."""

    species: str
    vertices: np.ndarray
    faces: np.ndarray
    tone: np.ndarray
    normals: np.ndarray
    uv: np.ndarray
    count: int


def grid_origin(terrain_lo, size: float) -> np.ndarray:
    """The spot grid's origin for a terrain whose meshes start at ``terrain_lo``.

    The daily loop's grid starts 1.5 cells below the terrain meshes' bounding box
    (:meth:`mitsuba_veg.daily.site.DaySite.new_grid`, :class:`~mitsuba_veg.moss.spatial.SpotGrid`),
    so cell boundaries lie at ``origin + k size``.

    Parameters
    ----------
    terrain_lo : array_like
        Lower corner of the terrain meshes' bounding box (3,) [m].
    size : float
        The run's moss size (the cell) [m].

    Returns
    -------
    numpy.ndarray
        The origin (3,) [m].
    """
    return np.asarray(terrain_lo, np.float64) - 1.5 * float(size)


@functools.lru_cache(maxsize=4)
def moss_texture(res: int = 512, seed: int = 0, shoot_px: float = 7.0,
                 density: float = 1.0 / 30.0) -> np.ndarray:
    """A tileable height map of moss shoot tips in [0, 1] (its side is :data:`TEXTURE_TILE`).

    Shoot tips at random texels (``density`` per texel, heights 0.6-1.4), each a rounded bump of
    radius ``shoot_px`` (``(1 - (r / shoot_px)²)^1.5``), summed by a periodic convolution (FFT),
    so the map tiles without seams; ``tanh`` keeps dense clusters from saturating. With the
    defaults a tip is ~1.1 mm in radius, as a moss shoot's.

    Parameters
    ----------
    res : int, optional
        Texels per side (default 512).
    seed : int, optional
        Seed (default 0).
    shoot_px : float, optional
        Radius of a shoot tip [texels] (default 7).
    density : float, optional
        Shoot tips per texel [-] (default 1/30).

    Returns
    -------
    numpy.ndarray
        (res, res) float32 in [0, 1].
    """
    rng = np.random.default_rng(seed)
    img = np.zeros((res, res))
    n = int(res * res * density)
    ys, xs = rng.integers(0, res, n), rng.integers(0, res, n)
    np.add.at(img, (ys, xs), 0.6 + 0.8 * rng.random(n))
    fy = np.fft.fftfreq(res)[:, None] * res
    fx = np.fft.fftfreq(res)[None, :] * res
    k = np.clip(1.0 - (np.hypot(fy, fx) / shoot_px) ** 2, 0.0, None) ** 1.5
    h = np.fft.irfft2(np.fft.rfft2(img) * np.fft.rfft2(k), s=img.shape)
    h = np.tanh(1.3 * h / np.percentile(h, 99.5))
    return np.clip(h / h.max(), 0.0, 1.0).astype(np.float32)


def _hash01(keys: np.ndarray, stream: int) -> np.ndarray:
    """Uniform [0, 1) values from int64 keys (n, k) and a stream number."""
    h = np.full(len(keys), np.uint64((stream * 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF))
    for c in range(keys.shape[1]):
        h ^= keys[:, c].astype(np.uint64) * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ (h >> np.uint64(31))) * np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(29)
    return (h >> np.uint64(40)).astype(np.float64) / float(1 << 24)


def cell_keys(pos, nrm, origin, size: float):
    """Each moss's cell seen along its dominant axis: (axis d, cell index along a, along b).

    ``d`` is the axis closest to the surface normal, ``a = (d + 1) % 3`` and ``b = (d + 2) % 3``
    the two others; the indices count cells of side ``size`` from ``origin``.

    Parameters
    ----------
    pos, nrm : array_like
        Moss positions [m] and unit normals [-], (n, 3).
    origin : array_like
        The grid origin (3,) [m] (:func:`grid_origin`).
    size : float
        Cell side [m].

    Returns
    -------
    d, ia, ib : numpy.ndarray
        int64 arrays (n,).
    """
    pos = np.asarray(pos, np.float64)
    nrm = np.asarray(nrm, np.float64)
    d = np.argmax(np.abs(nrm), axis=1)
    a, b = (d + 1) % 3, (d + 2) % 3
    r = np.arange(len(pos))
    ia = np.floor((pos[r, a] - origin[a]) / size).astype(np.int64)
    ib = np.floor((pos[r, b] - origin[b]) / size).astype(np.int64)
    return d, ia, ib


def _project(scene, pts, axis_dir, reach):
    """Ray casts from ``pts + reach axis_dir`` along ``-axis_dir`` over ``2 reach``: the hit
    points (n, 3) and whether each ray hit."""
    o = pts + reach[:, None] * axis_dir
    f32 = lambda x: mi.Float(np.ascontiguousarray(x, np.float32))  # noqa: E731
    ray = mi.Ray3f(mi.Point3f(f32(o[:, 0]), f32(o[:, 1]), f32(o[:, 2])),
                   mi.Vector3f(f32(-axis_dir[:, 0]), f32(-axis_dir[:, 1]), f32(-axis_dir[:, 2])))
    ray.maxt = f32(2.0 * reach)
    pi = scene.ray_intersect_preliminary(ray)
    t = np.asarray(pi.t, np.float64)
    hit = np.isfinite(t) & (t < 2.0 * reach)
    return o - np.where(hit, t, 0.0)[:, None] * axis_dir, hit


def _occupied(d, ia, ib):
    """A membership test for cells (d, ia, ib) among the given ones."""
    key = (d.astype(np.int64) << 60) ^ ((ia.astype(np.int64) & 0x3FFFFFFF) << 30) ^ \
        (ib.astype(np.int64) & 0x3FFFFFFF)
    u = np.unique(key)

    def has(dq, aq, bq):
        k = (dq.astype(np.int64) << 60) ^ ((aq.astype(np.int64) & 0x3FFFFFFF) << 30) ^ \
            (bq.astype(np.int64) & 0x3FFFFFFF)
        i = np.clip(np.searchsorted(u, k), 0, len(u) - 1)
        return u[i] == k
    return has


#: lattice points of a patch: the four corners and, for each, its two edge midpoints
_CORNERS = (0, 2, 6, 8)
_MIDS = {1: (0, 2), 3: (0, 6), 5: (2, 8), 7: (6, 8)}            # midpoint: its corners
_ACROSS = {1: (0, -1), 3: (-1, 0), 5: (1, 0), 7: (0, 1)}        # the cell across its edge


def carpet_patches(moss, size: float, origin, scene=None, seed: int = 0,
                   jitter: float = 0.16, rounding: float = 0.3, wobble_edges: float = 0.25,
                   lift: float = 0.05,
                   cushion: float = 0.04, noise_scale: float = 0.16) -> list:
    """One patch per moss over its cell, merged into one mesh per species (module docstring).

    The outline of the carpet is rounded: a patch corner that no other moss's cell shares is
    pulled towards the patch centre by ``rounding`` and the free edge midpoints next to it
    pushed out by ``rounding / (1 - rounding)`` of their distance to the centre, which keeps the
    patch's area (an isolated moss is an octagon of area ``size²``: (1 + m)(1 - k) = 1).

    Parameters
    ----------
    moss : MossSet
        The living moss (:class:`mitsuba_veg.render.moss.MossSet`).
    size : float
        The run's moss size, the spot grid's cell [m].
    origin : array_like
        The spot grid's origin (3,) [m] (:func:`grid_origin`).
    scene : mitsuba.Scene, optional
        The terrain (without moss or trees) to put the patches' vertices on; None: the tangent
        plane of each moss.
    seed : int, optional
        Seed of the jitter, relief and tone (default 0).
    jitter : float, optional
        In-plane jitter of the lattice points as a fraction of ``size`` [-] (default 0.16).
    rounding : float, optional
        How far a free corner is pulled in, as a fraction of its distance to the patch centre
        [-] (default 0.3; 0 gives square outlines).
    wobble_edges : float, optional
        Random bulge (or dent) of a free edge's midpoint, as a fraction of its distance to the
        patch centre [-] (default 0.25; zero mean).
    lift : float, optional
        Mean height of the shared vertices above the surface as a fraction of ``size`` [-]
        (default 0.05, varied by +-50 % by noise).
    cushion : float, optional
        Largest height of a patch's centre above its edge, for an established moss, as a fraction
        of ``size`` [-] (default 0.04).
    noise_scale : float, optional
        Largest wavelength of the tone's 1/f noise [m] (default 0.16).

    Returns
    -------
    list of CarpetMesh
        One mesh per species present, in species-index order.

    Raises
    ------
    ParameterError
        If ``size`` is not a positive length, ``jitter`` is outside [0, 0.25] or ``rounding``
        outside [0, 0.45].
    """
    if not (size > 0 and np.isfinite(size)):
        raise ParameterError("size", size, "> 0 [m]", "the moss size of the run, e.g. 0.01")
    if not 0.0 <= jitter <= 0.25:
        raise ParameterError("jitter", jitter, "[0, 0.25] (a fraction of the cell)")
    if not 0.0 <= rounding <= 0.45:
        raise ParameterError("rounding", rounding, "[0, 0.45] (a fraction of the half-diagonal)")
    n = len(moss)
    if n == 0:
        return []
    origin = np.asarray(origin, np.float64)
    pos, nrm = moss.pos, moss.nrm
    d, ia, ib = cell_keys(pos, nrm, origin, size)
    a, b = (d + 1) % 3, (d + 2) % 3
    has = _occupied(d, ia, ib)
    # in-plane lattice offsets from the cell centre, in half cells (-1, 0, 1)
    oa = np.tile(_LI - 1.0, (n, 1))
    ob = np.tile(_LJ - 1.0, (n, 1))
    pulled = np.zeros((n, PATCH_VERTICES), bool)
    for c in _CORNERS:
        sa, sb = int(_LI[c]) - 1, int(_LJ[c]) - 1           # -1 or +1: the corner's side
        others = has(d, ia + sa, ib) | has(d, ia, ib + sb) | has(d, ia + sa, ib + sb)
        pulled[:, c] = ~others
        oa[:, c] = np.where(pulled[:, c], sa * (1.0 - rounding), sa)
        ob[:, c] = np.where(pulled[:, c], sb * (1.0 - rounding), sb)
    push = rounding / (1.0 - rounding)
    cell_keys4 = np.stack([d, ia, ib, np.full(n, seed)], 1)
    for m_, (c0, c1) in _MIDS.items():
        da, db = _ACROSS[m_]
        free = ~has(d, ia + da, ib + db)
        f = np.where(free, 0.5 * (pulled[:, c0].astype(float) + pulled[:, c1]), 0.0)
        # a free edge also bulges or dents at random (zero mean: the area is kept on average),
        # so a carpet's outline does not follow the grid
        wobble = np.where(free, wobble_edges * (2.0 * _hash01(cell_keys4, 20 + m_) - 1.0), 0.0)
        oa[:, m_] *= 1.0 + push * f + wobble
        ob[:, m_] *= 1.0 + push * f + wobble
    # lattice coordinates of the 9 points in half cells: shared by neighbouring cells' patches
    la = 2 * ia[:, None] + _LI[None, :]
    lb = 2 * ib[:, None] + _LJ[None, :]
    dd = np.repeat(d[:, None], PATCH_VERTICES, 1)
    keys = np.stack([dd.ravel(), la.ravel(), lb.ravel(), np.full(dd.size, seed)], 1)
    ja = (_hash01(keys, 1) - 0.5) * 2.0 * jitter
    jb = (_hash01(keys, 2) - 0.5) * 2.0 * jitter
    ca = (origin[a][:, None] + size * (ia[:, None] + 0.5 + 0.5 * oa)).ravel() + ja * size
    cb = (origin[b][:, None] + size * (ib[:, None] + 0.5 + 0.5 * ob)).ravel() + jb * size
    # onto the moss's tangent plane: x_d from n . (x - p) = 0
    rows = np.repeat(np.arange(n), PATCH_VERTICES)
    A, B, D = a[rows], b[rows], d[rows]
    p, nn = pos[rows], nrm[rows]
    r9 = np.arange(len(rows))
    pts = np.empty((len(rows), 3))
    pts[r9, A] = ca
    pts[r9, B] = cb
    nd = nn[r9, D]
    pts[r9, D] = p[r9, D] - (nn[r9, A] * (ca - p[r9, A]) + nn[r9, B] * (cb - p[r9, B])) / nd
    if scene is not None:
        ax = np.zeros_like(pts)
        ax[r9, D] = np.sign(nd)
        hit_pts, hit = _project(scene, pts, ax, np.full(len(pts), 0.75 * size))
        pts = np.where(hit[:, None], hit_pts, pts)
    # relief: shared points by a height keyed on their grid point, the centre by the growth
    centre = np.tile(np.arange(PATCH_VERTICES) == 4, n)
    g = np.maximum(moss.growth[rows], 0.0)
    grown = 1.0 - np.exp(-g / 4.0)
    h_shared = lift * (0.5 + _hash01(keys, 3))
    h = np.where(centre, lift + cushion * (0.3 + 0.7 * grown) * (0.7 + 0.6 * _hash01(keys, 4)),
                 h_shared) * size
    verts = pts + h[:, None] * nn
    # tone: a continuous field over the carpet (1/f noise at the vertex: neighbours agree, so
    # no cell pattern), older moss a little darker
    nz = pink_noise(verts, noise_scale, octaves=5, seed=seed + 11)
    tone = np.clip(0.5 + 0.55 * nz - 0.2 * np.exp(-g / 3.0), 0.0, 1.0)
    # shading normals: the surface normal tilted by a smooth field (the same at a shared point
    # in every patch), so the carpet shades as a bumpy surface without facets or seams
    t1 = np.cross(nn, np.where(np.abs(nn[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]]))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nn, t1)
    bump = 0.45
    sn = nn + bump * (pink_noise(verts, 0.25 * noise_scale, octaves=3, seed=seed + 12)[:, None]
                      * t1 + pink_noise(verts, 0.25 * noise_scale, octaves=3,
                                        seed=seed + 13)[:, None] * t2)
    sn /= np.linalg.norm(sn, axis=1, keepdims=True)
    # texture coordinates: the cell plane's own coordinates, continuous across patches
    uv = np.stack([ca, cb], 1) / TEXTURE_TILE
    out = []
    names = moss.species_names
    for si in np.unique(moss.species):
        sel = np.nonzero(moss.species == si)[0]
        vi = (sel[:, None] * PATCH_VERTICES + np.arange(PATCH_VERTICES)[None, :]).ravel()
        # the lattice's winding faces +axis d; a patch whose moss faces -d (the west, north or
        # under side of a rock or log) is wound the other way, so that its geometric normal
        # agrees with its shading normals (a bump map turns its frame to the geometric normal:
        # against the shading normals the patch rendered black)
        back = nrm[sel, d[sel]] < 0
        faces = np.where(back[:, None, None], PATCH_FACES[None][:, :, [0, 2, 1]],
                         PATCH_FACES[None])
        f = faces + (PATCH_VERTICES * np.arange(len(sel)))[:, None, None]
        name = names[si] if si < len(names) else f"species{si}"
        out.append(CarpetMesh(name, verts[vi].astype(np.float32),
                              f.reshape(-1, 3).astype(np.uint32), tone[vi].astype(np.float32),
                              sn[vi].astype(np.float32), uv[vi].astype(np.float32),
                              len(sel)))
    return out


def patch_area(mesh: CarpetMesh) -> np.ndarray:
    """Area of each patch of a carpet mesh [m²] (its 8 triangles).

    Parameters
    ----------
    mesh : CarpetMesh
        A species' carpet.

    Returns
    -------
    numpy.ndarray
        (count,) [m²].
    """
    v = mesh.vertices.astype(np.float64)[mesh.faces.astype(np.int64)]
    a = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    return a.reshape(-1, len(PATCH_FACES)).sum(1)

