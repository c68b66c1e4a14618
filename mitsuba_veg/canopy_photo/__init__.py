"""Hemispherical canopy photographs of a world and what field instruments would read there,
against the truth the simulation knows (docs/hemiphoto.md):

- :mod:`.run_day`: a run's day as a camera sees it (its trees, their leaves' state);
- :mod:`.light_truth`: a photon pass of the day at photo points (direct and scattered shares
  of the open's sky and sun light);
- :mod:`.colour`: a colour photograph through the ``veg_fisheye`` lens (spectral render);
- :mod:`.hemiphoto`: ``mitsuba-veg hemiphoto RUN_DIR`` (:func:`run_hemiphoto`);
- :mod:`.world_light`: light studies under a world's trees in their leaf state on each date
  (:func:`run_world_sensor_study`).

The photograph itself (the ``veg_fisheye`` sensor, the ray-cast gap image, the gap fractions,
LAI and site factors) is in the light layer (:mod:`mitsuba_veg.integrators.veg_fisheye`,
:mod:`mitsuba_veg.light.fisheye`, :mod:`mitsuba_veg.light.gap_fraction`), the visible canopy
and its true area index in the models layer (:mod:`mitsuba_veg.world.visible_canopy`) and
the run's ``[[hemiphotos]]`` in the daily loop (:mod:`mitsuba_veg.daily.hemiphotos`).
"""
from __future__ import annotations

from .hemiphoto import run_hemiphoto
from .run_day import RunWorld
from .world_light import run_world_sensor_study

__all__ = ["run_hemiphoto", "RunWorld", "run_world_sensor_study"]
