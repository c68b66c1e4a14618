"""The photon-irradiance pass as a function: per-element incident irradiance of a scene.

A thin wrapper over the Mitsuba plugin ``veg_photon_irradiance``: the keyword arguments become
the plugin's properties, and the pass is the one ``mi.render`` runs with that integrator. See
:mod:`mitsuba_veg.integrators.photon_irradiance` for the method (paper 000 §3.4).
"""
from __future__ import annotations

import mitsuba as mi

from mitsuba_veg.defaults import LIGHT, check_light
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.integrators.photon_irradiance import (  # noqa: F401
    BANDS, DEFAULT_BANDS, DEFAULT_BATCH, PhotonIrradianceIntegrator, PhotonIrradianceResult,
    band_range)

__all__ = ["BANDS", "DEFAULT_BANDS", "DEFAULT_BATCH", "PhotonIrradianceIntegrator",
           "PhotonIrradianceResult", "band_range", "integrator", "photon_irradiance"]


def _band_property(bands) -> str:
    """Bands as the plugin's ``bands`` string: names, and ranges as ``"min-max"`` [nm]."""
    if isinstance(bands, str):
        bands = (bands,)
    items = []
    for b in bands:
        if isinstance(b, str):
            band_range(b)
            items.append(b)
        else:
            lo, hi = band_range(b)
            items.append(f"{lo!r}-{hi!r}")
    if not items:
        raise ParameterError("bands", bands, "at least one band", "e.g. bands=('total',)")
    return ",".join(items)


def integrator(photons: int = LIGHT["photons"].default, seed: int = LIGHT["seed"].default,
               max_depth: int = LIGHT["max_depth"].default, bands=DEFAULT_BANDS,
               indirect: bool = LIGHT["indirect"].default,
               batch: int = DEFAULT_BATCH) -> PhotonIrradianceIntegrator:
    """The ``veg_photon_irradiance`` plugin with these properties (what a scene file declares).

    Parameters
    ----------
    photons : int
        Total photons, shared among emitters by power (>= 5 % each).
    seed : int
        Random seed, 0 .. 2^31 - 1.
    max_depth : int
        Maximum surface hits per photon, 1 .. 1000.
    bands : sequence
        Band names of :data:`BANDS` or (min_nm, max_nm) pairs [nm].
    indirect : bool
        False records only the first hit.
    batch : int
        Photons per kernel launch (>= 1024).

    Returns
    -------
    PhotonIrradianceIntegrator
        The loaded Mitsuba integrator.
    """
    # checked here too: an error raised inside mi.load_dict would reach the caller re-wrapped
    for name, v in (("photons", photons), ("max_depth", max_depth), ("seed", seed),
                    ("batch", batch)):
        check_light(name, v)
    return mi.load_dict({"type": "veg_photon_irradiance", "photons": int(photons),
                         "seed": int(seed), "max_depth": int(max_depth),
                         "bands": _band_property(bands), "indirect": bool(indirect),
                         "batch": int(batch)})


def photon_irradiance(scene: mi.Scene, photons: int = LIGHT["photons"].default,
                      seed: int = LIGHT["seed"].default,
                      max_depth: int = LIGHT["max_depth"].default, bands=DEFAULT_BANDS,
                      indirect: bool = LIGHT["indirect"].default,
                      reflectance: dict | None = None, emitters=None,
                      progress: bool = False, modes: dict | None = None
                      ) -> PhotonIrradianceResult:
    """Trace ``photons`` photons from the emitters of ``scene``; irradiance per element.

    Same pass as ``mi.render(scene)`` with ``<integrator type="veg_photon_irradiance">`` and
    these properties (``result.tensor()`` equals that render's output for the same seed).

    Parameters
    ----------
    scene : mi.Scene
        A loaded scene whose meshes have ids (load with ``optimize=False``).
    photons : int
        Total photons, shared among emitters by power (>= 5 % each).
    seed : int
        Random seed (same seed, same result).
    max_depth : int
        Maximum surface hits per photon (1 = direct light only).
    bands : sequence
        Band names from :data:`BANDS` ("total" 360-830 nm, "par" 400-700 nm, "red" 655-665 nm,
        "far_red" 725-735 nm, ...) or (min_nm, max_nm) pairs [nm].
    indirect : bool
        False records only the first hit (no diffuse inter-reflection; paper fig 4.2).
    reflectance : dict, optional
        ``{shape_id: albedo per triangle}`` overriding the BSDF (Lambertian): shape (n,) grey or
        (n, len(bands)) per band; NaN keeps the BSDF. Lets moss cover change the light without
        rebuilding the scene.
    emitters : sequence, optional
        Ids or indices of the emitters to trace (default all).
    progress : bool
        Show a progress bar.
    modes : dict, optional
        ``{shape_id: "surface" | "sensor" | "hidden" | per-triangle array}``: a sensor records
        the photons that cross it and lets them pass (a virtual sensor that casts no shadow);
        a hidden shape lets them pass unrecorded (see the integrator's ``trace``).

    Returns
    -------
    PhotonIrradianceResult
        ``.irradiance(shape_id, band, component)`` [W m-2] one value per triangle (instances by
        instance id), ``.tensor()`` (element x band x component x side), ``.rays_traced``,
        energy bookkeeping [W], ``.single_element_shapes``.
    """
    integ = integrator(photons=photons, seed=seed, max_depth=max_depth, bands=bands,
                       indirect=indirect)
    return integ.trace(scene, reflectance=reflectance, emitters=emitters, progress=progress,
                       modes=modes)
