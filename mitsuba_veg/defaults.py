"""The one table of the light pass's settings: default, allowed range and meaning of each.

Read by the scenario schema (``[light]``), the command line (``--photons``, ``--seed``,
``--max-depth``), the Python API (:func:`mitsuba_veg.light.photon_irradiance`) and the
``veg_photon_irradiance`` plugin's properties, so that a default or a bound is written once.

``photons`` is the total of one pass, shared among the emitters by power (each gets at least
5 %); ``max_depth`` counts surface hits (1: the direct light only); ``batch`` is how many
photons one kernel launch traces (memory, not results: a pass of more photons runs in batches
with the same random numbers).
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import check_range


__all__ = ["Setting", "MAX_PHOTONS", "LIGHT", "check_light", "range_text"]

@dataclass(frozen=True)
class Setting:
    """One setting: ``default``, closed range ``lo`` .. ``hi`` (None: unbounded), ``doc``
    (meaning and unit) and ``fix`` (how to choose a good value, for error messages)."""

    default: object
    lo: int | None
    hi: int | None
    doc: str
    fix: str | None = None


#: the largest photon count of one light pass: ~2 minutes on 2 CPU cores at ~8 M photons/s
#: (more gains little: the estimate's noise falls as 1/sqrt(N) and a day has other errors)
MAX_PHOTONS = 1_000_000_000

#: the light pass's settings by name: photons, max_depth, seed, indirect, batch
LIGHT: dict[str, Setting] = {
    "photons": Setting(1_000_000, 1, MAX_PHOTONS,
                       "photons of one light pass, shared among the emitters by power",
                       "e.g. 1000000 (noise falls as 1/sqrt(photons))"),
    "max_depth": Setting(8, 1, 1000, "surface hits per photon (1: direct light only)",
                         "max_depth counts surface hits, e.g. 8"),
    "seed": Setting(0, 0, 2**31 - 1, "random seed (same seed, same result)"),
    "indirect": Setting(True, None, None, "false: only the first hit is recorded"),
    "batch": Setting(1 << 22, 1024, None, "photons per kernel launch (memory, not results)"),
}


def check_light(name: str, value, label: str | None = None, source: str | None = None):
    """Check a light setting against :data:`LIGHT`; returns ``value``.

    Parameters
    ----------
    name : str
        Key of :data:`LIGHT` (``photons``, ``max_depth``, ``seed``, ``batch``).
    value : int
        The value.
    label : str, optional
        The name shown in the error (e.g. ``--photons`` or ``light.photons``); default
        ``name``.
    source : str, optional
        File the value comes from, for the message.

    Returns
    -------
    int
        ``value``, unchanged.

    Raises
    ------
    ParameterError
        When it lies outside the setting's range.
    """
    s = LIGHT[name]
    return check_range(label or name, value, s.lo, s.hi, fix=s.fix, source=source)


def range_text(name: str) -> str:
    """The allowed range of a light setting as text.

    For example ``"1 .. 1e9"`` for ``photons``.

    Parameters
    ----------
    name : str
        Key of :data:`LIGHT`.

    Returns
    -------
    str
        ``"lo .. hi"`` (``">= lo"`` without an upper bound).
    """
    s = LIGHT[name]

    def fmt(v):
        return f"{v:.0e}".replace("e+0", "e") if v >= 10**6 else str(v)
    return f"{fmt(s.lo)} .. {fmt(s.hi)}" if s.hi is not None else f">= {fmt(s.lo)}"
