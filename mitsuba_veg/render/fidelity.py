"""How faithfully a render shows the run's moss: drawn cover against simulated cover.

The simulation's cover of a terrain triangle is ``min(n size² / area, 1)`` (n living moss on it,
``size`` the run's moss size; :meth:`mitsuba_veg.daily.moss.DayMoss.cover`). The render's cover of
the same triangle is the share of its visible pixels that show moss, told apart from soil by the
normalised difference of the far-red and red bands the film records anyway::

    NDVI = (L_fr - L_r) / (L_fr + L_r),   moss where NDVI > 0.45

(chlorophyll absorbs red and reflects far-red; soil, sand, concrete and bark stay far below 0.45
in daylight). Each pixel is assigned to the terrain triangle its centre ray meets in the terrain
alone (no moss, no trees); pixels whose ray meets a tree first are left out.

:func:`cover_comparison` gives both per triangle and the two summary numbers of
``benchmarks/render_moss_cover.py``: the ratio of drawn to simulated moss area and the mean
absolute difference over the mossy triangles.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError

__all__ = ["NDVI_MOSS", "simulated_cover", "pixel_rays", "pixel_triangles", "moss_pixels",
           "cover_counts", "cover_summary", "cover_comparison", "triangle_areas"]

#: NDVI above which a pixel shows moss [-]
NDVI_MOSS = 0.45


def _hit_ids(scene, si_shape) -> np.ndarray:
    """Index into ``scene.shapes()`` of each hit's shape (-1 for a miss)."""
    reg = np.asarray(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()))
    shp = np.asarray(dr.reinterpret_array(mi.UInt32, si_shape))
    order = np.argsort(reg)
    pos = np.clip(np.searchsorted(reg[order], shp), 0, len(reg) - 1)
    return np.where(reg[order][pos] == shp, order[pos], -1).astype(np.int64)


def triangle_areas(v, f) -> np.ndarray:
    """Triangle areas of a mesh.

    Parameters
    ----------
    v : array_like
        Vertices (n, 3) [m].
    f : array_like
        Faces (m, 3).

    Returns
    -------
    numpy.ndarray
        Areas (m,) [m²].
    """
    p = np.asarray(v, np.float64)[np.asarray(f, np.int64)]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def simulated_cover(terrain, moss, size: float, shape: str = "ground") -> np.ndarray:
    """The simulation's cover of each triangle of a terrain mesh: ``min(n size² / area, 1)``.

    Each moss is assigned to the triangle under it (a 6 mm ray from 2 mm above it, down its
    normal), as the daily loop holds it on its element.

    Parameters
    ----------
    terrain : Terrain
        The run's terrain (:class:`mitsuba_veg.render.scene.Terrain`).
    moss : MossSet
        The living moss.
    size : float
        The run's moss size [m].
    shape : str, optional
        The terrain mesh (default ``"ground"``).

    Returns
    -------
    numpy.ndarray
        Cover (triangles,) [-].

    Raises
    ------
    ParameterError
        If the terrain has no mesh ``shape``.
    """
    if shape not in terrain.meshes:
        raise ParameterError("shape", shape, "a terrain mesh: " + ", ".join(terrain.meshes))
    v, f = terrain.meshes[shape][0], terrain.meshes[shape][1]
    area = triangle_areas(v, f)
    n = np.zeros(len(f))
    if len(moss):
        o = moss.pos + moss.nrm * 2e-3
        f32 = lambda x: mi.Float(np.ascontiguousarray(x, np.float32))  # noqa: E731
        ray = mi.Ray3f(mi.Point3f(*[f32(o[:, k]) for k in range(3)]),
                       mi.Vector3f(*[f32(-moss.nrm[:, k]) for k in range(3)]))
        ray.maxt = mi.Float(6e-3)
        pi = terrain.base_scene.ray_intersect_preliminary(ray)
        ids = _hit_ids(terrain.base_scene, pi.shape)
        names = [s.id() for s in terrain.base_scene.shapes()]
        k = names.index(shape)
        on = (ids == k) & np.isfinite(np.asarray(pi.t))
        prim = np.asarray(pi.prim_index, np.int64)[on]
        n = np.bincount(prim, minlength=len(f)).astype(np.float64)
    return np.minimum(n * size ** 2 / np.maximum(area, 1e-30), 1.0)


def pixel_rays(sensor, width: int, height: int):
    """The rays through the pixel centres of a perspective sensor (row-major, top row first).

    Parameters
    ----------
    sensor : mitsuba.Sensor
        The camera.
    width, height : int
        Film size [px].

    Returns
    -------
    mitsuba.Ray3f
        ``width * height`` rays.
    """
    idx = np.arange(width * height)
    x = (idx % width + 0.5) / width
    y = (idx // width + 0.5) / height
    wav = mi.Float(np.full(len(idx), 0.5, np.float32))
    pos = mi.Point2f(mi.Float(x.astype(np.float32)), mi.Float(y.astype(np.float32)))
    ray, _ = sensor.sample_ray(0.0, wav, pos, mi.Point2f(0.5, 0.5))
    return ray


def pixel_triangles(rs, shape: str = "ground") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel of a render scene's camera: the triangle of the terrain mesh ``shape`` its
    centre ray meets in the terrain alone, and whether nothing but terrain or moss stands in front.

    Parameters
    ----------
    rs : RenderScene
        The render scene (its ``terrain`` and ``sensor``).
    shape : str, optional
        The terrain mesh (default ``"ground"``).

    Returns
    -------
    tri : numpy.ndarray
        (height, width) int64: triangle index, -1 where the ray meets another mesh or nothing.
    clear : numpy.ndarray
        (height, width) bool: the ray's first hit in the render scene is the terrain or moss.
    on_moss : numpy.ndarray
        (height, width) bool: the ray's first hit in the render scene is a moss mesh (tufts or
        carpet): the geometric cover, free of the render's noise.
    """
    w, h = rs.options.width, rs.options.height
    ray = pixel_rays(rs.sensor, w, h)
    base = rs.terrain.base_scene
    pi = base.ray_intersect_preliminary(ray)
    names = [s.id() for s in base.shapes()]
    ids = _hit_ids(base, pi.shape)
    tri = np.where((ids == names.index(shape)) & np.isfinite(np.asarray(pi.t)),
                   np.asarray(pi.prim_index, np.int64), -1)
    pr = rs.scene.ray_intersect_preliminary(ray)
    rnames = [s.id() for s in rs.scene.shapes()]
    rid = _hit_ids(rs.scene, pr.shape)
    ok = np.array([n in rs.terrain.meshes or n.startswith("moss_") for n in rnames] + [False])
    is_moss = np.array([n.startswith("moss_") for n in rnames] + [False])
    hit = np.isfinite(np.asarray(pr.t))
    clear = ok[rid] & hit
    on_moss = is_moss[rid] & hit
    return tri.reshape(h, w), clear.reshape(h, w), on_moss.reshape(h, w)


def moss_pixels(images: dict, threshold: float = NDVI_MOSS) -> np.ndarray:
    """Pixels that show moss: NDVI of the far-red and red bands above ``threshold``.

    Parameters
    ----------
    images : dict
        A render's images (:func:`mitsuba_veg.render.still.render`): ``bands["red"]`` and
        ``bands["far_red"]`` [W m-2 sr-1 nm-1].
    threshold : float, optional
        NDVI threshold [-] (default :data:`NDVI_MOSS`, 0.45).

    Returns
    -------
    numpy.ndarray
        (height, width) bool.
    """
    r, fr = images["bands"]["red"], images["bands"]["far_red"]
    with np.errstate(divide="ignore", invalid="ignore"):
        ndvi = (fr - r) / (fr + r)
    return np.nan_to_num(ndvi, nan=-1.0) > threshold


def cover_counts(rs, images: dict, shape: str = "ground") -> dict:
    """Per triangle of a terrain mesh, the pixels of one render that see it: in all, showing moss
    by NDVI, and meeting moss geometrically (the counts :func:`cover_comparison` compares; sum
    them over several views of the same scene to compare the views together).

    Parameters
    ----------
    rs : RenderScene
        The rendered scene (its camera).
    images : dict
        Its images (with the red and far-red bands).
    shape : str, optional
        The terrain mesh (default ``"ground"``).

    Returns
    -------
    dict
        ``pixels``, ``ndvi`` and ``geometric`` (triangles,) float64 counts.
    """
    tri, clear, on_moss = pixel_triangles(rs, shape)
    moss_px = moss_pixels(images)
    n = len(rs.terrain.meshes[shape][1])
    sel = (tri >= 0) & clear
    t = tri[sel]
    return {"pixels": np.bincount(t, minlength=n).astype(np.float64),
            "ndvi": np.bincount(t, weights=moss_px[sel].astype(np.float64), minlength=n),
            "geometric": np.bincount(t, weights=on_moss[sel].astype(np.float64), minlength=n)}


def cover_summary(counts: dict, simulated, area, min_pixels: int = 12) -> dict:
    """Drawn against simulated cover from pixel counts (:func:`cover_counts`, summed over views).

    Parameters
    ----------
    counts : dict
        ``pixels``, ``ndvi``, ``geometric`` per triangle.
    simulated : numpy.ndarray
        The simulation's cover per triangle (:func:`simulated_cover`) [-].
    area : numpy.ndarray
        Triangle areas [m²].
    min_pixels : int, optional
        Triangles with fewer pixels are left out (default 12).

    Returns
    -------
    dict
        As :func:`cover_comparison`.
    """
    px, sim, area = counts["pixels"], np.asarray(simulated), np.asarray(area)
    use = px >= min_pixels
    rend = np.where(use, counts["ndvi"] / np.maximum(px, 1), np.nan)
    geom = np.where(use, counts["geometric"] / np.maximum(px, 1), np.nan)
    mossy = use & (sim > 0)
    a_sim = float((sim * area)[use].sum())

    def summary(c):
        a = float((c * area)[use].sum())
        return {"area_ratio": a / a_sim if a_sim > 0 else float("nan"), "m2": a,
                "mad_mossy": float(np.abs(c - sim)[mossy].mean()) if mossy.any()
                else float("nan")}
    s_ndvi, s_geom = summary(rend), summary(geom)
    return {"simulated": sim, "rendered": rend, "geometric": geom, "pixels": px, "area": area,
            "area_ratio": s_ndvi["area_ratio"], "mad_mossy": s_ndvi["mad_mossy"],
            "rendered_m2": s_ndvi["m2"], "geometric_area_ratio": s_geom["area_ratio"],
            "geometric_mad_mossy": s_geom["mad_mossy"], "mossy": int(mossy.sum()),
            "compared": int(use.sum()), "simulated_m2": a_sim}


def cover_comparison(rs, images: dict, moss, size: float, shape: str = "ground",
                     min_pixels: int = 12) -> dict:
    """Drawn against simulated moss cover per triangle of a terrain mesh (module docstring).

    Parameters
    ----------
    rs : RenderScene
        The rendered scene.
    images : dict
        Its images (with the red and far-red bands).
    moss : MossSet
        The living moss the scene shows.
    size : float
        The run's moss size [m].
    shape : str, optional
        The terrain mesh (default ``"ground"``).
    min_pixels : int, optional
        Triangles with fewer clear pixels are left out (default 12).

    Returns
    -------
    dict
        ``simulated``, ``rendered`` (NDVI pixels) and ``geometric`` (pixels whose ray meets moss
        first) per triangle [-] (NaN where left out), ``pixels`` (clear pixels per triangle),
        ``area`` [m²]; for the NDVI cover ``area_ratio`` (drawn / simulated moss area over the
        triangles compared) and ``mad_mossy`` (mean absolute difference over compared triangles
        with simulated cover > 0), the same for the geometric cover (``geometric_area_ratio``,
        ``geometric_mad_mossy``); ``simulated_m2``, ``rendered_m2``; ``mossy`` and ``compared``
        triangle counts.
    """
    v, f = rs.terrain.meshes[shape][0], rs.terrain.meshes[shape][1]
    return cover_summary(cover_counts(rs, images, shape),
                         simulated_cover(rs.terrain, moss, size, shape), triangle_areas(v, f),
                         min_pixels)
