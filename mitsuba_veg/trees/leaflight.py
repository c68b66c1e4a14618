"""Light at leaf spheres (paper 001 §2.3.1, eqs 2.1-2.4), traced with Mitsuba.

The celestial sphere around every leaf sphere is divided into H (longitude) x V (latitude)
cells of equal angular size; cell (h, v) has the unit direction N(h, v) to its centre, solid
angle S(h, v) and unobstructed intensity B0 = C1 = C above the horizon, C2 = 1 below (eq 2.1,
C = C1/C2 eq 2.2). A ray from the sphere's centre towards a cell is attenuated by the factor α
for every *other* leaf sphere it passes through (α is the transmitted fraction, see
docs/deviations.md), and a ray that hits an obstacle takes the obstacle's reflected light
C2 x env (:mod:`mitsuba_veg.trees.environment`). Then, per band (light α_l, red α_r,
far-red α_fr):

    received = Σ B(h,v) S(h,v) / Σ B0(h,v) S(h,v)                       (eq 2.3)
    light vector = Σ N B S / ``|Σ N B S|``   (with the light band α_l)       (eq 2.4)

Counting the spheres a ray passes — three engines that make the same decisions:

- ``"grid"`` (the default): a Dr.Jit kernel walks a uniform grid of sphere lists (cell 2R,
  3D-DDA) and tests the spheres listed in each cell it crosses, counting a sphere in the cell
  that holds its entry point (t = 0 for a sphere containing the origin). Obstacles: one Mitsuba
  ``ray_intersect_preliminary`` per ray gives the distance up to which spheres count.
- ``"mitsuba"``: all leaf spheres of all trees form one Mitsuba ``ellipsoids`` shape
  (closed-form ellipsoid primitive, one BVH, in the same scene as the obstacle meshes). Its
  intersection reports only *entering* hits (it culls the far side of a sphere containing the
  ray origin), so a symbolic Dr.Jit loop casts, counts a sphere hit, re-spawns the ray just
  inside that sphere and casts again: one cast per sphere passed, + 1 for the escape or the
  obstacle hit. Spheres containing the ray origin are counted once per sphere with a k-d tree.
- ``"analytic"``: every ray against every sphere in a Dr.Jit loop (O(rays x spheres)).

``grid`` and ``analytic`` agree exactly; Mitsuba's float32 ellipsoid test differs on a few
grazing rays. ``grid`` was measured 2-4x faster than ``mitsuba`` from one tree to a 10 x 10
forest (benchmarks/trees_growth.py). A ray stops once every band is attenuated below ``cutoff``
(it could only add < cutoff x its cell's weight).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees.voxel import dda_advance, dda_start

__all__ = ["Sky", "LeafLight", "inside_counts", "sphere_grid", "leaf_sphere_light",
           "obstacle_sky_light"]

#: "no triangle" marker of the kernels
_NONE = 0xFFFFFFFF


@dataclass(frozen=True)
class Sky:
    """The H x V celestial sphere of paper 001 (C = C1/C2, C2 = 1)."""

    H: int = 10
    V: int = 10
    C: float = 1.5

    def __post_init__(self):
        if int(self.H) != self.H or self.H < 2:
            raise ParameterError("sky_h", self.H, "an integer >= 2", "e.g. 10 (paper table 3.1)")
        if int(self.V) != self.V or self.V < 2 or self.V % 2:
            raise ParameterError("sky_v", self.V, "an even integer >= 2 (half above, half below "
                                 "the horizon)", "e.g. 10 (paper table 3.1)")
        if not self.C > 0:
            raise ParameterError("light_ratio", self.C, "> 0 (C = C1/C2)")

    def cells(self):
        """The sky cells of eq 2.1 (cached per (H, V, C)).

        M = H x V cells, +y up, ordered latitude-major from the zenith.

        Returns
        -------
        directions : numpy.ndarray
            (M, 3) unit directions N(h, v) to the cell centres [-].
        solid_angles : numpy.ndarray
            (M,) solid angles S(h, v) [sr] (summing to 4 pi).
        upper : numpy.ndarray
            (M,) bool, True above the horizon.
        B0 : numpy.ndarray
            (M,) unobstructed intensity [-]: C1 = C above the horizon, C2 = 1 below.
        """
        key = (self.H, self.V, self.C)
        if key not in _CELL_CACHE:
            H, V = int(self.H), int(self.V)
            th0 = np.arange(V) * math.pi / V
            th1 = th0 + math.pi / V
            thc = th0 + 0.5 * math.pi / V
            phc = (np.arange(H) + 0.5) * 2 * math.pi / H
            TH, PH = np.meshgrid(thc, phc, indexing="ij")
            N = np.stack([np.sin(TH) * np.cos(PH), np.cos(TH), np.sin(TH) * np.sin(PH)], -1)
            S = np.repeat((2 * math.pi / H) * (np.cos(th0) - np.cos(th1)), H)
            upper = np.repeat(np.arange(V) < V // 2, H)
            B0 = np.where(upper, float(self.C), 1.0)
            _CELL_CACHE[key] = (N.reshape(-1, 3), S, upper, B0)
        return _CELL_CACHE[key]

    @property
    def M(self) -> int:
        """Number of sky cells M = H x V."""
        return int(self.H) * int(self.V)


_CELL_CACHE: dict = {}


@dataclass
class LeafLight:
    """Light at N leaf spheres: ``received[band]`` (N,) (eq 2.3), ``vector`` (N, 3) unit
    (eq 2.4, light band), and the cost: rays, ray casts, seconds."""

    received: dict
    vector: np.ndarray
    rays: int = 0
    casts: int = 0
    seconds: float = 0.0
    spheres_passed: float = 0.0           # mean spheres counted per ray
    stats: dict = field(default_factory=dict)

    def ratio(self, num="red", den="far_red") -> np.ndarray:
        """Ratio of two bands' received light per sphere (e.g. red / far-red, eq 2.5).

        Parameters
        ----------
        num : str, optional
            Numerator band (default ``"red"``).
        den : str, optional
            Denominator band (default ``"far_red"``).

        Returns
        -------
        numpy.ndarray
            (N,) ratio [-]; 0 where the denominator is 0.
        """
        d = self.received[den]
        return np.where(d > 0, self.received[num] / np.maximum(d, 1e-300), 0.0)


def _vec3(a, cls=None):
    cls = cls or mi.Point3f
    a = np.ascontiguousarray(np.asarray(a, np.float32).reshape(-1, 3))
    return cls(mi.Float(a[:, 0]), mi.Float(a[:, 1]), mi.Float(a[:, 2]))


def inside_counts(centers, radius) -> np.ndarray:
    """For every sphere, the number of *other* spheres (same radius) containing its centre.

    Parameters
    ----------
    centers : array_like
        (N, 3) sphere centres [m].
    radius : float
        Common sphere radius [m].

    Returns
    -------
    numpy.ndarray
        (N,) int64 counts.
    """
    centers = np.asarray(centers, float)
    n = len(centers)
    cnt = np.zeros(n, np.int64)
    if n < 2:
        return cnt
    try:
        from scipy.spatial import cKDTree
        pairs = cKDTree(centers).query_pairs(r=radius * (1 - 1e-9), output_type="ndarray")
        if len(pairs):
            np.add.at(cnt, pairs[:, 0], 1)
            np.add.at(cnt, pairs[:, 1], 1)
        return cnt
    except ImportError:  # pragma: no cover - scipy comes with pvlib
        for a in range(0, n, 2048):
            d2 = ((centers[a:a + 2048, None, :] - centers[None, :, :]) ** 2).sum(-1)
            cnt[a:a + 2048] = (d2 < radius * radius).sum(1) - 1
        return cnt


# --------------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------------
@dr.syntax
def _count_loop(scene, o, d, kmax, sphere_rid, lookup, eps):
    """Cast, count a sphere hit, re-spawn inside it, repeat (see module docstring)."""
    k = mi.UInt32(0)
    tri = mi.UInt32(_NONE)
    casts = mi.UInt32(0)
    active = kmax > 0
    while dr.hint(active, label="veg_leaf_sphere_count"):
        pi = scene.ray_intersect_preliminary(mi.Ray3f(o, d), coherent=False, active=active)
        casts += dr.select(active, mi.UInt32(1), mi.UInt32(0))
        hit = active & pi.is_valid()
        rid = dr.reinterpret_array(mi.UInt32, pi.shape)
        sph = hit & (rid == sphere_rid)
        obs = hit & ~sph
        tri = dr.select(obs, dr.gather(mi.UInt32, lookup, rid, obs) + pi.prim_index, tri)
        k = dr.select(sph, k + 1, k)
        o = dr.select(sph, o + d * (pi.t + eps), o)
        active = sph & (k < kmax)
    return k, tri, casts


@dr.syntax
def _brute_loop(o, d, own, centers, n, r2, tmax):
    """Count, for every ray, the spheres it passes (all spheres tested), before ``tmax``."""
    j = mi.UInt32(0)
    k = mi.UInt32(0)
    while dr.hint(j < n, label="veg_leaf_sphere_brute"):
        c = dr.gather(mi.Point3f, centers, j)
        w = c - o
        b = dr.dot(w, d)
        ww = dr.dot(w, w)
        disc = r2 - (ww - b * b)
        inside = ww < r2
        tnear = b - dr.sqrt(dr.maximum(disc, 0.0))
        hit = (inside & (j != own)) | (~inside & (disc > 0) & (tnear > 0) & (tnear < tmax))
        k += dr.select(hit, mi.UInt32(1), mi.UInt32(0))
        j += 1
    return k


@dr.syntax
def _grid_loop(o, d, own, tmax, kmax, q, cell_start, cell_items, centers, r2, h, nx, ny, nz):
    """Count the spheres each ray passes, walking a uniform grid of sphere lists (3D-DDA).

    Each iteration either tests one sphere listed in the current cell or steps to the next
    cell. A sphere is counted in the cell that contains its entry point (t = 0 for a sphere
    containing the origin), so spheres listed in several cells count once."""
    (ix, iy, iz), (sx, sy, sz), (tdx, tdy, tdz), (tmx, tmy, tmz) = dda_start(q, d, h)
    inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & (iz >= 0) & (iz < nz)
    cidx = mi.UInt32(ix + nx * (iy + ny * iz))
    j = dr.gather(mi.UInt32, cell_start, cidx, inside)
    jend = dr.gather(mi.UInt32, cell_start, cidx + 1, inside)
    t_in = mi.Float(-1.0)
    t_out = dr.minimum(tmx, dr.minimum(tmy, tmz))
    k = mi.UInt32(0)
    steps = mi.UInt32(0)
    active = inside & (kmax > 0)
    while dr.hint(active, label="veg_leaf_sphere_grid"):
        steps += 1
        item = active & (j < jend)
        s = dr.gather(mi.UInt32, cell_items, j, item)
        c = dr.gather(mi.Point3f, centers, s, item)
        w = c - o
        b = dr.dot(w, d)
        ww = dr.dot(w, w)
        disc = r2 - (ww - b * b)
        ins = ww < r2
        tn = dr.select(ins, 0.0, b - dr.sqrt(dr.maximum(disc, 0.0)))
        hit = item & (s != own) & (ins | ((disc > 0) & (tn > 0))) & (tn >= t_in) \
            & (tn < t_out) & (tn < tmax)
        k = dr.select(hit, k + 1, k)
        j = dr.select(item, j + 1, j)
        adv = active & ~item
        (ix, iy, iz), (tmx, tmy, tmz) = dda_advance((ix, iy, iz), (sx, sy, sz),
                                                    (tdx, tdy, tdz), (tmx, tmy, tmz), adv)
        t_in = dr.select(adv, t_out, t_in)
        t_out = dr.select(adv, dr.minimum(tmx, dr.minimum(tmy, tmz)), t_out)
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & (iz >= 0) & (iz < nz)
        cidx = mi.UInt32(ix + nx * (iy + ny * iz))
        j = dr.select(adv, dr.gather(mi.UInt32, cell_start, cidx, adv & ok), j)
        jend = dr.select(adv, dr.gather(mi.UInt32, cell_start, cidx + 1, adv & ok), jend)
        active = active & ok & (k < kmax) & (t_in < tmax)
    return k, steps


def sphere_grid(centers, radius, cell=None):
    """Uniform grid of sphere lists, for the ``"grid"`` engine.

    Every sphere is listed in each cell its bounding box overlaps. Cell size 2R by default:
    R minimises sphere tests per unit of ray length, but most rays spend their steps crossing
    empty cells on the way out, and 2R measured as fast or faster (benchmarks/trees_growth.py).
    Cells grow (x 1.5 at a time) until the grid has at most 16M cells.

    Parameters
    ----------
    centers : array_like
        (N, 3) sphere centres [m].
    radius : float
        Common sphere radius R [m].
    cell : float, optional
        Cell edge length [m]; default None: 2R.

    Returns
    -------
    origin : numpy.ndarray
        (3,) lower corner of the grid [m].
    cell : float
        Cell edge length used [m].
    shape : tuple of int
        Cells per axis (nx, ny, nz).
    cell_start : numpy.ndarray
        (ncell + 1,) uint32 offsets into ``items`` of each cell's list (cell index
        ix + nx (iy + ny iz)).
    items : numpy.ndarray
        uint32 sphere ids, grouped by cell.
    """
    c = np.asarray(centers, float).reshape(-1, 3)
    h = float(2.0 * radius if cell is None else cell)
    lo = c.min(0) - radius - 1e-3 * h
    hi = c.max(0) + radius + 1e-3 * h
    shape = np.maximum(np.ceil((hi - lo) / h).astype(np.int64), 1)
    # keep the grid bounded (very sparse scenes): grow cells until <= 16M cells
    while np.prod(shape) > 16_000_000:
        h *= 1.5
        shape = np.maximum(np.ceil((hi - lo) / h).astype(np.int64), 1)
    i0 = np.floor((c - radius - lo) / h).astype(np.int64)
    i1 = np.floor((c + radius - lo) / h).astype(np.int64)
    i0 = np.clip(i0, 0, shape - 1)
    i1 = np.clip(i1, 0, shape - 1)
    span = int((i1 - i0).max()) + 1
    offs = np.stack(np.meshgrid(*[np.arange(span)] * 3, indexing="ij"), -1).reshape(-1, 3)
    cells, ids = [], []
    for off in offs:
        ijk = i0 + off
        ok = np.all(ijk <= i1, axis=1)
        ijk = ijk[ok]
        cells.append(ijk[:, 0] + shape[0] * (ijk[:, 1] + shape[1] * ijk[:, 2]))
        ids.append(np.nonzero(ok)[0])
    cells = np.concatenate(cells)
    ids = np.concatenate(ids)
    order = np.argsort(cells, kind="stable")
    ncell = int(np.prod(shape))
    start = np.zeros(ncell + 1, np.int64)
    np.add.at(start, cells + 1, 1)
    start = np.cumsum(start)
    return lo, h, tuple(int(v) for v in shape), start.astype(np.uint32), \
        ids[order].astype(np.uint32)


def _rays(centers_dr, dirs_dr, n_rays, m):
    idx = dr.arange(mi.UInt32, n_rays)
    s = idx // dr.opaque(mi.UInt32, m)
    c = idx - s * dr.opaque(mi.UInt32, m)
    return s, dr.gather(mi.Point3f, centers_dr, s), dr.gather(mi.Vector3f, dirs_dr, c)


def _obstacle_table(scene, env):
    """(registry id of the leaf-sphere shape or NONE, lookup registry id -> triangle offset)."""
    reg = np.asarray(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()), np.int64)
    lookup = np.zeros(int(reg.max()) + 1 if len(reg) else 1, np.uint32)
    sphere_rid = _NONE
    offsets = {}
    if env is not None and len(env):
        counts = [len(o.faces) for o in env.obstacles]
        offs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        offsets = {f"obstacle_{i}": int(offs[i]) for i in range(len(counts))}
    for r, sh in zip(reg, scene.shapes()):
        if sh.id() == "leaf_spheres":
            sphere_rid = int(r)
        else:
            lookup[r] = offsets.get(sh.id(), 0)
    return sphere_rid, mi.UInt32(lookup)


def _sphere_shape(centers, radius):
    n = len(centers)
    data = np.zeros((n, 10), np.float32)
    data[:, 0:3] = centers
    data[:, 3:6] = radius
    data[:, 9] = 1.0      # unit quaternion (a sphere is invariant under any rotation)
    return {"type": "ellipsoids", "id": "leaf_spheres", "data": mi.TensorXf(data.ravel()),
            "extent": 1.0}


def _ray_values(sky, env, k, tri, dirs_idx, alphas, kin_per_ray):
    """Per-ray band values B (rays,) from counts and obstacle hits."""
    N, S, upper, B0 = sky.cells()
    base = B0[dirs_idx].astype(np.float64)
    hit = tri != _NONE
    if hit.any():
        _, _, nrm, _, _, _, lf = env.triangles()
        envv = env.reflected_light(sky)
        t = tri[hit].astype(np.int64)
        front = (nrm[t] * N[dirs_idx[hit]]).sum(1) < 0
        base[hit] = np.where(front, 1.0 * envv[t] * lf[t], 0.0)   # C2 = 1
    ktot = (k.astype(np.int64) + kin_per_ray.astype(np.int64))
    kmax = int(ktot.max()) if len(ktot) else 0
    # α^k by table lookup (k is a small integer)
    return {b: base * (float(a) ** np.arange(kmax + 1))[ktot] for b, a in alphas.items()}


def leaf_sphere_light(centers, radius, sky: Sky, alphas: dict, env=None, engine="grid",
                      cutoff: float = 1e-3, vector_band: str | None = None) -> LeafLight:
    """Light at leaf spheres of radius ``radius`` [m] centred at ``centers`` (N, 3) [m].

    Received light per band (eq 2.3) and light vector (eq 2.4) from the H x V sky, each ray
    attenuated by α per other leaf sphere passed; rays that hit an obstacle take C2 x env of the
    triangle's front (nothing from its back). A sphere centred inside an obstacle receives
    nothing. See the module docstring for the engines.

    Parameters
    ----------
    centers : array_like
        (N, 3) sphere centres [m].
    radius : float
        Common leaf-sphere radius R [m].
    sky : Sky
        The H x V sky (C = C1/C2).
    alphas : dict
        Band -> transmitted fraction per sphere passed [-] (e.g. {"light": 0.3, "red": 0.3,
        "far_red": 0.7}).
    env : mitsuba_veg.trees.environment.Environment, optional
        The obstacles, or None (the default: open sky all round).
    engine : str, optional
        ``"grid"`` (the default), ``"mitsuba"`` or ``"analytic"``.
    cutoff : float, optional
        A ray stops once every band is attenuated below this [-] (default 1e-3; at most 64
        spheres are counted per ray).
    vector_band : str, optional
        Band that gives the light vector; default None: the first band of ``alphas``.

    Returns
    -------
    LeafLight
        ``received[band]`` (N,) [-] (1 = unobstructed sky), unit ``vector`` (N, 3), the cost
        (rays, ray casts, seconds [s], mean spheres passed per ray) and ``stats``.

    Raises
    ------
    ParameterError
        For an unknown ``engine``.
    """
    t0 = time.perf_counter()
    centers = np.asarray(centers, float).reshape(-1, 3)
    n = len(centers)
    bands = list(alphas)
    vb = vector_band or bands[0]
    if n == 0:
        return LeafLight({b: np.zeros(0) for b in bands}, np.zeros((0, 3)))
    if env is not None and not len(env):
        env = None
    N, S, upper, B0 = sky.cells()
    m = sky.M
    n_rays = n * m
    kin = inside_counts(centers, radius)
    amax = max(float(a) for a in alphas.values())
    if amax <= 0:          # opaque spheres: the first one stops the ray (and log(0) is undefined)
        kcap = 1
    elif amax >= 1:
        kcap = 64
    else:
        kcap = int(min(64, max(1, math.ceil(math.log(cutoff) / math.log(amax)))))
    dirs_dr = _vec3(N, mi.Vector3f)
    centers_dr = _vec3(centers)
    eps = float(radius) * 1e-4
    if engine == "mitsuba":
        d = {"type": "scene", "leaf_spheres": _sphere_shape(centers, radius)}
        if env is not None:
            d.update(env.mitsuba_meshes())
        scene = mi.load_dict(d, optimize=False)
        sphere_rid, lookup = _obstacle_table(scene, env)
        kmax_s = mi.UInt32(np.maximum(kcap - kin, 0).astype(np.uint32))
        s, o, dd = _rays(centers_dr, dirs_dr, n_rays, m)
        kmax = dr.gather(mi.UInt32, kmax_s, s)
        k, tri, casts = _count_loop(scene, o, dd, kmax, dr.opaque(mi.UInt32, sphere_rid), lookup,
                                    dr.opaque(mi.Float, eps))
        dr.eval(k, tri, casts)
        k_np = np.asarray(k).astype(np.int64)
        tri_np = np.asarray(tri)
        n_casts = int(np.asarray(casts, np.int64).sum())
        loop_steps = n_casts
    elif engine in ("analytic", "grid"):
        s, o, dd = _rays(centers_dr, dirs_dr, n_rays, m)
        if env is not None:
            scene = env.scene()
            pi = scene.ray_intersect_preliminary(mi.Ray3f(o, dd), coherent=False)
            valid = pi.is_valid()
            tmax = dr.select(valid, pi.t, dr.inf)
            _, lookup = _obstacle_table(scene, env)
            rid = dr.reinterpret_array(mi.UInt32, pi.shape)
            tri = dr.select(valid, dr.gather(mi.UInt32, lookup, rid, valid) + pi.prim_index,
                            mi.UInt32(_NONE))
        else:
            tmax = dr.full(mi.Float, dr.inf, n_rays)
            tri = dr.full(mi.UInt32, _NONE, n_rays)
        r2 = dr.opaque(mi.Float, float(radius) ** 2)
        if engine == "analytic":
            k = _brute_loop(o, dd, s, centers_dr, dr.opaque(mi.UInt32, n), r2, tmax)
            steps = None
        else:
            lo, h, shape, start, items = sphere_grid(centers, radius)
            q = (o - mi.Vector3f(*[dr.opaque(mi.Float, float(v)) for v in lo])) \
                * dr.opaque(mi.Float, 1.0 / h)
            kmax = dr.gather(mi.UInt32, mi.UInt32(np.full(n, kcap, np.uint32)), s)
            k, steps = _grid_loop(o, dd, s, tmax, kmax, q, mi.UInt32(start), mi.UInt32(items),
                                  centers_dr, r2, dr.opaque(mi.Float, h),
                                  *[dr.opaque(mi.Int32, v) for v in shape])
        dr.eval(k, tri) if steps is None else dr.eval(k, tri, steps)
        k_np = np.asarray(k).astype(np.int64)
        tri_np = np.asarray(tri)
        kin = np.zeros(n, np.int64)         # counted by the kernel itself
        n_casts = n_rays if env is not None else 0   # the obstacle casts
        loop_steps = int(np.asarray(steps, np.int64).sum()) if steps is not None \
            else n_rays * n
    else:
        raise ParameterError("engine", engine, "'mitsuba', 'grid' or 'analytic'")
    cell = np.tile(np.arange(m), n)
    kin_ray = np.repeat(kin, m).astype(np.float64)
    vals = _ray_values(sky, env, k_np, tri_np, cell, alphas, kin_ray)
    buried = np.zeros(n, bool)
    if env is not None:
        # a sphere centred inside an obstacle (below the terrain, in a wall) receives nothing
        buried = env.inside(centers)
        if buried.any():
            zero = np.repeat(buried, m)
            for v in vals.values():
                v[zero] = 0.0
    norm = float((B0 * S).sum())
    Sr = np.tile(S, n)
    received = {b: (v * Sr).reshape(n, m).sum(1) / norm for b, v in vals.items()}
    w = (vals[vb] * Sr).reshape(n, m)
    vec = w @ N
    ln = np.linalg.norm(vec, axis=1, keepdims=True)
    vec = np.where(ln > 1e-12, vec / np.maximum(ln, 1e-300), np.array([[0.0, 1.0, 0.0]]))
    return LeafLight(received, vec, n_rays, n_casts, time.perf_counter() - t0,
                     float((k_np + kin_ray).mean()),
                     {"engine": engine, "spheres": n, "k_cap": kcap, "loop_steps": loop_steps,
                      "buried": int(buried.sum())})


# --------------------------------------------------------------------------------------------
# obstacles' own light (paper 001 §2.3.2, generalised to meshes)
# --------------------------------------------------------------------------------------------
def obstacle_sky_light(env, sky: Sky, passes: int = 2) -> np.ndarray:
    """Reflected-light factor env per obstacle triangle (paper 001 §2.3.2, generalised to meshes).

    Sky irradiance (cells weighted by the cosine to the triangle normal) relative to open flat
    ground; rays that hit another obstacle's front take C2 x env x light_factor of the previous
    pass (first pass: 0), rays that hit a back face take 0.

    Parameters
    ----------
    env : mitsuba_veg.trees.environment.Environment
        The obstacles.
    sky : Sky
        The H x V sky.
    passes : int, optional
        Number of passes (default 2; at least 1 is made).

    Returns
    -------
    numpy.ndarray
        (m,) env of every obstacle triangle [-] (order of ``env.triangles()``).
    """
    V, F, nrm, cen, area, obj, lf = env.triangles()
    nt = len(F)
    N, S, upper, B0 = sky.cells()
    m = sky.M
    if nt == 0:
        return np.zeros(0)
    lo, hi = env.bbox()
    eps = max(1e-4, 1e-5 * float(np.linalg.norm(hi - lo)))
    scene = env.scene()
    _, lookup = _obstacle_table(scene, env)
    o_np = cen + eps * nrm
    s, o, d = _rays(_vec3(o_np), _vec3(N, mi.Vector3f), nt * m, m)
    pi = scene.ray_intersect_preliminary(mi.Ray3f(o, d), coherent=False)
    valid = pi.is_valid()
    rid = dr.reinterpret_array(mi.UInt32, pi.shape)
    tri = dr.select(valid, dr.gather(mi.UInt32, lookup, rid, valid) + pi.prim_index,
                    mi.UInt32(_NONE))
    dr.eval(tri)
    tri = np.asarray(tri).reshape(nt, m)
    cosw = np.maximum(nrm @ N.T, 0.0)                       # (nt, m)
    norm = float(sky.C * (S * np.maximum(N[:, 1], 0) * upper).sum())
    hit = tri != _NONE
    front = np.zeros_like(hit)
    th = tri[hit].astype(np.int64)
    front[hit] = (nrm[th] * np.broadcast_to(N, (nt, m, 3))[hit]).sum(1) < 0
    envv = np.zeros(nt)
    for _ in range(max(1, passes)):
        val = np.broadcast_to(B0, (nt, m)).copy()
        val[hit] = 0.0
        fr = hit & front
        val[fr] = envv[tri[fr].astype(np.int64)] * lf[tri[fr].astype(np.int64)]
        envv = (val * S * cosw).sum(1) / norm
    return envv
