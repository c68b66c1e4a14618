"""Camera presets for the render.

A scenario can name its own views::

    [render.cameras.corner]
    origin = [2.6, 1.9, 2.9]      # [m]
    target = [-0.05, 0.25, -0.25]
    up = [0.0, 1.0, 0.0]          # optional
    fov = 50.0                    # [deg] field of view along the axis fov_axis names
    fov_axis = "x"                # optional: "x" (default, as Mitsuba), "y", "smaller"

Built-in presets, computed from the scene and from what the run grew (the ground's bounding box
when there is a ``terrain.ground``, the living moss, the trees):

- ``overview``: a three-quarter view from the south-east over the whole plot and its trees,
  pitched down :data:`OVERVIEW_PITCH` so that the horizon stays in the frame;
- ``floor``: at eye height (1.6 m, less on small grounds) looking across the place where the moss
  is densest, from the side with a clear line of sight, the moss in the lower middle of the
  frame (the ``overview`` where there is no moss);
- ``canopy``: from 1.2 m above the floor next to the trunk nearest the crowns' centre, looking
  up into the canopy through a wide lens (the ``overview`` without trees);
- ``scene``: the scene file's own ``camera`` sensor (position and field of view), else
  ``overview``;
- ``shelter``: close, from the middle of the ground, low, looking into the back (where the moss
  garden's roof shelters the moss);
- ``top``: straight down, north up (the moss-cover benchmark's view).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from ..errors import ParameterError

__all__ = ["BUILTIN", "OVERVIEW_PITCH", "OVERVIEW_FOV", "EYE_HEIGHT", "moss_focus", "presets",
           "sensor_dict"]

#: the built-in camera presets (module docstring)
BUILTIN = ("overview", "floor", "canopy", "shelter", "top", "scene")
#: downward pitch of the overview [degrees]: 2.5 degrees less than the vertical half-angle of
#: a 16:9 view at :data:`OVERVIEW_FOV`, so the horizon is in the frame
OVERVIEW_PITCH = 16.0
#: horizontal field of view of the overview [degrees]
OVERVIEW_FOV = 62.0
#: eye height of the floor view [m] (at most 0.35 of the ground's extent)
EYE_HEIGHT = 1.6


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


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / max(float(np.linalg.norm(v)), 1e-12)


def _clear(scene, a, b) -> bool:
    """Whether the segment from ``a`` to ``b`` meets nothing in ``scene``."""
    d = np.asarray(b, float) - np.asarray(a, float)
    L = float(np.linalg.norm(d))
    if L <= 0:
        return True
    ray = mi.Ray3f(mi.Point3f(*[float(x) for x in a]), mi.Vector3f(*[float(x) for x in d / L]))
    ray.maxt = L
    return not bool(np.asarray(scene.ray_test(ray)).ravel()[0])


def _ground_y(terrain, x, z, default):
    """Height of the terrain under (x, z) [m] (a ray down), ``default`` where there is none."""
    lo, hi = terrain.bbox()
    top = float(hi[1]) + 1.0
    ray = mi.Ray3f(mi.Point3f(float(x), top, float(z)), mi.Vector3f(0.0, -1.0, 0.0))
    pi = terrain.base_scene.ray_intersect_preliminary(ray)
    t = float(np.asarray(pi.t).ravel()[0])
    return top - t if np.isfinite(t) else float(default)


def moss_focus(moss, ground_lo, ground_hi):
    """Where the moss is densest: the centroid of the living moss in the densest cell of a 6 x 6
    grid over the ground (and its neighbours), moss on upward-facing surfaces preferred.

    Parameters
    ----------
    moss : MossSet or None
        The living moss.
    ground_lo, ground_hi : array_like
        The ground's bounding box (3,) [m].

    Returns
    -------
    numpy.ndarray or None
        The point (3,) [m], None without moss.
    """
    if moss is None or len(moss) == 0:
        return None
    p = moss.pos
    up = moss.nrm[:, 1] > 0.5
    if up.sum() >= 10:
        p = p[up]
    lo, hi = np.asarray(ground_lo, float), np.asarray(ground_hi, float)
    k = 6
    ix = np.clip(((p[:, 0] - lo[0]) / max(hi[0] - lo[0], 1e-9) * k).astype(int), 0, k - 1)
    iz = np.clip(((p[:, 2] - lo[2]) / max(hi[2] - lo[2], 1e-9) * k).astype(int), 0, k - 1)
    h = np.zeros((k, k))
    np.add.at(h, (ix, iz), 1.0)
    # a 3 x 3 box sum: the densest neighbourhood, not a lone crowded cell
    hp = np.pad(h, 1)
    box = sum(hp[1 + dx:1 + dx + k, 1 + dz:1 + dz + k] for dx in (-1, 0, 1) for dz in (-1, 0, 1))
    bx, bz = np.unravel_index(np.argmax(box), box.shape)
    near = (np.abs(ix - bx) <= 1) & (np.abs(iz - bz) <= 1)
    return p[near].mean(0)


def _tree_points(trees):
    """(trunk bases (t, 3), crown points (n, 3), obstacle points (m, 3)) of the trees [m]: the
    leaves (or branch ends) and points along every living branch every 0.2 m."""
    bases, crown, obst = [], [], []
    for t in trees or []:
        if len(t.start) == 0:
            continue
        bases.append(t.start[0])
        a = t.alive
        pts = t.leaves.position if len(t.leaves) else t.end[a] if a.any() else t.end
        crown.append(np.asarray(pts, float).reshape(-1, 3))
        s0, s1 = t.start[a], t.end[a]
        n = np.clip((np.linalg.norm(s1 - s0, axis=1) / 0.2).astype(int), 1, 50)
        u = np.concatenate([np.arange(k) / k for k in n])
        obst.append(np.repeat(s0, n, 0) + u[:, None] * np.repeat(s1 - s0, n, 0))
        obst.append(crown[-1][:: max(1, len(crown[-1]) // 5000)])
    if not bases:
        return None, None, None
    return np.array(bases), np.concatenate(crown), np.concatenate(obst)


def _overview(c, W, top_y, yg):
    """Three-quarter view from the south-east at OVERVIEW_PITCH, framing a plot W wide."""
    pitch = np.radians(OVERVIEW_PITCH)
    horiz = _unit([-1.0, 0.0, -1.15])                 # looking north-west
    height = max(top_y - yg, 0.1 * W)
    target = np.array([c[0], yg + 0.25 * height, c[2]]) + 0.1 * W * horiz
    # the plot's diagonal and the tallest crowns within the view
    D = 0.95 * W + 0.6 * height
    fwd = np.array([horiz[0] * np.cos(pitch), -np.sin(pitch), horiz[2] * np.cos(pitch)])
    origin = target - D * fwd
    return {"origin": origin.tolist(), "target": target.tolist(), "up": [0, 1, 0],
            "fov": OVERVIEW_FOV, "fov_axis": "x"}


def _floor_view(terrain, focus, c, W, yg, obstacles=None):
    """Eye-height view across the moss at ``focus`` from a side with a clear line of sight.

    Candidates at 16 azimuths and three distances around the focus; each scores for a clear line
    of sight over the terrain, for standing inside the plot, for looking outwards (the plot's
    edge or walls behind the moss, not in front of it), and against tree parts (``obstacles``:
    points of branches and leaves) near the camera or the line of sight.
    """
    eye = min(EYE_HEIGHT, 0.35 * W)
    dist0 = max(1.5 * eye, 0.1 * W)
    lo, hi = terrain.ground_bbox()
    from scipy.spatial import cKDTree      # here: only the floor view needs it

    tree = cKDTree(obstacles) if obstacles is not None and len(obstacles) else None
    best = None
    for dist in (dist0, 1.4 * dist0, 1.9 * dist0):
        for k in range(16):
            a = 2 * np.pi * k / 16
            d = np.array([np.cos(a), 0.0, np.sin(a)])
            cam_xz = focus + dist * d
            gy = _ground_y(terrain, cam_xz[0], cam_xz[2], yg)
            origin = np.array([cam_xz[0], gy + eye, cam_xz[2]])
            inside = lo[0] <= origin[0] <= hi[0] and lo[2] <= origin[2] <= hi[2]
            seen = _clear(terrain.base_scene, focus + np.array([0, 0.05, 0]), origin)
            score = 2.0 * seen + 1.0 * inside - \
                float(np.linalg.norm(cam_xz[[0, 2]] - c[[0, 2]])) / W - 0.1 * dist / dist0
            if tree is not None:
                near = len(tree.query_ball_point(origin, 0.8))
                line = origin + np.linspace(0.1, 0.9, 9)[:, None] * (focus - origin)
                blocked = sum(len(x) > 0 for x in tree.query_ball_point(line, 0.25))
                score -= 0.02 * min(near, 100) + 0.3 * blocked
            if best is None or score > best[0]:
                best = (score, origin, dist)
    _, origin, dist = best
    look = _unit(focus - origin)
    target = focus + 0.35 * dist * _unit([look[0], 0.0, look[2]])
    return {"origin": origin.tolist(), "target": target.tolist(), "up": [0, 1, 0],
            "fov": 60.0, "fov_axis": "x"}


def _canopy_view(terrain, bases, crown, yg):
    """From 1.2 m above the floor beside the trunk nearest the crowns' centre, looking up."""
    cc = crown.mean(0)
    i = int(np.argmin(np.linalg.norm((bases - cc)[:, [0, 2]], axis=1)))
    b = bases[i]
    away = _unit([(cc - b)[0], 0.0, (cc - b)[2]]) if np.linalg.norm((cc - b)[[0, 2]]) > 1e-3 \
        else np.array([1.0, 0.0, 0.0])
    # stand a little off the trunk, towards the crowns' centre, and look up past the trunk
    stand = b + 1.2 * away
    gy = _ground_y(terrain, stand[0], stand[2], yg)
    origin = np.array([stand[0], gy + 1.2, stand[2]])
    crown_h = float(np.median(crown[:, 1]))
    target = np.array([cc[0], max(crown_h, origin[1] + 1.0), cc[2]])
    look = target - origin
    horiz = float(np.linalg.norm(look[[0, 2]]))
    rise = max(look[1], 1e-3)
    if np.degrees(np.arctan2(rise, horiz)) < 50.0:      # at least 50 degrees up
        target = origin + np.array([look[0], 0, look[2]]) / max(horiz, 1e-9) * rise / \
            np.tan(np.radians(50.0)) + np.array([0.0, rise, 0.0])
    return {"origin": origin.tolist(), "target": target.tolist(), "up": [0, 1, 0],
            "fov": 80.0, "fov_axis": "x"}


def presets(scn, terrain, moss=None, trees=None, only: str | None = None) -> dict:
    """All camera presets of a scenario: the built-ins, overridden/extended by ``[render.cameras]``.

    Parameters
    ----------
    scn : Scenario
        The scenario (its ``render.cameras`` tables).
    terrain : Terrain
        The scene's meshes (:class:`~mitsuba_veg.render.scene.Terrain`): its bounding boxes
        place the built-in views, its base scene gives the ``scene`` preset.
    moss : MossSet, optional
        The living moss (the ``floor`` view looks at it).
    trees : list of Tree, optional
        The trees drawn (the ``overview`` frames them, the ``canopy`` view looks up into them).
    only : str, optional
        Compute this preset only (a render needs one; the floor view's search costs a
        fraction of a second); default all.

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
    yg = float(np.median(terrain.meshes[terrain.ground][0][:, 1])) if terrain.ground \
        else float(c[1])
    bases, crown, obstacles = _tree_points(trees)
    top_y = float(ab_hi[1])
    if crown is not None:
        top_y = max(top_y, float(crown[:, 1].max()))
    overview = _overview(c, W, top_y, yg)

    def want(name):
        return only is None or only == name
    focus = moss_focus(moss, lo, hi) if want("floor") else None
    out = {
        "overview": overview,
        "floor": _floor_view(terrain, focus, c, W, yg, obstacles) if focus is not None
        else dict(overview),
        "canopy": _canopy_view(terrain, bases, crown, yg) if bases is not None and
        want("canopy") else dict(overview),
        "shelter": {"origin": [c[0] + 0.1 * W, yg + 0.16 * W, c[2] + 0.12 * W],
                    "target": [c[0] - 0.02 * W, yg, c[2] - 0.36 * W],
                    "up": [0, 1, 0], "fov": 58.0, "fov_axis": "x"},
        "top": {"origin": [c[0], float(ab_hi[1]) + 1.25 * W, c[2] + 1e-4],
                "target": [c[0], yg, c[2]], "up": [0, 0, -1], "fov": 46.0,
                "fov_axis": "smaller"},
    }
    sc = _scene_camera(terrain) if want("scene") else None
    out["scene"] = sc if sc is not None else dict(out["overview"])
    for name, cam in (scn.get("render.cameras", {}) or {}).items():
        if not want(name):
            continue
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


def sensor_dict(scn, terrain, options, film: dict, moss=None, trees=None) -> dict:
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
    moss, trees : optional
        What the run grew, for the presets that look at it (:func:`presets`).

    Returns
    -------
    dict
        The sensor dict (id ``"camera"``) for ``mi.load_dict``.

    Raises
    ------
    ParameterError
        If ``options.camera`` is not a preset of the scenario.
    """
    cams = presets(scn, terrain, moss, trees, only=options.camera)
    if options.camera not in cams:
        cams = presets(scn, terrain, moss, trees)           # the error lists them all
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
