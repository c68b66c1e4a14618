"""The ``mitsuba-veg`` command (the top layer: nothing in the library imports it).

- :mod:`.command` the command and its own sub-commands (demo, run, irradiance);
- :mod:`.args`    the options and checks every sub-command shares;
- :mod:`.entry`   running a parsed command: one-line errors and exit codes;
- :mod:`.grow`    ``mitsuba-veg grow``; :mod:`.render` ``render`` and ``animate``;
  :mod:`.sweep` ``sweep``.

``python -m mitsuba_veg.cli ...`` is the same as ``mitsuba-veg ...``.
"""
from __future__ import annotations

__all__ = ["main", "build_parser", "run_parsed", "standalone", "run_irradiance"]


def __getattr__(name):
    # The command's functions load on first use, so that importing ``mitsuba_veg.cli.args``
    # (the shared options) does not import every command: the parser of ``tune/cli.py`` still
    # lives outside this package and imports it.
    if name in __all__:
        from . import command
        return getattr(command, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
