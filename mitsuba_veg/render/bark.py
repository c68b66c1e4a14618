"""Wood as the render draws it: branches as smooth swept tubes and a textured bark with relief.

**Swept tubes** (:func:`swept_tubes`, trees without paper 004's junction mesh: paper 001's growth
model, paper 002's and the simple trees). The segments of one branch (a segment and the child
that continues it, :func:`mitsuba_veg.trees.junction.stem_structure`; where a stem ends, its
thickest live child of at least 0.3 of its radius) are chained into one
centreline through their joints (a branch's first point moved back into its parent's tube by
the parent's radius); the radius at a joint is the mean of the two segments' radii
there (continuous). Two rounds of corner cutting (Chaikin, a quarter of each edge) round every
joint (a kink of angle a becomes four of about a / 4 over the joint's neighbourhood; the ends stay).
Rings of ``S`` corners follow the centreline in parallel-transport frames (each ring's frame is
the previous one projected onto the new cross-section: no twist), ``S`` from the branch's base
radius (:data:`SIDES`). The tips are closed by a fan to a point half a radius past the end
(flat where thinner branches go on from the end).
Vertex normals are the rings' radial directions (smooth shading).

**UVs** (both here and in :func:`mitsuba_veg.trees.junction.tree_mesh`): u around the stem
(0..1), v along it in units of the stem's base circumference, so that one unit of (u, v) is a
square on the bark: the bark texture keeps its aspect on thick and thin stems.

**Bark** (:func:`bark_bsdf`): a reflectance between the ``bark`` (furrows) and ``bark_light``
(ridges) spectra (:data:`mitsuba_veg.render.materials.SPECTRA`), blended by a procedural furrow
texture (:func:`bark_texture`: narrow furrows along the stem between broad ridges that meander,
split and join, from 1/f noise; periodic in u and v), and relief from the same height field as
a tangent-space ``normalmap`` (:func:`bark_normals`: slopes per circumference, so the relief
looks the same on thick and thin stems), all two-sided.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..trees.junction import stem_structure
from . import materials as mat

__all__ = ["SIDES", "FURROWS", "RELIEF", "swept_tubes", "bark_texture", "bark_normals",
           "bark_bsdf"]

#: corners of a tube by the branch's base radius [m]: (radius >= r: S)
SIDES = ((0.06, 14), (0.025, 10), (0.008, 7), (0.0, 5))
#: furrows around a stem in the bark texture (one texture tile is one circumference square)
FURROWS = 9
#: depth of the bark's relief per stem circumference [-] (furrows 1.5 % of the circumference
#: deep: 9 mm on a trunk 0.6 m round)
RELIEF = 0.015


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _chains(tree):
    """(head segment, position in its chain) of every alive segment: chains of segments that
    continue their parent's stem."""
    st = stem_structure(tree)
    n = len(tree)
    alive = tree.alive
    par = tree.parent
    cont = st["cont"] & alive
    # a segment whose own stem ends there (its apex stopped) is continued by its thickest live
    # child when that child is at least 0.3 of its radius (a sympodial axis, tapering into it:
    # no tip and collar)
    has = np.zeros(n, bool)
    has[par[cont]] = True
    cand = np.nonzero(alive & (par >= 0) & ~cont)[0]
    cand = cand[alive[par[cand]] & ~has[par[cand]]
                & (tree.radius_start[cand] >= 0.3 * tree.radius_end[par[cand]])]
    if len(cand):
        order = cand[np.lexsort((tree.radius_start[cand], par[cand]))]   # thickest last
        best = np.full(n, -1)
        best[par[order]] = order
        cont = cont.copy()
        cont[best[best >= 0]] = True
    head = np.where(cont, par, np.arange(n))
    pos = cont.astype(np.int64)
    # pointer jumping: log2(chain length) rounds over all segments at once
    while True:
        nxt = head[head]
        if np.array_equal(nxt, head):
            break
        pos = pos + np.where(head != np.arange(n), pos[head], 0)
        head = nxt
    return head, pos, st


def _chaikin(P, R, m):
    """One round of corner cutting on padded chains.

    P (c, L, 3) points, R (c, L) radii, m (c,) valid points per chain (>= 2). Returns the new
    arrays and counts: the ends kept, each inner point replaced by two at a quarter of its
    edges."""
    c, L = R.shape
    L2 = 2 * L - 2
    P2 = np.zeros((c, L2, 3))
    R2 = np.zeros((c, L2))
    P2[:, 0], R2[:, 0] = P[:, 0], R[:, 0]
    # inner point i (1..m-2) -> 2i-1 (towards i-1), 2i (towards i+1)
    i = np.arange(1, L - 1)
    P2[:, 2 * i - 1] = 0.75 * P[:, i] + 0.25 * P[:, i - 1]
    P2[:, 2 * i] = 0.75 * P[:, i] + 0.25 * P[:, i + 1]
    R2[:, 2 * i - 1] = 0.75 * R[:, i] + 0.25 * R[:, i - 1]
    R2[:, 2 * i] = 0.75 * R[:, i] + 0.25 * R[:, i + 1]
    m2 = 2 * m - 2
    rows = np.arange(c)
    P2[rows, m2 - 1] = P[rows, m - 1]
    R2[rows, m2 - 1] = R[rows, m - 1]
    return P2, R2, m2


def _sides(r):
    s = np.full(len(r), SIDES[-1][1])
    for lo, k in SIDES[::-1]:
        s = np.where(r >= lo, k, s)
    return s


def swept_tubes(tree, rounds: int = 2, min_radius: float = 0.0):
    """The tree's branches as smooth swept tubes (module docstring).

    Parameters
    ----------
    tree : Tree
        The tree (alive segments are drawn).
    rounds : int, optional
        Rounds of corner cutting at the joints (default 2; 0: mitred polylines).
    min_radius : float, optional
        Lower bound on the drawn radii [m] (default 0).

    Returns
    -------
    vertices : numpy.ndarray
        (v, 3) [m].
    faces : numpy.ndarray
        (f, 3) int64, outward (counter-clockwise seen from outside).
    uv : numpy.ndarray
        (v, 2): u around (0..1), v along in base circumferences [-].
    normals : numpy.ndarray
        (v, 3) unit vertex normals.
    """
    empty = (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 2)), np.zeros((0, 3)))
    alive = tree.alive
    if not alive.any():
        return empty
    head, pos, st = _chains(tree)
    segs = np.nonzero(alive)[0]
    h, p = head[segs], pos[segs]
    heads, cid = np.unique(h, return_inverse=True)
    nc = len(heads)
    nseg = np.bincount(cid, minlength=nc)
    L = int(nseg.max()) + 1
    P = np.zeros((nc, L, 3))
    R = np.zeros((nc, L))
    r0 = np.maximum(tree.radius_start, min_radius)
    r1 = np.maximum(tree.radius_end, min_radius)
    P[cid, p + 1] = tree.end[segs]
    # a branch starts inside its parent (moved back along itself by the parent's radius there,
    # at most half its first segment): its open base hides in the parent's tube, whose
    # centreline the corner cutting has moved off the node
    par_h = tree.parent[heads]
    has_par = (par_h >= 0) & alive[np.maximum(par_h, 0)]
    back = np.where(has_par, np.minimum(r1[np.maximum(par_h, 0)], 0.5 * st["length"][heads]),
                    0.0)
    P[np.arange(nc), 0] = tree.start[heads] - back[:, None] * st["dir"][heads]
    # radius at a joint: the mean of the two segments' radii there
    R[cid, p + 1] = r1[segs]
    # (at most 0.9 of the parent's radius there: a fork's second stem does not stand out as a
    # collar where it leaves its parent)
    R[np.arange(nc), 0] = np.where(has_par, np.minimum(r0[heads],
                                                       0.9 * r1[np.maximum(par_h, 0)]),
                                   r0[heads])
    inner = p > 0
    R[cid[inner], p[inner]] = 0.5 * (R[cid[inner], p[inner]] + r0[segs[inner]])
    m = nseg + 1
    # pad each chain with its last point (the cuts then leave the pads on the end point)
    last = P[np.arange(nc), m - 1]
    pad = np.arange(L)[None, :] >= m[:, None]
    P = np.where(pad[..., None], last[:, None, :], P)
    R = np.where(pad, R[np.arange(nc), m - 1][:, None], R)
    for _ in range(int(rounds)):
        P, R, m = _chaikin(P, R, m)
        L = P.shape[1]
        pad = np.arange(L)[None, :] >= m[:, None]
        last = P[np.arange(nc), m - 1]
        P = np.where(pad[..., None], last[:, None, :], P)
        R = np.where(pad, R[np.arange(nc), m - 1][:, None], R)
    L = P.shape[1]
    valid = ~(np.arange(L)[None, :] >= m[:, None])
    # tangents: central differences (one-sided at the ends)
    T = np.zeros_like(P)
    T[:, 1:-1] = P[:, 2:] - P[:, :-2]
    T[:, 0] = P[:, 1] - P[:, 0]
    rows = np.arange(nc)
    T[rows, m - 1] = P[rows, m - 1] - P[rows, m - 2]
    T = _unit(T)
    # parallel transport: the first frame's u from the parent's direction (else +x)
    par = tree.parent[heads]
    ref = np.where((par >= 0)[:, None], st["dir"][np.maximum(par, 0)], [[1.0, 0.0, 0.0]])
    U = np.zeros_like(P)
    u = ref - (ref * T[:, 0]).sum(1, keepdims=True) * T[:, 0]
    bad = np.linalg.norm(u, axis=1) < 1e-6
    alt = np.where((np.abs(T[:, 0, 0]) < 0.9)[:, None], [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    u[bad] = np.cross(T[bad, 0], alt[bad])
    U[:, 0] = _unit(u)
    for j in range(1, L):
        u = U[:, j - 1] - (U[:, j - 1] * T[:, j]).sum(1, keepdims=True) * T[:, j]
        U[:, j] = _unit(u)
    V = np.cross(T, U)
    # arc length along the chain, in base circumferences
    seg_len = np.linalg.norm(np.diff(P, axis=1), axis=2)
    arc = np.concatenate([np.zeros((nc, 1)), np.cumsum(seg_len, 1)], 1)
    circ = 2 * np.pi * np.maximum(R[:, 0], 1e-6)
    vcoord = arc / circ[:, None]
    S_chain = _sides(R[:, 0])
    # chains whose last segment has live children (their ends are closed flat)
    kids = np.zeros(len(tree), bool)
    kids[tree.parent[alive & (tree.parent >= 0)]] = True
    last_seg = np.zeros(nc, np.int64)
    last_seg[cid[p == nseg[cid] - 1]] = segs[p == nseg[cid] - 1]
    forked = kids[last_seg]
    # the valid points, flat (chain-major): ring r of chain c is flat row off[c] + r
    off = np.r_[0, np.cumsum(m)[:-1]]
    Pf, Rf, Uf, Vf = P[valid], R[valid], U[valid], V[valid]
    vf = vcoord[valid]
    cf = np.repeat(np.arange(nc), m)
    verts, faces, uvs, nrms = [], [], [], []
    nv = 0
    for S in np.unique(S_chain):
        selc = np.nonzero(S_chain == S)[0]
        pts = np.nonzero(S_chain[cf] == S)[0]           # flat points of these chains
        local = np.full(len(Pf), -1)
        local[pts] = np.arange(len(pts))
        th = 2 * np.pi * np.arange(S + 1) / S
        cs, sn = np.cos(th), np.sin(th)
        radial = cs[None, :, None] * Uf[pts][:, None, :] + sn[None, :, None] * Vf[pts][:, None, :]
        ring = Pf[pts][:, None, :] + Rf[pts][:, None, None] * radial
        uvr = np.stack(np.broadcast_arrays((np.arange(S + 1) / S)[None, :], vf[pts][:, None]),
                       -1)
        # faces between consecutive rings of a chain
        first = off[selc]
        cnt = m[selc]
        nxt_ok = np.ones(len(pts), bool)
        last_of = local[first + cnt - 1]
        nxt_ok[last_of] = False
        ra = np.nonzero(nxt_ok)[0]
        k = np.arange(S)
        oa = nv + ra[:, None] * (S + 1)
        ob = oa + (S + 1)
        q = np.stack([np.stack([oa + k, oa + k + 1, ob + k + 1], -1),
                      np.stack([oa + k, ob + k + 1, ob + k], -1)], 1).reshape(-1, 3)
        verts.append(ring.reshape(-1, 3))
        nrms.append(radial.reshape(-1, 3))
        uvs.append(uvr.reshape(-1, 2))
        faces.append(q)
        base = nv
        nv += len(pts) * (S + 1)
        # tip caps: a fan to a point half a tip radius past the end (flat where thinner
        # branches go on from the end)
        tip = first + cnt - 1
        tipT, tipR = T[selc, cnt - 1], Rf[tip]
        apex = Pf[tip] + (0.5 * tipR * ~forked[selc])[:, None] * tipT
        ai = nv + np.arange(len(selc))
        o = base + last_of[:, None] * (S + 1)
        fan = np.stack([o + k, o + k + 1, np.broadcast_to(ai[:, None], (len(selc), S))], -1)
        verts.append(apex)
        nrms.append(tipT)
        uvs.append(np.stack([np.full(len(selc), 0.5), vf[tip] + 0.5 * tipR / circ[selc]], 1))
        faces.append(fan.reshape(-1, 3))
        nv += len(selc)
    V_ = np.concatenate(verts)
    F_ = np.concatenate(faces).astype(np.int64)
    # outward: the frames are right-handed (T, U, V): ring order k -> k+1 turns about T;
    # orient every face by the vertex normals
    pv = V_[F_]
    fn = np.cross(pv[:, 1] - pv[:, 0], pv[:, 2] - pv[:, 0])
    wrong = (fn * np.concatenate(nrms)[F_].sum(1)).sum(1) < 0
    F_[wrong] = F_[wrong][:, ::-1]
    return V_, F_, np.concatenate(uvs), np.concatenate(nrms)


# ---- texture --------------------------------------------------------------------------------
def _pink(shape, rng, slope=1.6):
    """Periodic 1/f^slope noise in [0, 1] (FFT)."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.fftfreq(w)[None, :]
    f = np.sqrt(fx ** 2 + fy ** 2)
    f[0, 0] = 1.0
    spec = (rng.normal(size=shape) + 1j * rng.normal(size=shape)) / f ** slope
    spec[0, 0] = 0.0
    x = np.real(np.fft.ifft2(spec))
    x = (x - x.min()) / max(float(np.ptp(x)), 1e-12)
    return x


@lru_cache(maxsize=4)
def bark_texture(resolution: int = 256, furrows: int = FURROWS, seed: int = 0):
    """A periodic furrowed-bark tile: one circumference square of the (u, v) of the tubes.

    Narrow furrows run along the stem (v) between broad, flat ridges; the furrows' phase
    meanders with 1/f noise of v (and a little of u), so that they wander, split and join; a
    second noise varies each ridge's height and weathering along it (plates), a third adds
    grain. The images tile (periodic in u and v).

    Parameters
    ----------
    resolution : int, optional
        Tile size [px] (default 256).
    furrows : int, optional
        Furrows around the stem (default :data:`FURROWS`).
    seed : int, optional
        Noise seed (default 0).

    Returns
    -------
    tone : numpy.ndarray
        (resolution, resolution) float32 in [0, 1]: 1 on a ridge's weathered top (light bark),
        0 in a furrow (dark bark); rows are v, columns u.
    height : numpy.ndarray
        (resolution, resolution) float32 in [0, 1]: the relief (0 at the bottom of a furrow).
    """
    rng = np.random.default_rng(seed)
    n = int(resolution)
    warp = _pink((n, n), rng, 2.4) - 0.5
    plates = _pink((n, n), rng, 1.8)
    grain = _pink((n, n), rng, 1.2) - 0.5
    u = np.arange(n)[None, :] / n
    phase = furrows * u + 1.8 * warp
    # distance from the nearest furrow in half periods (0 in a furrow, 1 mid-ridge)
    d = np.abs(np.sin(np.pi * phase))
    ridge = np.clip(d / 0.8, 0.0, 1.0) ** 0.8                    # broad flat ridges
    # plates: each ridge's height and weathering vary along it (the plate noise, stretched
    # along v by sampling it at the ridge's index and v)
    k = np.floor(phase).astype(np.int64) % furrows
    rows = np.arange(n)[:, None]
    plate = plates[(rows * 1 + 0) % n, (k * n // furrows) % n]
    height = ridge * (0.7 + 0.3 * plate) + 0.06 * grain
    height = (height - height.min()) / max(float(np.ptp(height)), 1e-12)
    tone = np.clip(0.1 + 0.75 * ridge * (0.35 + 0.65 * plate) + 0.35 * grain, 0.0, 1.0)
    return tone.astype(np.float32), height.astype(np.float32)


def bark_normals(height, depth: float = RELIEF) -> np.ndarray:
    """Tangent-space normals of the bark's relief (for Mitsuba's ``normalmap``).

    The relief is ``depth`` x height in units of the stem's circumference (the tile's size), so
    its slopes are the same on thick and thin stems: n = normalise(−depth ∂h/∂u, −depth ∂h/∂v,
    1) with u, v in tile units (periodic differences).

    Parameters
    ----------
    height : numpy.ndarray
        (n, n) height field in [0, 1] (rows v, columns u), periodic.
    depth : float, optional
        Relief depth per circumference [-] (default :data:`RELIEF`).

    Returns
    -------
    numpy.ndarray
        (n, n, 3) float32 in [0, 1]: (n + 1) / 2 as the ``normalmap`` plugin reads it.
    """
    h = np.asarray(height, float)
    n = h.shape[0]
    du = (np.roll(h, -1, 1) - np.roll(h, 1, 1)) * (n / 2.0)
    dv = (np.roll(h, -1, 0) - np.roll(h, 1, 0)) * (n / 2.0)
    nrm = np.stack([-depth * du, -depth * dv, np.ones_like(h)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return (0.5 * (nrm + 1.0)).astype(np.float32)


def _bitmap(img):
    import mitsuba as mi
    a = np.ascontiguousarray(np.asarray(img, np.float32))
    a = a[..., None] if a.ndim == 2 else a
    return {"type": "bitmap", "bitmap": mi.Bitmap(a), "raw": True, "filter_type": "bilinear",
            "wrap_mode": "repeat"}


def bark_bsdf(relief: bool = True, dark: str = "bark", light: str = "bark_light") -> dict:
    """The bark's BSDF dict: textured reflectance and relief, two-sided (module docstring).

    Parameters
    ----------
    relief : bool, optional
        Wrap the reflectance in a ``normalmap`` of the bark's relief (:func:`bark_normals`;
        default True).
    dark, light : str, optional
        Spectra (:data:`~mitsuba_veg.render.materials.SPECTRA`) of the furrows and the ridges
        (default ``"bark"``, ``"bark_light"``).

    Returns
    -------
    dict
        ``twosided`` (``normalmap`` (``blendbsdf``)) for ``mi.load_dict``; meshes need the tube
        UVs of the module docstring.
    """
    tone, height = bark_texture()
    b = mat.blend(mat.diffuse(dark), mat.diffuse(light), _bitmap(tone))
    if relief:
        b = {"type": "normalmap", "normalmap": _bitmap(bark_normals(height)), "bsdf": b}
    return {"type": "twosided", "bsdf": b}
