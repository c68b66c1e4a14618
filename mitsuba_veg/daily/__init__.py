"""The day as one device-resident pipeline of stages (paper 000 §3.7 with the world's trees),
shared by a run, the world and tuning:

- :mod:`.config`      the run's settings from its scenario (:class:`MossConfig`, defaults);
- :mod:`.site`        the light scene and the surfaces, built once (:class:`Site`,
  :func:`build_site`, :func:`prepare_site` for tuning);
- :mod:`.inputs`      every day's weather, sun path and band shapes, computed at set-up;
- :mod:`.leaves`, :mod:`.light`, :mod:`.soil`, :mod:`.moss`, :mod:`.record`  the stages;
- :mod:`.pipeline`    :class:`DayPipeline` (one day, the stages composed) and
  :class:`Simulation` (the loop over the days, checkpoints, summary);
- :mod:`.checkpoint`  saving and resuming the state;
- :mod:`.run`         one run into a folder: :func:`mitsuba_veg.daily.run.run`, also
  ``mitsuba_veg.run``.

A scenario without ``[[trees]]`` is a world without trees: the same pipeline without the
leaves stage.
"""
from __future__ import annotations

from .config import BANDS, MOSS_DEFAULTS, SIM_DEFAULTS, MossConfig
from .inputs import DayInputs, band_shapes, band_shapes_days
from .pipeline import DayPipeline, DayState, Interrupted, Simulation
from .site import Site, build_site, prepare_site

__all__ = ["BANDS", "MOSS_DEFAULTS", "SIM_DEFAULTS", "MossConfig", "Site", "build_site",
           "prepare_site", "DayInputs", "band_shapes", "band_shapes_days", "DayPipeline",
           "DayState", "Simulation", "Interrupted"]
