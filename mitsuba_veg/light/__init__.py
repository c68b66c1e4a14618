"""Light: sun position, daylight spectra (sun + sky emitters) and the photon-irradiance pass.

- :func:`photon_irradiance` traces photons from a scene's emitters and returns per-triangle
  incident irradiance [W m-2] per band, split direct / indirect (paper 000 §3.4).
- :func:`sun_position` gives the solar azimuth/elevation [deg] (NREL SPA).
- :func:`daylight` gives Mitsuba emitter dicts for sun and sky with spectra over 300-4000 nm.

The Mitsuba plugins (the ``veg_sky``, ``veg_sun_path`` and ``veg_sun_steps`` emitters, the
photon-irradiance integrator) are in :mod:`mitsuba_veg.integrators`; this package holds their
models (:mod:`.sky`, :mod:`.sunpath`) and the functions that run them.
"""
from __future__ import annotations

from .photon import photon_irradiance, PhotonIrradianceResult, BANDS, band_range
from .solar_position import sun_position, sun_direction, direction_to_angles, sun_ephemeris
from .clear_sky import daylight, daylight_from_angles, clear_sky_spectra
from . import sky  # noqa: F401  (the sky radiance model of the `veg_sky` emitter)
from . import sunpath  # noqa: F401  (sun paths: the directions of the `veg_sun_path` emitter)
from . import sensors  # noqa: F401  (virtual sensors: mv.light.sensors.point/grid/read)

__all__ = ["photon_irradiance", "PhotonIrradianceResult", "BANDS", "band_range",
           "sun_position", "sun_direction", "direction_to_angles", "sun_ephemeris", "daylight",
           "daylight_from_angles", "clear_sky_spectra"]
