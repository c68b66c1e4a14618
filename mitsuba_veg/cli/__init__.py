"""The ``mitsuba-veg`` command (the top layer: nothing in the library imports it).

- :mod:`.command` the command and its own sub-commands (demo, run, irradiance);
- :mod:`.args`    the options and checks every sub-command shares;
- :mod:`.entry`   running a parsed command: one-line errors and exit codes;
- :mod:`.grow`    ``mitsuba-veg grow``; :mod:`.render` ``render`` and ``animate``;
  :mod:`.sweep` ``sweep``; :mod:`.light_study` ``light-study``; :mod:`.tune` ``tune``.

``python -m mitsuba_veg.cli ...`` is the same as ``mitsuba-veg ...``.
"""
from __future__ import annotations

from .command import build_parser, main, run_irradiance
from .entry import run_parsed, standalone

__all__ = ["main", "build_parser", "run_parsed", "standalone", "run_irradiance"]
