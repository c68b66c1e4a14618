"""A photographed coverage map: an image of the terrain seen from a camera -> cover per triangle.

The camera is a Mitsuba ``perspective`` sensor given by a small dict (a JSON file on the command
line)::

    {"origin": [0, 4, 0.001], "target": [0, 0, 0], "up": [0, 0, -1], "fov": 30,
     "width": 400, "height": 400}

origin, target [m] in the scene's frame (+y up), up: the image's up direction, fov: horizontal
field of view [deg], width, height [px]. :func:`pixel_elements` casts one ray through every
pixel centre into the moss scene and records the triangle it hits first (a triangle-id image:
occlusion is handled by the ray cast; pixels that hit nothing or a shape without moss get -1).
:func:`cover_from_image` reads the image and averages each triangle's pixels:

- ``mode="gray"``: the pixel value (0-1: 8-bit / 255, 16-bit / 65535) *is* the covered fraction
  (a classified moss map);
- ``mode="colour"``: the pixel colour is unmixed between a bare-surface colour and a moss colour
  (sRGB 0-1, as a colour picker gives them) in linear light: c = clip(``<p - b, m - b> / |m - b|^2``,
  0, 1), with p, b, m linearised by the sRGB transfer curve.

Triangles seen by fewer than ``min_pixels`` pixels are NaN (ignored by
:func:`mitsuba_veg.tune.fit`).
:func:`render_cover_image` makes the synthetic photograph of a cover map with the same camera
(the example and the tests use it for round trips).
"""
from __future__ import annotations

import json
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError

__all__ = ["camera_sensor", "load_camera", "pixel_elements", "cover_from_image",
           "render_cover_image", "srgb_to_linear", "linear_to_srgb"]

_CAMERA_KEYS = {"origin", "target", "up", "fov", "width", "height"}


def load_camera(camera) -> dict:
    """A validated camera dict from a dict or a JSON file path.

    Parameters
    ----------
    camera : dict or path
        Camera dict (``origin``, ``target``, ``up`` [m], ``fov`` [deg], ``width``, ``height``
        [px]) or a JSON file of it (module docstring).

    Returns
    -------
    dict
        The validated camera.
    """
    if isinstance(camera, (str, Path)):
        p = Path(camera)
        try:
            camera = json.loads(p.read_text())
        except (OSError, ValueError) as e:
            raise ParameterError("camera", str(p), "a readable JSON file with origin, target, "
                                 "up, fov, width, height", f"fix the file ({e})") from None
    if not isinstance(camera, dict):
        raise ParameterError("camera", type(camera).__name__, "a dict or a JSON file")
    for k in camera:
        if k not in _CAMERA_KEYS:
            raise ParameterError(f"camera.{k}", camera[k],
                                 "one of " + ", ".join(sorted(_CAMERA_KEYS)),
                                 "remove or rename the field")
    out = {"up": [0.0, 0.0, -1.0]}
    out.update(camera)
    for k in ("origin", "target"):
        if k not in out:
            raise ParameterError(f"camera.{k}", None, "[x, y, z] in metres", f"give camera.{k}")
    for k in ("origin", "target", "up"):
        v = np.asarray(out[k], float)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ParameterError(f"camera.{k}", out[k], "three finite numbers [x, y, z]")
        out[k] = [float(x) for x in v]
    d = np.subtract(out["target"], out["origin"])
    if np.linalg.norm(d) == 0:
        raise ParameterError("camera.target", out["target"], "a point other than the origin")
    if np.linalg.norm(np.cross(d, out["up"])) < 1e-9 * np.linalg.norm(d):
        raise ParameterError("camera.up", out["up"], "a direction not parallel to target - origin",
                             "for a view straight down use up = [0, 0, -1]")
    fov = out.get("fov", 40.0)
    try:
        fov = float(fov)
    except (TypeError, ValueError):
        raise ParameterError("camera.fov", fov, "a number in (0, 180) [deg]") from None
    if not 0.0 < fov < 180.0:
        raise ParameterError("camera.fov", fov, "(0, 180) [deg]")
    out["fov"] = fov
    for k in ("width", "height"):
        v = out.get(k, 256)
        if not isinstance(v, (int, np.integer)) or not 1 <= v <= 16384:
            raise ParameterError(f"camera.{k}", v, "an integer in [1, 16384] [px]")
        out[k] = int(v)
    return out


def camera_sensor(camera) -> mi.Sensor:
    """The Mitsuba ``perspective`` sensor of a camera dict.

    Parameters
    ----------
    camera : dict or path
        Camera dict (``origin``, ``target``, ``up`` [m], ``fov`` [deg], ``width``, ``height``
        [px]) or a JSON file of it (module docstring).

    Returns
    -------
    mitsuba.Sensor
        A perspective sensor with a box-filtered film of the camera's size.
    """
    c = load_camera(camera)
    return mi.load_dict({
        "type": "perspective", "fov": c["fov"], "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=c["origin"], target=c["target"],
                                                   up=c["up"]),
        "film": {"type": "hdrfilm", "width": c["width"], "height": c["height"],
                 "rfilter": {"type": "box"}}})


def pixel_elements(scene: mi.Scene, index, camera, living=None) -> np.ndarray:
    """The element (triangle) hit through every pixel centre.

    Parameters
    ----------
    scene : mitsuba.Scene
        The moss scene.
    index : SceneIndex
        Its element index (``ModelData.index``).
    camera : dict or path
        Camera dict (``origin``, ``target``, ``up`` [m], ``fov`` [deg], ``width``, ``height``
        [px]) or a JSON file of it (module docstring).
    living : array_like, optional
        Bool per element: elements outside it count as not hit.

    Returns
    -------
    ndarray
        (height, width) element index; -1 where the ray hits nothing or an element outside
        ``living``.
    """
    c = load_camera(camera)
    sensor = camera_sensor(c)
    W, H = c["width"], c["height"]
    k = dr.arange(mi.UInt32, W * H)
    x = mi.Float(k % W) + 0.5
    y = mi.Float(k // W) + 0.5
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / W, y / H), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal, coherent=True)
    valid = si.is_valid()
    lookup = index.lookup
    idx = dr.gather(mi.UInt32, lookup, dr.reinterpret_array(mi.UInt32, si.shape), valid) \
        + dr.gather(mi.UInt32, lookup, dr.reinterpret_array(mi.UInt32, si.instance), valid) \
        + si.prim_index
    e = np.where(np.asarray(valid), np.asarray(idx).astype(np.int64), -1)
    e[(e < 0) | (e >= index.n_elements)] = -1
    if living is not None:
        ok = e >= 0
        e[ok & ~np.asarray(living, bool)[np.maximum(e, 0)]] = -1
    return e.reshape(H, W)


def srgb_to_linear(v):
    """The sRGB transfer curve inverted (IEC 61966-2-1).

    Parameters
    ----------
    v : array_like
        sRGB-encoded values [-] in 0-1.

    Returns
    -------
    ndarray
        Linear values [-] in 0-1.
    """
    v = np.asarray(v, float)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v):
    """The sRGB transfer curve (IEC 61966-2-1).

    Parameters
    ----------
    v : array_like
        Linear values [-] (clipped to 0-1).

    Returns
    -------
    ndarray
        sRGB-encoded values [-] in 0-1.
    """
    v = np.clip(np.asarray(v, float), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def _colour(v, field):
    a = np.asarray(v, float)
    if a.shape != (3,) or np.any(~np.isfinite(a)) or a.min() < 0 or a.max() > 1:
        raise ParameterError(field, v, "an sRGB triple with values in [0, 1]")
    return a


def _read_image(image) -> np.ndarray:
    if isinstance(image, np.ndarray):
        return np.asarray(image, float)
    from PIL import Image
    p = Path(image)
    try:
        im = Image.open(p)
        im.load()
    except (OSError, ValueError) as e:
        raise ParameterError("image", str(p), "a readable PNG/JPEG image", f"check the file ({e})"
                             ) from None
    a = np.asarray(im)
    if a.dtype == np.uint8:
        return a.astype(float) / 255.0
    if a.dtype in (np.uint16, np.int32) or im.mode.startswith("I"):
        return a.astype(float) / 65535.0
    return a.astype(float)


def cover_from_image(image, camera, scene: mi.Scene, index, living=None, mode: str = "colour",
                     bare=(0.45, 0.36, 0.26), moss=(0.22, 0.42, 0.12), min_pixels: int = 1
                     ) -> np.ndarray:
    """Covered fraction per element [-] from an image of the scene seen by ``camera``.

    Parameters
    ----------
    image : path or ndarray
        A PNG/JPEG path or an array (height, width[, channels]) with values 0-1.
    camera : dict or path
        Camera dict (``origin``, ``target``, ``up`` [m], ``fov`` [deg], ``width``, ``height``
        [px]) or a JSON file of it (module docstring).
    scene : mitsuba.Scene
        The moss scene (``ModelData.scene``).
    index : SceneIndex
        Its element index (``ModelData.index``).
    living : array_like, optional
        Bool per element: elements that may hold moss (others NaN).
    mode : {"colour", "gray"}
        "colour": unmixed in linear light between the ``bare`` and ``moss`` sRGB colours;
        "gray": pixel value = cover.
    bare, moss : tuple of float
        sRGB colours [-] of bare ground and of full moss cover.
    min_pixels : int
        Triangles seen by fewer pixels get NaN.

    Returns
    -------
    ndarray
        One covered fraction per element [-] (NaN where not seen).
    """
    c = load_camera(camera)
    if mode not in ("gray", "colour"):
        raise ParameterError("mode", mode, "'gray' or 'colour'")
    if int(min_pixels) < 1:
        raise ParameterError("min_pixels", min_pixels, ">= 1")
    a = _read_image(image)
    if a.shape[:2] != (c["height"], c["width"]):
        raise ParameterError("image", f"{a.shape[1]} x {a.shape[0]} px",
                             f"{c['width']} x {c['height']} px (the camera's width x height)",
                             "use the camera the image was taken with")
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[..., :3]                       # alpha ignored
    if mode == "gray":
        val = a if a.ndim == 2 else a[..., :3].mean(-1)
    else:
        if a.ndim != 3 or a.shape[2] != 3:
            raise ParameterError("image", f"shape {a.shape}", "an RGB image for mode='colour'")
        b = srgb_to_linear(_colour(bare, "bare"))
        m = srgb_to_linear(_colour(moss, "moss"))
        dm = m - b
        if float(dm @ dm) < 1e-8:
            raise ParameterError("moss", list(moss), "a colour different from bare")
        val = np.clip((srgb_to_linear(a) - b) @ dm / float(dm @ dm), 0.0, 1.0)
    e = pixel_elements(scene, index, c, living).ravel()
    ok = e >= 0
    n = index.n_elements
    cnt = np.bincount(e[ok], minlength=n)
    s = np.bincount(e[ok], weights=np.asarray(val, float).ravel()[ok], minlength=n)
    out = np.full(n, np.nan)
    seen = cnt >= int(min_pixels)
    out[seen] = s[seen] / cnt[seen]
    return np.clip(out, 0.0, 1.0)


def render_cover_image(cover, camera, scene: mi.Scene, index, path=None, mode: str = "colour",
                       bare=(0.45, 0.36, 0.26), moss=(0.22, 0.42, 0.12), background=(0, 0, 0),
                       bits: int = 8) -> np.ndarray:
    """The synthetic photograph of a cover map seen by ``camera``: each pixel shows the
    triangle its centre sees, its colour mixed in linear light between ``bare`` and ``moss`` by
    the cover (``mode="gray"``: the cover itself).

    Parameters
    ----------
    cover : array_like
        Covered fraction per element [-] (0-1).
    camera : dict or path
        Camera dict (``origin``, ``target``, ``up`` [m], ``fov`` [deg], ``width``, ``height``
        [px]) or a JSON file of it (module docstring).
    scene : mitsuba.Scene
        The moss scene.
    index : SceneIndex
        Its element index.
    path : path, optional
        PNG to write.
    mode : {"colour", "gray"}
        Colour mix or gray value = cover.
    bare, moss : tuple of float
        sRGB colours [-] of bare ground and of full moss cover.
    background : tuple of float
        sRGB colour [-] of pixels that hit nothing.
    bits : {8, 16}
        Bits per channel of the PNG (16: gray only).

    Returns
    -------
    ndarray
        The image (height, width[, 3]), values 0-1.
    """
    if bits not in (8, 16) or (bits == 16 and mode != "gray"):
        raise ParameterError("bits", bits, "8, or 16 with mode='gray'")
    c = load_camera(camera)
    e = pixel_elements(scene, index, c)
    cov = np.nan_to_num(np.clip(np.asarray(cover, float), 0, 1))
    k = np.where(e >= 0, e, 0)
    v = np.where(e >= 0, cov[k], 0.0)
    if mode == "gray":
        img = v
    elif mode == "colour":
        b = srgb_to_linear(_colour(bare, "bare"))
        m = srgb_to_linear(_colour(moss, "moss"))
        img = linear_to_srgb((1 - v)[..., None] * b + v[..., None] * m)
        img[e < 0] = _colour(background, "background")
    else:
        raise ParameterError("mode", mode, "'gray' or 'colour'")
    if path is not None:
        from PIL import Image
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        if bits == 16:
            Image.fromarray(np.round(np.clip(img, 0, 1) * 65535).astype(np.uint16)).save(path)
        else:
            Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(path)
    return img
