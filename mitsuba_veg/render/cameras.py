"""Camera presets for the render.

A scenario can name its own views::

    [render.cameras.corner]
    origin = [2.6, 1.9, 2.9]      # [m]
    target = [-0.05, 0.25, -0.25]
    up = [0.0, 1.0, 0.0]          # optional
    fov = 50.0                    # [deg] field of view along the axis fov_axis names
    fov_axis = "x"                # optional: "x" (default, as Mitsuba), "y", "smaller"

Built-in presets, computed from the scene (the ground's bounding box when there is a
``terrain.ground``):

- ``overview``: a three-quarter view from the south-east, above, framing the ground;
- ``scene``: the scene file's own ``camera`` sensor (position and field of view), else
  ``overview``;
- ``shelter``: close, from the middle of the ground, low, looking into the back (where the moss
  garden's roof shelters the moss);
- ``top``: straight down, north up.
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from ..errors import ParameterError

BUILTIN = ("overview", "shelter", "top", "scene")


def _scene_camera(terrain):
    try:
        for s in terrain.base_scene.sensors():
            if s.id() == "camera" or len(terrain.base_scene.sensors()) == 1:
                m = np.array(s.world_transform().matrix, dtype=np.float64).reshape(4, 4)
                p = mi.traverse(s)
                fov = float(p["x_fov"][0]) if "x_fov" in p else 45.0
                origin = m[:3, 3]
                fwd = m[:3, 2]
                up = m[:3, 1]
                return {"origin": origin.tolist(), "target": (origin + fwd).tolist(),
                        "up": up.tolist(), "fov": fov, "fov_axis": "x"}
    except Exception:  # pragma: no cover - a scene without a usable sensor
        return None
    return None


def presets(scn, terrain) -> dict:
    """All camera presets of a scenario: the built-ins, overridden/extended by ``[render.cameras]``.

    Parameters
    ----------
    scn : Scenario
        The scenario (its ``render.cameras`` tables).
    terrain : Terrain
        The scene's meshes (:class:`~mitsuba_veg.render.scene.Terrain`): its bounding boxes
        place the built-in views, its base scene gives the ``scene`` preset.

    Returns
    -------
    dict
        ``{name: {"origin": [x, y, z] [m], "target": [x, y, z] [m], "up": [x, y, z] [-],
        "fov": float [degrees], "fov_axis": str}}``.

    Raises
    ------
    ParameterError
        If a ``[render.cameras.NAME]`` entry has a malformed origin, target or up, a fov outside
        [1, 170] degrees, an unknown fov_axis, or lacks origin or target.
    """
    lo, hi = terrain.ground_bbox()
    c = 0.5 * (lo + hi)
    ext = hi - lo
    W = float(max(ext[0], ext[2], 1e-3))
    ab_lo, ab_hi = terrain.bbox()
    yg = float(c[1])
    out = {
        "overview": {"origin": [c[0] + 1.1 * W, yg + 0.78 * W, c[2] + 1.25 * W],
                     "target": [c[0] - 0.12 * W, yg + 0.14 * W, c[2] - 0.2 * W],
                     "up": [0, 1, 0], "fov": 46.0, "fov_axis": "x"},
        "shelter": {"origin": [c[0] + 0.1 * W, yg + 0.16 * W, c[2] + 0.12 * W],
                    "target": [c[0] - 0.02 * W, yg, c[2] - 0.36 * W],
                    "up": [0, 1, 0], "fov": 58.0, "fov_axis": "x"},
        "top": {"origin": [c[0], float(ab_hi[1]) + 1.25 * W, c[2] + 1e-4],
                "target": [c[0], yg, c[2]], "up": [0, 0, -1], "fov": 46.0,
                "fov_axis": "smaller"},
    }
    sc = _scene_camera(terrain)
    out["scene"] = sc if sc is not None else dict(out["overview"])
    for name, cam in (scn.get("render.cameras", {}) or {}).items():
        base = dict(out.get(name, {"up": [0, 1, 0], "fov": 45.0, "fov_axis": "x"}))
        for k in ("origin", "target", "up"):
            if k in cam:
                v = cam[k]
                if not (isinstance(v, list) and len(v) == 3 and
                        all(isinstance(x, (int, float)) for x in v)):
                    raise ParameterError(f"render.cameras.{name}.{k}", v, "[x, y, z] in metres",
                                         None, str(scn.path))
                base[k] = [float(x) for x in v]
        if "fov" in cam:
            f = cam["fov"]
            if not isinstance(f, (int, float)) or not (1.0 <= f <= 170.0):
                raise ParameterError(f"render.cameras.{name}.fov", f, "[1, 170] degrees", None,
                                     str(scn.path))
            base["fov"] = float(f)
        if "fov_axis" in cam:
            if cam["fov_axis"] not in ("x", "y", "smaller", "larger", "diagonal"):
                raise ParameterError(f"render.cameras.{name}.fov_axis", cam["fov_axis"],
                                     "x, y, smaller, larger or diagonal", None, str(scn.path))
            base["fov_axis"] = cam["fov_axis"]
        if "origin" not in base or "target" not in base:
            raise ParameterError(f"render.cameras.{name}", cam, "origin and target",
                                 "give origin = [x, y, z] and target = [x, y, z]", str(scn.path))
        out[name] = base
    return out


def sensor_dict(scn, terrain, options, film: dict) -> dict:
    """The Mitsuba ``perspective`` sensor dict of the preset ``options.camera``.

    Near and far clip 0.005 m and 1e5 m; the sampler is ``options.sampler`` with
    ``options.samples`` samples per pixel and ``options.seed``.

    Parameters
    ----------
    scn : Scenario
        The scenario (its own camera presets).
    terrain : Terrain
        The scene's meshes (see :func:`presets`).
    options : RenderOptions
        Camera name, sampler, samples per pixel and seed.
    film : dict
        The film dict (:func:`mitsuba_veg.render.film.film_dict`).

    Returns
    -------
    dict
        The sensor dict (id ``"camera"``) for ``mi.load_dict``.

    Raises
    ------
    ParameterError
        If ``options.camera`` is not a preset of the scenario.
    """
    cams = presets(scn, terrain)
    if options.camera not in cams:
        raise ParameterError("camera", options.camera, "one of " + ", ".join(cams),
                             "add [render.cameras.NAME] to the scenario for your own view",
                             str(scn.path))
    c = cams[options.camera]
    return {"type": "perspective", "id": "camera", "fov": float(c["fov"]),
            "fov_axis": c.get("fov_axis", "x"), "near_clip": 0.005, "far_clip": 1.0e5,
            "to_world": mi.ScalarTransform4f().look_at(origin=c["origin"], target=c["target"],
                                                       up=c["up"]),
            "sampler": {"type": options.sampler, "sample_count": int(options.samples),
                        "seed": int(options.seed)},
            "film": film}
