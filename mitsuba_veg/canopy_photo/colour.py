"""A colour hemispherical photograph: the ``veg_fisheye`` sensor in the spectral render.

The day's world (:meth:`~mitsuba_veg.world.visible_canopy.VisibleCanopy.scene` with its
optics: PROSPECT-D leaves of their stage, bark, the scenario's own BSDFs) under the physical
sun and sky of the site at a local hour of the day (:func:`mitsuba_veg.render.scene.sky_emitters`),
rendered with Mitsuba's ``path`` integrator into the package's spectral film
(:func:`mitsuba_veg.render.film.film_dict`: CIE XYZ and the red and far-red bands) and
developed to linear sRGB (:func:`mitsuba_veg.render.film.develop`). The exposure is a canopy
photographer's: set on the sky, so that the brightest sky (the 99th percentile of the
luminance inside the image disc) is just below white and the canopy comes out dark; then the
sRGB curve.
"""
from __future__ import annotations

import datetime as _dt
import time
from types import SimpleNamespace

import mitsuba as mi
import numpy as np

from ..integrators.veg_sky import attach_scene
from ..light.fisheye import Lens, sensor_dict
from ..render.film import develop, film_dict
from ..render.scene import sky_emitters
from ..scenario import site_offset_hours

__all__ = ["colour_photo", "srgb_encode"]


def srgb_encode(linear) -> np.ndarray:
    """The sRGB transfer curve (IEC 61966-2-1) of linear values clipped to [0, 1].

    Parameters
    ----------
    linear : array_like
        Linear sRGB [-].

    Returns
    -------
    numpy.ndarray
        Encoded values in [0, 1].
    """
    x = np.clip(np.asarray(linear, float), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def colour_photo(canopy, base_shapes, state, position, date: _dt.date, scenario,
                 lens: Lens = Lens(512), spp: int = 32, hour: float = 12.0,
                 max_depth: int = 6, seed: int = 0) -> tuple[np.ndarray, dict]:
    """A spectral render of the day's world through the fisheye (module docstring).

    Parameters
    ----------
    canopy : VisibleCanopy
        The day's trees.
    base_shapes : sequence of mitsuba.Shape
        The scenario's shapes.
    state : LeafState
        The day's leaves.
    position : sequence of 3 float
        Lens centre [m].
    date : datetime.date
        The day.
    scenario : Scenario
        The scenario (its site: latitude, longitude, time zone).
    lens : Lens
        Size, projection, field of view.
    spp : int
        Samples per pixel.
    hour : float
        Local hour of the daylight [h].
    max_depth : int
        Path length.
    seed : int
        The sampler's seed.

    Returns
    -------
    srgb : numpy.ndarray
        (size, size, 3) encoded sRGB in [0, 1] (black outside the image disc).
    info : dict
        ``when`` (ISO time of the light), ``exposure`` (factor on the linear sRGB),
        ``seconds`` (``load``, ``render``).
    """
    t0 = time.perf_counter()
    tz = _dt.timezone(_dt.timedelta(hours=site_offset_hours(scenario.get("site") or {})))
    when = (_dt.datetime(date.year, date.month, date.day, tzinfo=tz)
            + _dt.timedelta(minutes=round(float(hour) * 60))).isoformat()
    film = film_dict(SimpleNamespace(width=lens.size, height=lens.size))
    cam = sensor_dict(position, lens, film=film, spp=spp)
    scene = canopy.scene(base_shapes, state, optics=True, emitters=sky_emitters(scenario, when),
                         extra={"camera": cam, "integrator": {"type": "path",
                                                              "max_depth": int(max_depth),
                                                              "hide_emitters": False}})
    attach_scene(scene)
    sensor = [s for s in scene.sensors() if s.id() == "camera"][0]
    t1 = time.perf_counter()
    img = np.asarray(mi.render(scene, sensor=sensor, spp=int(spp), seed=int(seed)))
    t2 = time.perf_counter()
    dev = develop(img)
    rgb = np.maximum(np.asarray(dev["rgb"], float), 0.0)
    inside = lens.pixel_map()["inside"]
    y = np.asarray(dev["XYZ"], float)[..., 1]
    ref = float(np.percentile(y[inside], 99)) if inside.any() else 1.0
    exposure = 0.95 / ref if ref > 0 else 1.0
    out = srgb_encode(rgb * exposure)
    out[~inside] = 0.0
    return out, {"when": when, "exposure": exposure,
                 "seconds": {"load": t1 - t0, "render": t2 - t1}}
