"""The moss daily loop of paper 000 (§3.7), in four parts:

- :mod:`.config`      the run's settings from its scenario (:class:`MossConfig`, defaults);
- :mod:`.site`        site preparation, shared with tuning (:class:`MossSite`,
  :func:`prepare_site`);
- :mod:`.day`         the day step and the loop over the days (:class:`MossSimulation`);
- :mod:`.checkpoint`  saving and resuming the state (:class:`Checkpoints`);
- :mod:`.run`         one run into a folder (the world's loop when the scenario has trees):
  :func:`mitsuba_veg.daily.run.run`, also ``mitsuba_veg.run``.

:mod:`.run` is not imported here: it sits above :mod:`mitsuba_veg.world`, which builds on
:class:`MossSimulation`.
"""
from __future__ import annotations

from .checkpoint import Checkpoints
from .config import BANDS, MOSS_DEFAULTS, SIM_DEFAULTS, MossConfig
from .day import Interrupted, MossSimulation
from .site import MossSite, prepare_site

__all__ = ["BANDS", "MOSS_DEFAULTS", "SIM_DEFAULTS", "MossConfig", "MossSite", "prepare_site",
           "Checkpoints", "MossSimulation", "Interrupted"]
