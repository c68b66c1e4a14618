"""Voxel-space light (paper 002 §4, after Green 1989), traced by one vectorised 3D-DDA kernel.

Space is cut into cubic voxels of side ``size`` [m]. Every branch tip (a leaf) adds a fixed
shading ``s`` to the voxel containing it; obstacle voxels are opaque. Light at a point = the
sky light reaching it along 36 rays (12 azimuths x 3 elevation bands, centres at 15°, 45°, 75°),
each attenuated voxel by voxel along its path (Amanatides-Woo 3D-DDA, Fujimoto's 3DDDA):

    T_ray = exp(- Σ_voxels τ_v ℓ_v / size),   τ_v = -n_v ln(1 - s)   (opaque: τ = 1e3)
    light = Σ_rays w_ray T_ray,   w = solid angle of the ray's band / 12, Σ w = 1 (open sky = 1)

so a ray crossing a voxel with n tips along a full voxel edge keeps (1 - s)^n of its light.
All rays of all query points run as one Dr.Jit symbolic loop (one kernel per call).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

__all__ = ["OPAQUE_TAU", "TAU_STOP", "sky_rays", "dda_start", "dda_advance", "VoxelSpace",
           "gradient_sampler"]

#: optical depth of an opaque (obstacle) voxel per voxel length
OPAQUE_TAU = 1e3
#: rays stop when their optical depth exceeds this (transmission < 1e-9)
TAU_STOP = 20.7


def sky_rays(azimuths: int = 12, elevations: int = 3):
    """Directions and weights of the paper's sky sampling.

    ``azimuths`` x ``elevations`` rays at the centres of equal-angle bands (elevation 0..90°),
    weighted by the solid angle of their band (sum 1); +y up, azimuth 0 towards -z.

    Parameters
    ----------
    azimuths : int, optional
        Rays per elevation band (default 12).
    elevations : int, optional
        Elevation bands (default 3: centres at 15°, 45°, 75°).

    Returns
    -------
    directions : numpy.ndarray
        (k, 3) unit ray directions [-], k = azimuths x elevations, elevation-major.
    weights : numpy.ndarray
        (k,) weights [-], summing to 1.
    """
    e0 = np.arange(elevations) * (math.pi / 2) / elevations
    e1 = e0 + (math.pi / 2) / elevations
    ec = 0.5 * (e0 + e1)
    az = (np.arange(azimuths) + 0.5) * 2 * math.pi / azimuths
    E, A = np.meshgrid(ec, az, indexing="ij")
    d = np.stack([np.cos(E) * np.sin(A), np.sin(E), -np.cos(E) * np.cos(A)], -1).reshape(-1, 3)
    w = np.repeat(np.sin(e1) - np.sin(e0), azimuths) / azimuths
    return d, w / w.sum()


def dda_start(q, d, h=1.0):
    """Start of a 3D-DDA walk (Amanatides & Woo) from ``q`` along unit directions ``d``.

    Parameters
    ----------
    q : mi.Point3f
        Ray origins in cell units (position relative to the grid corner / cell size) [-].
    d : mi.Vector3f
        Unit ray directions [-].
    h : float or mi.Float, optional
        Cell side [m] (default 1: distances in cell units).

    Returns
    -------
    cell : tuple of mi.Int32
        The start cell (ix, iy, iz).
    step : tuple of mi.Int32
        The step signs (+1 / -1) on each axis.
    td : list of mi.Float
        Ray length per cell along each axis (in the unit of ``h``; 1e30 for an axis the ray is
        parallel to).
    tm : list of mi.Float
        Ray length to the first cell boundary on each axis (same unit).
    """
    ix, iy, iz = (mi.Int32(dr.floor(c)) for c in (q.x, q.y, q.z))
    sx, sy, sz = (dr.select(c > 0, mi.Int32(1), mi.Int32(-1)) for c in (d.x, d.y, d.z))
    big = mi.Float(1e30)
    td = [dr.select(dr.abs(c) > 1e-12, h / dr.abs(c), big) for c in (d.x, d.y, d.z)]
    tm = [dr.select(dr.abs(dc) > 1e-12, (mi.Float(i) + dr.select(dc > 0, 1.0, 0.0) - qc) * h / dc,
                    big) for i, dc, qc in ((ix, d.x, q.x), (iy, d.y, q.y), (iz, d.z, q.z))]
    return (ix, iy, iz), (sx, sy, sz), td, tm


def dda_advance(i, s, td, tm, active=True):
    """One step of the walk of :func:`dda_start`.

    Where ``active``, move to the neighbour cell across the nearest boundary.

    Parameters
    ----------
    i : tuple of mi.Int32
        Current cell (ix, iy, iz).
    s : tuple of mi.Int32
        Step signs of :func:`dda_start`.
    td : tuple of mi.Float
        Ray length per cell along each axis.
    tm : tuple of mi.Float
        Ray length to the next boundary on each axis.
    active : bool or mi.Bool, optional
        Lanes that step (default True: all).

    Returns
    -------
    cell : tuple of mi.Int32
        The new cell (ix, iy, iz).
    tm : tuple of mi.Float
        Ray lengths to the next boundaries on each axis.
    """
    (ix, iy, iz), (sx, sy, sz), (tdx, tdy, tdz), (tmx, tmy, tmz) = i, s, td, tm
    bx = active & (tmx <= tmy) & (tmx <= tmz)
    by = active & ~bx & (tmy <= tmz)
    bz = active & ~bx & ~by
    return ((dr.select(bx, ix + sx, ix), dr.select(by, iy + sy, iy), dr.select(bz, iz + sz, iz)),
            (dr.select(bx, tmx + tdx, tmx), dr.select(by, tmy + tdy, tmy),
             dr.select(bz, tmz + tdz, tmz)))


@dr.syntax
def _dda(q, d, tau_grid, nx, ny, nz, tau_stop):
    """Optical depth along rays starting at q (in voxel units) in unit directions d."""
    (ix, iy, iz), (sx, sy, sz), (tdx, tdy, tdz), (tmx, tmy, tmz) = dda_start(q, d)
    t = mi.Float(0.0)
    tau = mi.Float(0.0)
    steps = mi.UInt32(0)
    active = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & (iz >= 0) & (iz < nz)
    while dr.hint(active, label="veg_voxel_dda"):
        idx = mi.UInt32(ix + nx * (iy + ny * iz))
        s = dr.gather(mi.Float, tau_grid, idx, active)
        tn = dr.minimum(tmx, dr.minimum(tmy, tmz))
        tau += s * (tn - t)
        t = tn
        steps += 1
        (ix, iy, iz), (tmx, tmy, tmz) = dda_advance((ix, iy, iz), (sx, sy, sz),
                                                    (tdx, tdy, tdz), (tmx, tmy, tmz))
        active = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & (iz >= 0) & (iz < nz) \
            & (tau < tau_stop)
    return tau, steps


@dataclass
class VoxelSpace:
    """A voxel grid: ``origin`` (3,) [m] of its corner, voxel ``size`` [m], ``tau`` (nx, ny, nz)
    optical depth per voxel length, ``opaque`` (nx, ny, nz) obstacle mask."""

    origin: np.ndarray
    size: float
    tau: np.ndarray
    opaque: np.ndarray
    shading: float = 0.3
    stats: dict = field(default_factory=dict)

    @property
    def shape(self):
        """Grid shape (nx, ny, nz)."""
        return self.tau.shape

    @staticmethod
    def build(leaf_points, size: float = 0.5, shading=0.3, env=None, bounds=None,
              margin: int = 2, max_voxels: int = 20_000_000) -> "VoxelSpace":
        """Voxels covering ``leaf_points`` (and ``bounds``, and the obstacles of ``env`` near them).

        Each point removes the fraction ``shading`` of the light crossing its voxel along a voxel
        edge (optical depth ``-ln(1 - s)`` per point); obstacle voxels are opaque
        (``OPAQUE_TAU``). Obstacles count from the lowest leaf point up to their top, within the
        horizontal reach of the lowest (15°) rays; ``margin`` voxels are added on every side.

        Parameters
        ----------
        leaf_points : array_like
            (n, 3) leaf (branch tip) positions [m].
        size : float, optional
            Voxel side [m] (default 0.5); > 0.
        shading : float or array_like, optional
            Fraction ``s`` of the light removed per point [-], one value or one per point, each in
            [0, 1) (default 0.3).
        env : mitsuba_veg.trees.environment.Environment, optional
            Obstacles, as opaque voxels (default None: none).
        bounds : tuple of array_like, optional
            (lo, hi), each (3,) [m], a box the grid must also cover (default None).
        margin : int, optional
            Extra voxels on every side (default 2).
        max_voxels : int, optional
            Largest allowed voxel count (default 20,000,000).

        Returns
        -------
        VoxelSpace
            The grid, with ``stats`` (``voxels``, ``leaf_points``).

        Raises
        ------
        ParameterError
            If ``size`` <= 0, a shading is outside [0, 1) or the grid would exceed ``max_voxels``.
        """
        check_range("voxel_size", size, 0.0, None, lo_open=True)
        sh = np.asarray(shading, float)
        if sh.ndim == 0:
            check_range("shading", float(sh), 0.0, 1.0, hi_open=True)
        elif np.any(~(sh >= 0) | ~(sh < 1)):
            raise ParameterError("shading", "per-point values", "each in [0, 1)")
        pts = np.asarray(leaf_points, float).reshape(-1, 3)
        lo = pts.min(0) if len(pts) else np.zeros(3)
        hi = pts.max(0) if len(pts) else np.zeros(3)
        if bounds is not None:
            lo = np.minimum(lo, bounds[0])
            hi = np.maximum(hi, bounds[1])
        rising = None
        if env is not None and len(env):
            V, F = env.triangles()[:2]
            tv = V[F]                                             # (m, 3, 3)
            rising = tv[:, :, 1].max(1) > lo[1] + 1e-6 * size     # parts above the trees' foot
        if rising is not None and rising.any():
            tv = tv[rising].reshape(-1, 3)
            elo, ehi = tv.min(0), tv.max(0)
            # rays go up: obstacles matter from the lowest query point up to their top, within
            # the horizontal reach of the lowest (15 deg) rays
            y0 = lo[1]
            reach = (max(hi[1], ehi[1]) - y0) / math.tan(math.radians(15.0)) + size
            lo = np.minimum(lo, np.maximum(elo, lo - reach))
            hi = np.maximum(hi, np.minimum(ehi, hi + reach))
            lo[1] = y0
        lo = lo - margin * size
        hi = hi + margin * size
        shape = tuple(int(v) for v in np.maximum(np.ceil((hi - lo) / size), 1))
        nvox = int(np.prod(shape))
        if nvox > max_voxels:
            raise ParameterError("voxel_size", size, f"a size giving <= {max_voxels:,} voxels "
                                 f"(this one gives {nvox:,} for {hi - lo} m)",
                                 "use larger voxels")
        tau = np.zeros(shape, np.float64)
        idx = np.floor((pts - lo) / size).astype(np.int64)
        per = -np.log1p(-np.broadcast_to(sh, (len(pts),)))
        np.add.at(tau, (idx[:, 0], idx[:, 1], idx[:, 2]), per)
        opaque = env.voxel_mask(lo, size, shape) if env is not None and len(env) else \
            np.zeros(shape, bool)
        tau = np.where(opaque, OPAQUE_TAU, tau)
        return VoxelSpace(lo, float(size), tau, opaque, float(sh.mean()) if sh.size else 0.0,
                          {"voxels": nvox, "leaf_points": len(pts)})

    # ---- light -------------------------------------------------------------------------------
    def optical_depth(self, points, directions):
        """Optical depth [-] from every point along every direction to the grid's boundary.

        One DDA kernel for all n x k rays; a ray stops once its depth exceeds ``TAU_STOP``.
        Updates ``stats`` (``rays``, ``dda_steps``).

        Parameters
        ----------
        points : array_like
            (n, 3) ray origins [m].
        directions : array_like
            (k, 3) unit directions [-].

        Returns
        -------
        numpy.ndarray
            (n, k) optical depths [-].
        """
        pts = np.asarray(points, float).reshape(-1, 3)
        D = np.asarray(directions, float).reshape(-1, 3)
        n, k = len(pts), len(D)
        if n == 0 or k == 0:
            return np.zeros((n, k))
        q = ((pts - self.origin) / self.size).astype(np.float32)
        idx = dr.arange(mi.UInt32, n * k)
        pi = idx // dr.opaque(mi.UInt32, k)
        ri = idx - pi * dr.opaque(mi.UInt32, k)
        qd = mi.Point3f(*[mi.Float(np.ascontiguousarray(q[:, c])) for c in range(3)])
        dd = mi.Vector3f(*[mi.Float(np.ascontiguousarray(D[:, c].astype(np.float32)))
                           for c in range(3)])
        qq = dr.gather(mi.Point3f, qd, pi)
        rd = dr.gather(mi.Vector3f, dd, ri)
        nx, ny, nz = self.shape
        # flat index ix + nx (iy + ny iz): store the grid with x fastest
        grid = mi.Float(np.ascontiguousarray(self.tau.transpose(2, 1, 0).ravel(), np.float32))
        tau, steps = _dda(qq, rd, grid, dr.opaque(mi.Int32, nx), dr.opaque(mi.Int32, ny),
                          dr.opaque(mi.Int32, nz), dr.opaque(mi.Float, TAU_STOP))
        dr.eval(tau, steps)
        self.stats.update({"rays": n * k, "dda_steps": int(np.asarray(steps, np.int64).sum())})
        return np.asarray(tau, np.float64).reshape(n, k)

    def light(self, points, azimuths: int = 12, elevations: int = 3) -> np.ndarray:
        """Sky light (open sky = 1) at ``points`` from 36 (default) rays each.

        ``light = Σ_rays w_ray exp(-τ_ray)`` (:func:`sky_rays` weights); points inside an obstacle
        voxel get 0. Updates ``stats["light_s"]`` [s].

        Parameters
        ----------
        points : array_like
            (n, 3) points [m].
        azimuths : int, optional
            Rays per elevation band (default 12).
        elevations : int, optional
            Elevation bands (default 3).

        Returns
        -------
        numpy.ndarray
            (n,) light [-] in [0, 1].
        """
        t0 = time.perf_counter()
        pts = np.asarray(points, float).reshape(-1, 3)
        if len(pts) == 0:
            return np.zeros(0)
        D, W = sky_rays(azimuths, elevations)
        tr = np.exp(-self.optical_depth(pts, D))
        q = (pts - self.origin) / self.size
        inside = np.all((q >= 0) & (q < np.array(self.shape)), axis=1)
        # points inside an obstacle voxel get no light
        iv = np.clip(np.floor(q).astype(np.int64), 0, np.array(self.shape) - 1)
        buried = self.opaque[iv[:, 0], iv[:, 1], iv[:, 2]] & inside
        out = tr @ W
        out[buried] = 0.0
        self.stats["light_s"] = time.perf_counter() - t0
        return out

    def centers(self) -> np.ndarray:
        """Centres of all voxels, x-major (index ix ny nz + iy nz + iz).

        Returns
        -------
        numpy.ndarray
            (nx ny nz, 3) voxel centres [m].
        """
        nx, ny, nz = self.shape
        ix, iy, iz = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
        return self.origin + (np.stack([ix, iy, iz], -1).reshape(-1, 3) + 0.5) * self.size

    def light_field(self, **kw) -> np.ndarray:
        """Light at every voxel centre.

        Parameters
        ----------
        **kw : dict
            Keyword arguments of :meth:`light` (``azimuths``, ``elevations``).

        Returns
        -------
        numpy.ndarray
            (nx, ny, nz) light [-] (open sky = 1).
        """
        return self.light(self.centers(), **kw).reshape(self.shape)


def gradient_sampler(field: np.ndarray, origin, size):
    """A sampler of the gradient of a field given on voxel centres.

    The returned function maps points (n, 3) [m] to the trilinear interpolation of the
    finite-difference gradient of ``field`` [field units per m]; zero outside the grid of voxel
    centres (and everywhere for a grid one voxel thick along some axis).

    Parameters
    ----------
    field : numpy.ndarray
        (nx, ny, nz) values on voxel centres (e.g. :meth:`VoxelSpace.light_field`).
    origin : array_like
        (3,) corner of the grid [m].
    size : float
        Voxel side [m].

    Returns
    -------
    callable
        ``sample(points) -> (n, 3)`` gradient [field units per m].
    """
    g = np.stack(np.gradient(field, size), -1) if min(field.shape) > 1 else \
        np.zeros(field.shape + (3,))
    origin = np.asarray(origin, float)
    shape = np.array(field.shape)

    def sample(points):
        p = (np.asarray(points, float).reshape(-1, 3) - origin) / size - 0.5
        i0 = np.floor(p).astype(np.int64)
        f = p - i0
        out = np.zeros((len(p), 3))
        inside = np.all((p >= 0) & (p <= shape - 1), axis=1)
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    ii = np.clip(i0 + [dx, dy, dz], 0, shape - 1)
                    w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                         * (f[:, 2] if dz else 1 - f[:, 2]))
                    out += w[:, None] * g[ii[:, 0], ii[:, 1], ii[:, 2]]
        out[~inside] = 0.0
        return out

    return sample
