"""Denoising the display image of a render (Intel Open Image Denoise).

A path-traced image at a few dozen samples per pixel is grainy. The display image (linear sRGB,
the PNG's source) is denoised with Open Image Denoise's ``RT`` filter (``pyoidn``, on the CPU).
The filter can be guided by two auxiliary buffers, the surface albedo and the shading normal of
the first hit per pixel (``RenderOptions.denoise_guides``). Mitsuba's ``aov`` integrator makes
them, but not on the spectral film of the render (its channels do not match), so they come from
a pass of their own: a second camera with the same view and an RGB ``hdrfilm``
(:func:`aux_sensor_dict`), rendered by ``aov`` at :data:`AUX_SPP` samples per pixel. On the
views measured (docs/render.md) the guides raised the error against a converged render by about
0.3 percentage points, so they are off by default. The film's pixel filter is a box: the
denoiser is trained on independent pixel noise, which a wider filter would correlate.

Only the display image is denoised: the EXR keeps the rendered XYZ, RGB, red and far-red bands and
R:FR as they came from the film, so measurements never see the denoiser.
"""
from __future__ import annotations

import time

import mitsuba as mi
import numpy as np

__all__ = ["AUX_SPP", "AUX_CAMERA", "aux_sensor_dict", "aux_buffers", "denoise", "timed_denoise"]

#: samples per pixel of the albedo and normal pass (anti-aliased edges for the denoiser)
AUX_SPP = 16
#: id of the auxiliary camera in a render scene
AUX_CAMERA = "aux_camera"
_AOV = None


def aux_sensor_dict(camera: dict) -> dict:
    """A copy of a render camera's dict with an RGB ``hdrfilm`` of the same size (box filter) and
    :data:`AUX_SPP` samples, id :data:`AUX_CAMERA`.

    Parameters
    ----------
    camera : dict
        The render camera's sensor dict (:func:`mitsuba_veg.render.cameras.sensor_dict`).

    Returns
    -------
    dict
        The auxiliary sensor dict.
    """
    d = dict(camera)
    film = camera["film"]
    d["id"] = AUX_CAMERA
    d["film"] = {"type": "hdrfilm", "width": int(film["width"]), "height": int(film["height"]),
                 "pixel_format": "rgb", "component_format": "float32",
                 "rfilter": {"type": "box"}}
    sampler = dict(camera.get("sampler", {"type": "independent"}))
    sampler["sample_count"] = AUX_SPP
    sampler["type"] = "independent"
    d["sampler"] = sampler
    return d


def aux_buffers(scene, sensor, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The albedo and shading-normal buffers of a view (the ``aov`` integrator).

    Parameters
    ----------
    scene : mitsuba.Scene
        The render scene.
    sensor : mitsuba.Sensor
        Its auxiliary camera (:func:`aux_sensor_dict`).
    seed : int, optional
        Sampler seed (default 0).

    Returns
    -------
    albedo : numpy.ndarray
        (h, w, 3) float32: the first hit's diffuse reflectance as linear sRGB [-] (0 where the
        ray leaves the scene).
    normal : numpy.ndarray
        (h, w, 3) float32: its shading normal in world space [-] (0 for no hit).
    """
    global _AOV
    if _AOV is None:
        _AOV = mi.load_dict({"type": "aov", "aovs": "albedo:albedo,nn:sh_normal"})
    a = np.asarray(mi.render(scene, sensor=sensor, integrator=_AOV, seed=int(seed)),
                   np.float32)
    return np.ascontiguousarray(a[..., 0:3]), np.ascontiguousarray(a[..., 3:6])


def denoise(rgb, albedo=None, normal=None) -> np.ndarray:
    """Denoise a linear HDR image with Open Image Denoise's ``RT`` filter (high quality).

    Parameters
    ----------
    rgb : array_like
        (h, w, 3) linear sRGB radiance [W m-2 sr-1 nm-1]: scaled by its mean to O(1) for the
        filter, which is trained on such values, and scaled back.
    albedo, normal : array_like, optional
        The auxiliary buffers (:func:`aux_buffers`), both or neither.

    Returns
    -------
    numpy.ndarray
        (h, w, 3) float64, the denoised image on the input's scale; NaNs of the input stay NaN.
    """
    import pyoidn

    rgb = np.asarray(rgb, np.float64)
    nan = ~np.isfinite(rgb)
    scale = float(np.nanmean(np.abs(rgb))) or 1.0
    col = np.ascontiguousarray(np.nan_to_num(rgb / scale, nan=0.0), np.float32)
    kw = {}
    if albedo is not None and normal is not None:
        kw = {"albedo": np.ascontiguousarray(np.clip(albedo, 0, 1), np.float32),
              "normal": np.ascontiguousarray(normal, np.float32)}
    out = np.asarray(pyoidn.denoise(col, hdr=True, quality="high", **kw), np.float64) * scale
    out[nan] = np.nan
    return out


def timed_denoise(rs, images: dict, seed: int = 0) -> dict:
    """Add the denoised display image to a render's images: ``display`` (h, w, 3) linear sRGB,
    ``seconds_denoise`` [s], and with the scene's auxiliary camera
    (``RenderOptions.denoise_guides``) the guided result and ``seconds_aux`` [s].

    Parameters
    ----------
    rs : RenderScene
        The rendered scene (with its auxiliary camera).
    images : dict
        The render's images (:func:`mitsuba_veg.render.still.render`).
    seed : int, optional
        Seed of the auxiliary pass.

    Returns
    -------
    dict
        ``images``, updated.
    """
    t0 = time.perf_counter()
    albedo = normal = None
    if rs.aux_sensor is not None:
        albedo, normal = aux_buffers(rs.scene, rs.aux_sensor, seed)
        images["seconds_aux"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    images["display"] = denoise(images["rgb"], albedo, normal)
    images["seconds_denoise"] = time.perf_counter() - t1
    return images

