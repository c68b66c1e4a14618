"""Leaf litter: the leaves that fell, lying on the ground under their tree, darkening and vanishing.

A leaf that fell (the world's phenology keeps the day, :mod:`mitsuba_veg.world.phenology`; the
calendar phenology of ``[[render.trees]]``, :mod:`mitsuba_veg.render.seasons`, computes it) is
drawn on the ground from that day on. The trees carry, per leaf, ``litter_age`` [days] (days
since the leaf fell on the frame's date; NaN: not fallen, or no record) in ``leaves.attrs``, set
by the seasons objects (:class:`mitsuba_veg.render.world.WorldLeaves`,
:class:`~mitsuba_veg.render.seasons.TreeSeasons`); leaves of an earlier version of a tree (a
world's trees are rebuilt at a year's end when they grow or age) come as
``tree.attrs["litter_extra"]``, a :class:`LitterLeaves`.

**Where it lies** (fixed per leaf, deterministic: hashes of the leaf's index and its tree's):

- xz: the leaf's position plus a drift in a random direction, of length
  :data:`DRIFT` x h x ρ (h: the leaf's height above its tree's base [m]; ρ a Rayleigh variate of
  mean 1.25: leaves fall at 1-2 m s⁻¹ and drift with the wind and their flutter, most land
  within half their height of the point below them);
- y: where a ray cast straight down from above the scene meets the terrain (the scenario's own
  meshes: the ground, logs, rocks, roofs; the Terrain's base scene), 3 mm above it; a leaf whose
  ray misses (off the terrain) is not drawn;
- lying flat on the surface, its normal within 15° of the surface's, turned at random about it,
  curled (:func:`mitsuba_veg.render.leaves.leaf_template` ``curl`` :data:`CURL`), in its tree's
  outline and size (the same area as on the tree).

**Colour and decay** (age a [days] since the fall; the choice and its reasons):

- a stage s from 0 to 1: s = 0.5 min(a / :data:`DRY_DAYS`, 1) while the fallen leaf dries from
  the colour it fell in to the brown of dry litter (anthocyanins and carotenoids break down in a
  few weeks: 45 days), then s = 0.5 + 0.5 min((a − 45) / :data:`DARK_DAYS`, 1) as it darkens
  through the winter towards wet, decomposing litter (135 days more);
- reflectance: the leaf's PROSPECT-D reflectance at τ = 1 (a leaf falls when its raw logical
  time passes its threshold φ, log-normal around 1.25, so its colour at the fall is τ = 1),
  blended linearly to ``litter`` at s = 0.5 and to ``litter_dark`` at s = 1
  (:data:`mitsuba_veg.render.materials.SPECTRA`), two-sided diffuse;
- vanishing: each leaf lasts L = :data:`LIFE_DAYS` (270-330 days, uniform per leaf: broadleaf
  litter loses most of its mass in a year, decomposition rates of 0.5-1.5 per year; and a
  world keeps one fall day per leaf, which the leaf's next fall a year later overwrites, so a
  lifetime under a year never shows a leaf twice), shrinking over its last
  :data:`SHRINK_DAYS` = 60 days (fragmentation) to nothing at L.

The litter is :data:`BINS` meshes ``litter_00`` ... by stage (each with its stage's spectrum;
an empty bin is one degenerate triangle far away), so :meth:`mitsuba_veg.render.scene.
RenderScene.update` swaps their buffers in place frame by frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..foliage import leaf_spectra
from ..meshes import make_mesh
from . import materials as mat
from .leaves import blade_mesh, leaf_frames, leaf_shape_of

__all__ = ["BINS", "DRIFT", "DRY_DAYS", "DARK_DAYS", "LIFE_DAYS", "SHRINK_DAYS", "CURL", "LIFT",
           "TILT", "LitterLeaves", "stage", "lifetime", "size_factor", "stage_spectrum", "place",
           "litter_arrays", "litter_bsdf", "litter_shapes"]

#: stage bins (one mesh each)
BINS = 6
#: drift per metre of fall height [-] (times a Rayleigh variate of mean 1.25)
DRIFT = 0.35
#: days from the fall to dry brown litter (stage 0.5)
DRY_DAYS = 45.0
#: days from dry to dark litter (stage 0.5 -> 1)
DARK_DAYS = 135.0
#: the range of a leaf's lifetime on the ground [days]
LIFE_DAYS = (270.0, 330.0)
#: days over which a leaf shrinks to nothing before its lifetime ends
SHRINK_DAYS = 60.0
#: extra curl of a leaf on the ground (:func:`mitsuba_veg.render.leaves.leaf_template`)
CURL = 0.2
#: height above the surface of a leaf's centre [m]
LIFT = 0.003
#: largest tilt of a leaf from the surface it lies on [rad]
TILT = np.radians(15.0)

_EMPTY_V = np.full((3, 3), -1e4, np.float32)
_EMPTY_F = np.array([[0, 1, 2]], np.uint32)


@dataclass
class LitterLeaves:
    """Fallen leaves of an earlier version of a tree: their blades on the tree and their ages.

    ``position`` (m, 3) [m], ``normal``, ``up`` (m, 3), ``size`` (m,) [m], ``age`` (m,) [days]
    (NaN: no litter), ``base_y`` the tree's base height [m], ``shape`` the outline and ``key``
    a stable id (for the placement cache)."""

    position: np.ndarray
    normal: np.ndarray
    up: np.ndarray | None
    size: np.ndarray
    age: np.ndarray
    base_y: float
    shape: str
    key: tuple


def _hash01(idx, salt: int) -> np.ndarray:
    """Uniform [0, 1) numbers from integer indices (splitmix64 of index and salt)."""
    with np.errstate(over="ignore"):             # (wrapping arithmetic modulo 2^64)
        x = np.asarray(idx, np.uint64) + np.uint64(salt) * np.uint64(0x9E3779B97F4A7C15)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x = x ^ (x >> np.uint64(31))
    return (x >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def stage(age) -> np.ndarray:
    """Darkening stage of litter by its age (module docstring).

    Parameters
    ----------
    age : array_like
        Days since the fall [days].

    Returns
    -------
    numpy.ndarray
        Stage in [0, 1] [-]: 0 fresh, 0.5 dry brown, 1 dark.
    """
    a = np.asarray(age, float)
    return np.where(a <= DRY_DAYS, 0.5 * np.clip(a / DRY_DAYS, 0.0, 1.0),
                    0.5 + 0.5 * np.clip((a - DRY_DAYS) / DARK_DAYS, 0.0, 1.0))


def lifetime(index, salt: int = 0) -> np.ndarray:
    """Each leaf's lifetime on the ground [days] (uniform in :data:`LIFE_DAYS`, by index).

    Parameters
    ----------
    index : array_like
        Leaf indices (within their tree).
    salt : int, optional
        The tree's salt (default 0).

    Returns
    -------
    numpy.ndarray
        Lifetimes [days].
    """
    lo, hi = LIFE_DAYS
    return lo + (hi - lo) * _hash01(index, 7 * salt + 3)


def size_factor(age, life) -> np.ndarray:
    """Size of a leaf on the ground relative to its size on the tree [-]: 1, then shrinking
    linearly over the last :data:`SHRINK_DAYS` of its lifetime to 0.

    Parameters
    ----------
    age, life : array_like
        Days since the fall and the leaf's lifetime [days].

    Returns
    -------
    numpy.ndarray
        Factor in [0, 1] [-] (0 before the fall: negative or NaN age).
    """
    a = np.asarray(age, float)
    f = np.clip((np.asarray(life, float) - a) / SHRINK_DAYS, 0.0, 1.0)
    return np.where(np.isfinite(a) & (a >= 0), f, 0.0)


def stage_spectrum(s: float) -> np.ndarray:
    """Reflectance of litter at stage ``s`` on :data:`~mitsuba_veg.render.materials.WAVELENGTHS`.

    Parameters
    ----------
    s : float
        Stage in [0, 1] (:func:`stage`).

    Returns
    -------
    numpy.ndarray
        Reflectance (95,) [-]: the leaf's PROSPECT-D reflectance at τ = 1 blended linearly to
        ``litter`` at 0.5 and to ``litter_dark`` at 1.
    """
    ls = leaf_spectra(tau=1.0)
    fresh = np.interp(mat.WAVELENGTHS, ls.wavelength, ls.reflectance)   # (flat below 400 nm)
    s = float(np.clip(s, 0.0, 1.0))
    if s <= 0.5:
        return (1 - 2 * s) * fresh + 2 * s * mat.SPECTRA["litter"]
    return (2 - 2 * s) * mat.SPECTRA["litter"] + (2 * s - 1) * mat.SPECTRA["litter_dark"]


def place(terrain, position, base_y: float, salt: int):
    """Where leaves that fell from ``position`` lie (module docstring): ground point and frame.

    Parameters
    ----------
    terrain : Terrain
        The scene's meshes (:class:`mitsuba_veg.render.scene.Terrain`): rays are cast on its
        base scene.
    position : numpy.ndarray
        (m, 3) the leaves' positions on the tree [m].
    base_y : float
        Height of the tree's base [m] (the fall height is y − base_y).
    salt : int
        The tree's salt (deterministic randomness per leaf).

    Returns
    -------
    dict
        ``pos`` (m, 3) float32 centres on the ground [m], ``normal`` and ``up`` (m, 3) float32,
        ``hit`` (m,) bool (the ray met the terrain).
    """
    import mitsuba as mi

    p = np.asarray(position, float)
    m = len(p)
    idx = np.arange(m)
    h = np.maximum(p[:, 1] - base_y, 0.0)
    u1, u2 = _hash01(idx, 11 * salt + 1), _hash01(idx, 11 * salt + 2)
    rho = np.sqrt(-2.0 * np.log(np.maximum(1.0 - u1, 1e-12)))     # Rayleigh, mean 1.25
    phi = 2 * np.pi * u2
    d = DRIFT * h * rho
    x = p[:, 0] + d * np.cos(phi)
    z = p[:, 2] + d * np.sin(phi)
    lo, hi = terrain.bbox()
    y0 = float(hi[1]) + 1.0
    ray = mi.Ray3f(mi.Point3f(mi.Float(x.astype(np.float32)), mi.Float(np.full(m, y0, np.float32)),
                              mi.Float(z.astype(np.float32))),
                   mi.Vector3f(0.0, -1.0, 0.0))
    si = terrain.base_scene.ray_intersect(ray)
    hit = np.asarray(si.is_valid())
    t = np.asarray(si.t, float)
    n = np.stack([np.asarray(si.n.x), np.asarray(si.n.y), np.asarray(si.n.z)], 1).astype(float)
    del si, ray
    n = np.where(hit[:, None], n, [[0.0, 1.0, 0.0]])
    n = np.where((n[:, 1:2] < 0), -n, n)
    y = np.where(hit, y0 - np.where(hit, t, 0.0), 0.0)
    # the blade's normal: the surface's, tilted by up to TILT in a random direction
    s1, s2 = _hash01(idx, 11 * salt + 3), _hash01(idx, 11 * salt + 4)
    tangent, bitangent, n = leaf_frames(n, None)
    tilt = TILT * np.sqrt(s1)
    az = 2 * np.pi * s2
    w = np.cos(az)[:, None] * tangent + np.sin(az)[:, None] * bitangent
    bn = np.cos(tilt)[:, None] * n + np.sin(tilt)[:, None] * w
    # face-up or face-down (the curl cups up or down), turned at random about the normal
    flip = _hash01(idx, 11 * salt + 5) < 0.5
    bn = np.where(flip[:, None], -bn, bn)
    s3 = _hash01(idx, 11 * salt + 6)
    t2, b2, _ = leaf_frames(bn, None)
    up = np.cos(2 * np.pi * s3)[:, None] * t2 + np.sin(2 * np.pi * s3)[:, None] * b2
    pos = np.stack([x, y, z], 1) + LIFT * n
    return {"pos": pos.astype(np.float32), "normal": bn.astype(np.float32),
            "up": up.astype(np.float32), "hit": hit}


def _tree_litter(tree, index: int):
    """The litter sources of one tree: (key, position, size, age, base_y, shape) for its own
    leaves and its earlier version's (``attrs["litter_extra"]``)."""
    out = []
    lv = tree.leaves
    base_y = float(tree.start[0][1]) if len(tree) else float(np.min(lv.position[:, 1], initial=0))
    shape = leaf_shape_of(tree)
    age = lv.attrs.get("litter_age")
    if age is not None and len(lv):
        out.append((("tree", id(tree)), lv.position, lv.size, np.asarray(age, float), base_y,
                    shape, index))
    ex = tree.attrs.get("litter_extra") if isinstance(tree.attrs, dict) else None
    if isinstance(ex, LitterLeaves) and len(ex.size):
        out.append((ex.key, ex.position, ex.size, np.asarray(ex.age, float), ex.base_y,
                    ex.shape, index + 7919))
    return out


def litter_arrays(trees, terrain, options=None, cache=None) -> dict:
    """The litter meshes of the trees' fallen leaves, one per stage bin (module docstring).

    Parameters
    ----------
    trees : list of Tree
        The trees; their leaves' ``litter_age`` attrs (and ``attrs["litter_extra"]``) say which
        leaves lie on the ground and for how long.
    terrain : Terrain
        The scene's meshes (ray casts onto its base scene).
    options : RenderOptions, optional
        Unused (the bins are fixed: :data:`BINS`); for symmetry with the leaves.
    cache : dict, optional
        Placement cache (``{("litter", key): (tree, placement)}``), filled on first use: a
        leaf's place on the ground does not change.

    Returns
    -------
    dict
        ``{"litter_KK": (vertices (v, 3) float32 [m], faces (f, 3) uint32)}`` for the
        :data:`BINS` bins (an empty bin: one degenerate triangle far away), and
        ``"count"``: the litter leaves drawn.
    """
    parts = {b: [] for b in range(BINS)}
    count = 0
    for i, t in enumerate(trees or []):
        for key, position, size, age, base_y, shape, salt in _tree_litter(t, i):
            life = lifetime(np.arange(len(size)), salt)
            f = size_factor(age, life)
            sel = np.nonzero(f > 1e-3)[0]
            if not len(sel):
                continue
            ck = ("litter",) + tuple(key)
            if cache is not None and ck in cache and cache[ck][0] is t:
                pl = cache[ck][1]
            else:
                pl = place(terrain, position, base_y, salt)
                if cache is not None:
                    cache[ck] = (t, pl)
            sel = sel[pl["hit"][sel]]
            if not len(sel):
                continue
            b = np.minimum((stage(age[sel]) * BINS).astype(np.int64), BINS - 1)
            count += len(sel)
            for bb in np.unique(b):
                ls = sel[b == bb]
                v, fc = blade_mesh(pl["pos"][ls], pl["normal"][ls], pl["up"][ls],
                                   size[ls] * f[ls], shape, curl=CURL,
                                   variant=(ls * 2654435761 >> 7) % 4)
                parts[int(bb)].append((v, fc))
    out = {}
    for b in range(BINS):
        sid = f"litter_{b:02d}"
        if not parts[b]:
            out[sid] = (_EMPTY_V, _EMPTY_F)
            continue
        # one copy into the bin's arrays (the faces renumbered by the vertices before)
        verts = np.empty((sum(len(v) for v, _ in parts[b]), 3), np.float32)
        faces = np.empty((sum(len(f) for _, f in parts[b]), 3), np.uint32)
        o = of = 0
        for v, f in parts[b]:
            verts[o:o + len(v)] = v
            faces[of:of + len(f)] = f
            faces[of:of + len(f)] += np.uint32(o)
            o += len(v)
            of += len(f)
        parts[b] = None
        out[sid] = (verts, faces)
    out["count"] = count
    return out


def litter_bsdf(b: int) -> dict:
    """The two-sided diffuse BSDF of stage bin ``b`` (its middle stage's spectrum).

    Parameters
    ----------
    b : int
        Bin 0..:data:`BINS` − 1.

    Returns
    -------
    dict
        ``twosided`` ``diffuse`` with the reflectance of :func:`stage_spectrum` at
        (b + 0.5) / :data:`BINS`.
    """
    return {"type": "twosided",
            "bsdf": mat.diffuse(np.clip(stage_spectrum((b + 0.5) / BINS), 0.0, 0.95))}


def litter_shapes(trees, terrain, options=None, cache=None) -> tuple[dict, dict]:
    """Mitsuba meshes of the litter (:func:`litter_arrays`) and their count.

    Parameters
    ----------
    trees : list of Tree
        The trees.
    terrain : Terrain
        The scene's meshes.
    options : RenderOptions, optional
        Unused.
    cache : dict, optional
        Placement cache of :func:`litter_arrays`.

    Returns
    -------
    shapes : dict
        ``{"litter_KK": mesh}`` for the :data:`BINS` bins.
    info : dict
        ``litter`` (leaves drawn) and ``litter_triangles``.
    """
    arr = litter_arrays(trees, terrain, options, cache)
    count = arr.pop("count")
    out, tri = {}, 0
    for b, (sid, (v, f)) in enumerate(sorted(arr.items())):
        out[sid] = make_mesh(sid, v, f, litter_bsdf(b))
        tri += 0 if f is _EMPTY_F else len(f)
    return out, {"litter": int(count), "litter_triangles": int(tri)}
