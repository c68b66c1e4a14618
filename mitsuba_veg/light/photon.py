"""The photon-irradiance pass as a function: per-triangle incident irradiance of a scene.

See :mod:`mitsuba_veg.integrators.photon_irradiance` for the method (paper 000 §3.4).
"""
from __future__ import annotations

import mitsuba as mi

from mitsuba_veg.integrators.photon_irradiance import (  # noqa: F401
    BANDS, DEFAULT_BANDS, PhotonIrradianceIntegrator, PhotonIrradianceResult, band_range)

_integrator: PhotonIrradianceIntegrator | None = None


def photon_irradiance(scene: mi.Scene, photons: int = 1_000_000, seed: int = 0,
                      max_depth: int = 8, bands=DEFAULT_BANDS, indirect: bool = True,
                      reflectance: dict | None = None, emitters=None,
                      progress: bool = False) -> PhotonIrradianceResult:
    """Trace ``photons`` photons from the emitters of ``scene``; irradiance per triangle.

    Parameters
    ----------
    scene: a loaded ``mi.Scene`` whose meshes have ids (load with ``optimize=False``).
    photons: total photons, shared among emitters by power (>= 5 % each).
    seed: random seed (same seed, same result).
    max_depth: maximum surface hits per photon (1 = direct light only).
    bands: band names from :data:`BANDS` ("total" 360-830 nm, "par" 400-700 nm, "red" 655-665
        nm, "far_red" 725-735 nm, ...) or (min_nm, max_nm) pairs.
    indirect: False records only the first hit (no diffuse inter-reflection; paper fig 4.2).
    reflectance: ``{shape_id: albedo per triangle}`` overriding the BSDF (Lambertian): shape
        (n,) grey or (n, len(bands)) per band; NaN keeps the BSDF. Lets moss cover change the
        light without rebuilding the scene.
    emitters: ids or indices of the emitters to trace (default all).

    Returns a :class:`PhotonIrradianceResult`: ``.irradiance(shape_id, band, component)``
    [W m-2] one value per triangle, ``.rays_traced``, energy bookkeeping.
    """
    global _integrator
    if _integrator is None:
        _integrator = PhotonIrradianceIntegrator()
    return _integrator.trace(scene, photons=photons, seed=seed, max_depth=max_depth, bands=bands,
                             indirect=indirect, reflectance=reflectance, emitters=emitters,
                             progress=progress)
