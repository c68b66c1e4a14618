"""Command-line arguments shared by every ``mitsuba-veg`` sub-command.

One parser class (errors on one line, exit code 2), one help formatter (every option shows its
default), typed and range-checked option values, and the options that several commands share
(``--out``, ``--set``, ``--quiet``, ``--photons``).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import math
import sys

from ..defaults import LIGHT, range_text


__all__ = ["HelpFormatter", "Parser", "ranged", "iso_datetime", "out_dir", "add_out", "add_set",
           "add_quiet", "add_photons", "light_type"]

class HelpFormatter(argparse.HelpFormatter):
    """Help that shows each option's default (when it has one) after its text."""

    def _get_help_string(self, action):
        h = action.help or ""
        if action.default not in (None, False, argparse.SUPPRESS) and "%(default)" not in h \
                and action.option_strings and "default" not in h:
            h += " (default: %(default)s)"
        return h


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (``PROG: error: ...``, exit code 2)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):  # noqa: D401 - argparse API
        """Print ``PROG: error: MESSAGE (see `PROG --help`)`` on one line to stderr and exit with 2.

        Overrides :meth:`argparse.ArgumentParser.error` (never returns).

        Parameters
        ----------
        message : str
            The argparse error message (whitespace runs collapsed to one space).
        """
        msg = " ".join(str(message).split())
        sys.stderr.write(f"{self.prog}: error: {msg} (see `{self.prog} --help`)\n")
        sys.exit(2)


def ranged(kind, lo=None, hi=None, unit: str = "", name: str | None = None):
    """An argparse ``type`` that parses a number and checks its range.

    Parameters
    ----------
    kind : {int, float}
        The type (an integer also accepts ``1e6``).
    lo, hi : float, optional
        Inclusive bounds (None: open); the value must be finite.
    unit : str
        Unit shown in the error, e.g. ``"photons"``, ``"h"``.
    name : str, optional
        The type's name in argparse messages.

    Returns
    -------
    callable
        ``parse(text)``: the value, or ``argparse.ArgumentTypeError`` naming the value, the
        allowed range and the fix.
    """

    def parse(text: str):
        what = "an integer" if kind is int else "a number"
        lo_s = "-inf" if lo is None else f"{lo:g}"
        hi_s = "inf" if hi is None else f"{hi:g}"
        allowed = f"{what} in [{lo_s}, {hi_s}]" + (f" {unit}" if unit else "")
        try:
            v = kind(text)
        except (TypeError, ValueError):
            v = None
            if kind is int:  # 1e6 is a fine photon count
                try:
                    f = float(text)
                    v = int(f) if math.isfinite(f) and f == int(f) else None
                except (TypeError, ValueError, OverflowError):
                    v = None
        ok = v is not None and math.isfinite(v) and (lo is None or v >= lo) and \
            (hi is None or v <= hi)
        if not ok:
            raise argparse.ArgumentTypeError(f"{text!r} is invalid (allowed: {allowed}). Fix: "
                                             "give a value in the allowed range")
        return v

    parse.__name__ = name or ("integer" if kind is int else "number")
    return parse


def iso_datetime(text: str) -> str:
    """An argparse ``type`` for ``--when``: an ISO 8601 date-time.

    Parameters
    ----------
    text : str
        E.g. ``2026-04-20T10:00:00+09:00`` or ``2026-04-20T01:00:00Z``.

    Returns
    -------
    str
        The text as given (stripped).
    """
    t = text.strip()
    try:
        _dt.datetime.fromisoformat(t[:-1] + "+00:00" if t.endswith(("Z", "z")) else t)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid (allowed: an ISO 8601 date-time). Fix: write it like "
            "2026-04-20T10:00:00+09:00 (local time with its UTC offset) or 2026-04-20T01:00:00Z"
        ) from None
    return t


def out_dir(text: str) -> str:
    """An argparse ``type`` for ``--out``: a non-empty folder path.

    Parameters
    ----------
    text : str
        The path as given.

    Returns
    -------
    str
        The path, unchanged.
    """
    if not str(text).strip():
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid (allowed: a folder path; an empty one would be the current "
            "folder). Fix: give --out DIR (is a variable such as $OUTDIR unset?)")
    return text


def add_out(p, default: str | None, what: str) -> None:
    """Add ``--out DIR``: the output folder of ``what``.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The (sub-command) parser.
    default : str or None
        Default output path (None: the command picks one).
    what : str
        What the folder receives, for the help text.
    """
    p.add_argument("--out", default=default, metavar="DIR", type=out_dir,
                   help=f"output folder for {what} (created; refused if another process is "
                        "writing it, it holds another kind of result, or it holds files "
                        "mitsuba-veg did not write and is not an output folder)")


def add_set(p, what: str = "scenario", example: str = "light.photons=2000000") -> None:
    """Add ``--set KEY=VALUE`` (repeatable): override a field of the ``what`` file.

    Fields are named by their dotted names, values use TOML syntax; unknown fields are refused
    by the command.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The (sub-command) parser.
    what : str, optional
        The file whose fields are overridden (default ``"scenario"``), for the help text.
    example : str, optional
        An example override shown in the help (default ``"light.photons=2000000"``).
    """
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help=f"override a {what} field by its dotted name (TOML value syntax), "
                        f"e.g. --set {example}; unknown fields are refused")


def add_quiet(p, what: str = "no progress bar") -> None:
    """Add ``--quiet`` (``what`` it leaves out, for the help).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The (sub-command) parser.
    what : str, optional
        Help text of the flag (default ``"no progress bar"``).
    """
    p.add_argument("--quiet", action="store_true", help=what)


def add_photons(p, default: int | None, what: str = "per light pass") -> None:
    """Add ``--photons N``: photons ``what`` (range: ``defaults.LIGHT["photons"]``).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The (sub-command) parser.
    default : int or None
        Default photon count [photons]; None: the scenario's.
    what : str, optional
        What the count is per, for the help (default ``"per light pass"``).
    """
    p.add_argument("--photons", type=light_type("photons"), default=default,
                   metavar="N", help=f"photons {what} ({range_text('photons')})")


def light_type(name: str):
    """The argparse ``type`` of a light setting (``photons``, ``seed``, ``max_depth``): its
    range from the one table, :data:`mitsuba_veg.defaults.LIGHT`.

    Parameters
    ----------
    name : str
        Key of the table.

    Returns
    -------
    callable
        The ``type`` for ``add_argument``.
    """
    s = LIGHT[name]
    unit = {"photons": "photons", "max_depth": "bounces"}.get(name, "")
    return ranged(int, s.lo, s.hi, unit)
