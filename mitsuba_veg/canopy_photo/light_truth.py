"""The light's truth at photo points: a photon pass of the day's scene with enough photons for
a point, its direct and scattered light apart.

The scene is the day's world as :class:`~mitsuba_veg.world.visible_canopy.VisibleCanopy`
builds it (the scenario's shapes with their BSDFs, the wood, the shown leaves with the
PROSPECT-D optics of their stage) with the daily loop's two emitters, each normalised to a unit
horizontal irradiance of the open (:mod:`mitsuba_veg.daily.site`): an isotropic ``veg_sky`` of
radiance 1/π W m-2 sr-1 nm-1 and the day's ``veg_sun_path`` (every sun position of the day,
weighted by its clear-sky beam). At each point a horizontal cosine sensor (a square of side
``size``, facing up, at the lens's height; :mod:`mitsuba_veg.light.sensors`) records the
photons that cross it without blocking any, split by the pass into *direct* (not scattered
yet: the light that came straight through the canopy's gaps) and *scattered* light, per
emitter. An open sensor above the highest point of the scene reads the open's irradiance in
the same pass.

Shares (irradiance at the point / the open's horizontal irradiance of the same emitter, PAR):

- ``sky_direct_share``: the sky light that reaches the point unscattered: what the diffuse
  site factor of a photograph (its gaps weighted by cos θ and the uniform sky's radiance)
  estimates;
- ``sky_scattered_share``: the sky light that reaches it after scattering by leaves, wood and
  ground (a photograph does not see it);
- ``sun_direct_share``, ``sun_scattered_share``: the same for the day's sun (the direct one is
  what the photograph's direct site factor over the day's sun path estimates).

The open's irradiance of each emitter is exactly its band width × 1 W m-2 nm-1 (the
normalisation); the open sensor's own reading checks it and is returned
(``open_sky_share``, ``open_sun_share``: 1 within their noise). Noise: a sensor of side s in a
scene whose photons are spread over an aiming area A receives ~N s²/A of N photons
(:mod:`mitsuba_veg.light.sensors`), so the relative standard error of a share q is about
sqrt((1 − q)/(n q)) for n = N s²/A; ``sky_direct_share_se`` estimates it from
the pass's own sensor counts (binomial over the photons that reach the sensor's area).
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import check_range
from ..integrators.photon_irradiance import BANDS
from ..light import sensors as S
from ..light.photon import photon_irradiance
from ..light.sunpath import day_sun_path
from ..meshes import make_mesh

__all__ = ["light_truth", "SKY", "SUN", "DEFAULT_SIZE", "DEFAULT_PHOTONS"]

#: the emitters of the light truth, by name
SKY, SUN = "sky", "sun"
#: default side of the point's sensor [m] and photons of the sky pass
DEFAULT_SIZE, DEFAULT_PHOTONS = 0.3, 20_000_000
_BAND = "par"


def _emitters():
    return {SUN: {"type": "veg_sun_path", "id": SUN},
            SKY: {"type": "veg_sky", "id": SKY, "distribution": "uniform",
                  "radiance": {"type": "uniform", "value": 1.0 / math.pi}}}


def light_truth(canopy, base_shapes, state, positions, date, latitude: float,
                longitude: float, photons: int = DEFAULT_PHOTONS,
                sun_photons: int | None = None, size: float = DEFAULT_SIZE, seed: int = 0,
                max_depth: int = 8, repeats: int = 4) -> list[dict]:
    """Direct and scattered shares of the open's sky and sun light at points (module
    docstring).

    Parameters
    ----------
    canopy : VisibleCanopy
        The day's trees.
    base_shapes : sequence of mitsuba.Shape
        The scenario's shapes (terrain, walls) with their BSDFs.
    state : LeafState
        The day's leaves.
    positions : array_like
        (n, 3) sensor centres [m] (the photo points' lenses).
    date : datetime.date
        The day (its sun path).
    latitude, longitude : float
        The site [deg].
    photons : int
        Photons of the sky pass.
    sun_photons : int, optional
        Photons of the sun pass (default ``photons`` / 2; 0: no sun pass).
    size : float
        Side of each point's sensor [m].
    seed : int
        Random seed.
    max_depth : int
        Bounces per photon.
    repeats : int
        Independent parts of each pass (different seeds, the photons shared out): the
        standard error of a share is their standard deviation / sqrt(repeats).

    Returns
    -------
    list of dict
        Per point: ``sky_direct_share``, ``sky_scattered_share``, ``sun_direct_share``,
        ``sun_scattered_share`` [-] and the standard errors ``sky_direct_share_se``,
        ``sun_direct_share_se``, ``open_sky_share``,
        ``open_sun_share`` (the open sensor, 1 within noise), ``sensor_size_m``,
        ``photons`` (sky pass), ``seconds``.
    """
    t0 = time.perf_counter()
    check_range("size", size, 0.01, 10.0, fix="sensor side in metres, e.g. 0.3")
    pos = np.asarray(positions, float).reshape(-1, 3)
    n = len(pos)
    names = [f"point{i}" for i in range(n)]
    sset = None
    for nm, p in zip(names, pos):
        s = S.point(nm, p, kind="cosine", size=size)
        sset = s if sset is None else sset + s
    emitters = _emitters()
    # the open: above the highest point of the world (the sensor mesh joins the scene's box,
    # so photons aimed at the box reach it from every direction of the sky)
    probe = canopy.scene(base_shapes, state, optics=False)
    top = float(probe.bbox().max[1]) + 0.5
    mid = np.asarray(probe.bbox().center(), float)
    del probe
    sset = sset + S.point("open", [mid[0], top, mid[2]], kind="cosine", size=size)
    v, f, owner = sset.mesh()
    scene = canopy.scene(base_shapes, state, optics=True, emitters=emitters,
                         extra={S.SENSOR_SHAPE: make_mesh(S.SENSOR_SHAPE, v, f, albedo=0.0)})
    ems = {e.id(): e for e in scene.emitters()}
    dirs, w, _ = day_sun_path(latitude, longitude, date)
    sun_photons = int(photons // 2 if sun_photons is None else sun_photons)
    has_sun = len(w) > 0 and sun_photons > 0
    if has_sun:
        ems[SUN].set_day(dirs, w)
    check_range("repeats", repeats, 1, 64)
    lo, hi = BANDS[_BAND]
    width = hi - lo
    area = sset.normalising_area()
    out = [dict() for _ in range(n)]
    opened = {}
    for em, count in ((SKY, int(photons)), (SUN, sun_photons if has_sun else 0)):
        if count <= 0:
            continue
        # the pass in ``repeats`` independent parts (seeds): their spread is the noise
        parts = []
        for k in range(int(repeats)):
            r = photon_irradiance(scene, photons=max(count // int(repeats), 1),
                                  seed=(int(seed) * 1009 + k * 7919 + (0 if em == SKY else 1))
                                  & 0x7FFFFFFF, max_depth=int(max_depth), bands=(_BAND,),
                                  emitters=[em], modes={S.SENSOR_SHAPE: "sensor"})
            e = list(r.emitters).index(em)
            sl = r.index.shape_slice(S.SENSOR_SHAPE)
            b = list(r.bands).index(_BAND)
            f = r.flux[e, sl, :, 0, b]                              # (faces, comp)
            per = np.zeros((len(sset), 2))
            np.add.at(per, owner, f)
            parts.append(per / area[:, None] / width)
            del r
        share = np.mean(parts, axis=0)
        se = np.std(parts, axis=0, ddof=1) / math.sqrt(len(parts)) if len(parts) > 1 else \
            np.full(share.shape, math.nan)
        opened[em] = float(share[-1].sum())
        for i in range(n):
            out[i][f"{em}_direct_share"] = float(share[i, 0])
            out[i][f"{em}_scattered_share"] = float(share[i, 1])
            out[i][f"{em}_direct_share_se"] = float(se[i, 0])
    for i in range(n):
        out[i]["open_sky_share"] = opened.get(SKY, math.nan)
        out[i]["open_sun_share"] = opened.get(SUN, math.nan)
        if not has_sun:
            out[i]["sun_direct_share"] = out[i]["sun_scattered_share"] = math.nan
        out[i]["sensor_size_m"] = float(size)
        out[i]["photons"] = float(photons)
        out[i]["seconds"] = time.perf_counter() - t0
    return out

