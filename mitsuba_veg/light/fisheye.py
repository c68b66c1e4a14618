"""Hemispherical photographs as the scene's geometry gives them: the fisheye's pixel map and the
binary sky/vegetation image of a ray-cast pass.

:class:`Lens` maps the pixels of a square, levelled canopy photograph (the ``veg_fisheye``
sensor looking at the zenith, north at the image's top and east on its left, the way it is
read in the field) to their zenith angle θ [rad], azimuth [rad, clockwise from north] and
solid angle [sr], and directions back to pixels (the sun's track over a photo).

:func:`gap_image` casts one ray per pixel centre through the same sensor
(:meth:`mitsuba_veg.integrators.veg_fisheye.VegFisheye.direction_at`, the map its ``sample_ray``
uses for a render) into a scene: a pixel is **sky** (a gap) when its ray leaves the scene
without hitting anything, vegetation (or wood, ground, a wall) otherwise. Geometry decides each
pixel: there is no exposure and no threshold, so none of a real photograph's classification
error (a pixel is one direction, not the mean over the pixel's area: the edge of a leaf falls
on whole pixels).

Pixel solid angle (δ = 1/R, R the disc's radius in pixels; the value at the pixel centre):

- equidistant: dΩ = θ_max sin θ / r · δ²  (θ_max² δ² at the centre);
- equisolid: dΩ = 4 sin²(θ_max/2) δ²  (every pixel alike).

Summed over the disc they give 2π (1 − cos θ_max) to within the disc edge's pixels
(tests/test_hemiphoto.py).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError, check_range
from mitsuba_veg.integrators.veg_fisheye import PROJECTIONS, radius_of_zenith, zenith_of_radius

__all__ = ["Lens", "GapImage", "sensor_dict", "gap_image", "MAX_SIZE"]

#: largest photograph side [px]
MAX_SIZE = 8192


@dataclass(frozen=True)
class Lens:
    """A square, levelled fisheye photograph (module docstring).

    Attributes
    ----------
    size : int
        Image side [px] (the image disc's diameter).
    projection : str
        ``"equidistant"`` or ``"equisolid"``.
    fov : float
        Full field of view [deg], (0, 180].
    """

    size: int = 1024
    projection: str = "equidistant"
    fov: float = 180.0

    def __post_init__(self):
        check_range("size", self.size, 16, MAX_SIZE, fix="image side in pixels, e.g. 1024")
        if self.projection not in PROJECTIONS:
            raise ParameterError("projection", self.projection, ", ".join(PROJECTIONS))
        check_range("fov", self.fov, 1.0, 180.0, fix="180 for a hemispherical photograph")

    @property
    def theta_max(self) -> float:
        """Half the field of view [rad]."""
        return math.radians(0.5 * self.fov)

    def _xy(self):
        c = (np.arange(self.size) + 0.5 - 0.5 * self.size) / (0.5 * self.size)
        return c[None, :], -c[:, None]          # image right, image top (rows go down)

    def pixel_map(self) -> dict:
        """Zenith, azimuth and solid angle of every pixel centre.

        Returns
        -------
        dict
            ``theta`` (size, size) zenith angle [rad]; ``azimuth`` (size, size) [rad],
            clockwise from north (north at the top, east on the left); ``solid_angle``
            (size, size) [sr]; ``inside`` (size, size) bool: the pixel centre lies on the image
            disc (outside it the other arrays are 0).
        """
        x, y = self._xy()
        r = np.hypot(x, y)
        inside = r <= 1.0
        theta = np.where(inside, zenith_of_radius(np.minimum(r, 1.0), self.projection,
                                                  self.theta_max), 0.0)
        az = np.mod(np.arctan2(-x, y), 2.0 * np.pi)
        d2 = (2.0 / self.size) ** 2
        if self.projection == "equidistant":
            with np.errstate(invalid="ignore", divide="ignore"):
                w = np.where(r > 0, self.theta_max * np.sin(theta) / np.where(r > 0, r, 1.0),
                             self.theta_max ** 2)
        else:
            w = np.full(r.shape, 4.0 * math.sin(0.5 * self.theta_max) ** 2)
        return {"theta": theta, "azimuth": np.where(inside, az, 0.0),
                "solid_angle": np.where(inside, w * d2, 0.0), "inside": inside}

    def pixel_of(self, theta, azimuth):
        """The pixel that sees a direction.

        Parameters
        ----------
        theta : array_like
            Zenith angle [rad].
        azimuth : array_like
            Azimuth [rad], clockwise from north.

        Returns
        -------
        row, col : numpy.ndarray
            Pixel indices (int); -1 where the direction lies outside the image disc.
        """
        th = np.asarray(theta, float)
        az = np.asarray(azimuth, float)
        r = radius_of_zenith(th, self.projection, self.theta_max)
        x = -r * np.sin(az)
        y = r * np.cos(az)
        col = np.floor((x + 1.0) * 0.5 * self.size).astype(np.int64)
        row = np.floor((1.0 - y) * 0.5 * self.size).astype(np.int64)
        bad = (r > 1.0) | (col < 0) | (col >= self.size) | (row < 0) | (row >= self.size) | \
            (th < 0)
        return np.where(bad, -1, row), np.where(bad, -1, col)


def sensor_dict(position, lens: Lens = Lens(), film: dict | None = None,
                direction=(0.0, 1.0, 0.0), up=(0.0, 0.0, -1.0), spp: int = 4) -> dict:
    """The ``veg_fisheye`` sensor of a photograph at ``position``.

    Parameters
    ----------
    position : sequence of 3 float
        Centre of the lens [m] (scene frame).
    lens : Lens
        Image size [px], projection and field of view.
    film : dict, optional
        The film (default: an ``hdrfilm`` of the lens's size with a box filter).
    direction, up : sequence of 3 float
        Optical axis and the image's top (default: zenith, north).
    spp : int
        Samples per pixel of the sampler.

    Returns
    -------
    dict
        For ``mi.load_dict``.
    """
    p = np.asarray(position, float).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ParameterError("position", position, "[x, y, z]: three finite numbers [m]")
    film = film or {"type": "hdrfilm", "width": lens.size, "height": lens.size,
                    "rfilter": {"type": "box"}, "pixel_format": "rgb"}
    return {"type": "veg_fisheye", "projection": lens.projection, "fov": float(lens.fov),
            "origin": [float(v) for v in p], "direction": [float(v) for v in direction],
            "up": [float(v) for v in up], "film": film,
            "sampler": {"type": "independent", "sample_count": int(spp)}}


@dataclass
class GapImage:
    """A binary hemispherical photograph.

    Attributes
    ----------
    gap : numpy.ndarray
        (size, size) bool: the pixel's ray reaches the sky.
    lens : Lens
        Its lens.
    position : numpy.ndarray
        (3,) lens centre [m].
    seconds : float
        Time of the ray-cast pass [s].
    """

    gap: np.ndarray
    lens: Lens
    position: np.ndarray
    seconds: float = 0.0

    def pixel_map(self) -> dict:
        """:meth:`Lens.pixel_map` of its lens.

        Returns
        -------
        dict
            ``theta``, ``azimuth``, ``solid_angle``, ``inside``.
        """
        return _pixel_map(self.lens)


_MAPS: dict = {}


def _pixel_map(lens: Lens) -> dict:
    if lens not in _MAPS:
        if len(_MAPS) > 4:
            _MAPS.clear()
        _MAPS[lens] = lens.pixel_map()
    return _MAPS[lens]


def gap_image(scene, position, lens: Lens = Lens()) -> GapImage:
    """The binary photograph of ``scene`` from ``position``: one ray per pixel centre through
    the ``veg_fisheye`` sensor's own map, sky where it hits nothing (module docstring).

    Parameters
    ----------
    scene : mi.Scene
        The scene (emitters are ignored; every shape blocks the sky: build it with the shapes
        a camera would see, e.g. :mod:`mitsuba_veg.world.visible_canopy`).
    position : sequence of 3 float
        Lens centre [m].
    lens : Lens
        Size, projection and field of view.

    Returns
    -------
    GapImage
        The gaps (False outside the image disc).
    """
    t0 = time.perf_counter()
    sensor = mi.load_dict(sensor_dict(position, lens))
    n = lens.size
    idx = dr.arange(mi.UInt32, n * n)
    pos = mi.Point2f(mi.Float(idx % n) + 0.5, mi.Float(idx // n) + 0.5)
    d, valid = sensor.direction_at(pos)
    o = mi.Point3f(*[float(v) for v in np.asarray(position, float)])
    pi = scene.ray_intersect_preliminary(mi.Ray3f(o, d), valid)
    gap = np.asarray(valid & ~pi.is_valid(), bool).reshape(n, n)
    return GapImage(gap, lens, np.asarray(position, float).copy(), time.perf_counter() - t0)
