"""Errors raised at the package's boundaries.

Every message names what is wrong (file, field, value), the allowed range and the fix, so that a
user never has to read a traceback from inside a kernel.
"""
from __future__ import annotations

import difflib
import math
import re


__all__ = ["MitsubaVegError", "VariantError", "ParameterError", "FolderBusy", "SceneError",
           "plugin_error", "check_range", "DependencyError", "unknown_field"]

class MitsubaVegError(Exception):
    """Base class of all mitsuba-veg errors."""


class VariantError(MitsubaVegError, RuntimeError):
    """The active Mitsuba variant cannot be used (e.g. an RGB variant)."""


class ParameterError(MitsubaVegError, ValueError):
    """A parameter or scenario field has a value outside its allowed range.

    The message reads
    ``"<source>: <field> = <value> is invalid (allowed: <allowed>). Fix: <fix>"``.

    Parameters
    ----------
    field : str
        The field or argument (dotted scenario name, CLI option ...).
    value : object
        The offending value.
    allowed : str
        What is allowed (a range with units, a list of choices ...).
    fix : str, optional
        How to fix it; default None.
    source : str, optional
        The file the value comes from; default None.
    """

    def __init__(self, field: str, value, allowed: str, fix: str | None = None,
                 source: str | None = None):
        self.field, self.value, self.allowed, self.fix, self.source = field, value, allowed, fix, source
        where = f"{source}: " if source else ""
        msg = f"{where}{field} = {value!r} is invalid (allowed: {allowed})"
        if fix:
            msg += f". Fix: {fix}"
        super().__init__(msg)


class FolderBusy(ParameterError):
    """An output folder is in use by another process (its lock is held): the refusal of
    :class:`mitsuba_veg.outputs.OutputFolder`, which a sweep retries."""


class SceneError(MitsubaVegError, ValueError):
    """A scene lacks something a computation needs (a shape id, an emitter, a file ...)."""


def plugin_error(exc: BaseException) -> str:
    """The message of an error raised inside a Python plugin's constructor, without Mitsuba's
    wrapping.

    A loader that fails to build a plugin raises ``RuntimeError("... failed to
    instantiate <kind> plugin of type "<name>": Traceback ... <Error>: <message>")``; this
    returns ``'<where>: <message>'`` (``where`` = the XML position and plugin), or the whole
    message, whitespace collapsed, when it is not such an error.

    Parameters
    ----------
    exc : BaseException
        The error.

    Returns
    -------
    str
        One line.
    """
    text = str(exc)
    if "Traceback (most recent call last)" in text:
        head = text.split("Traceback (most recent call last)")[0].rstrip(" :\n")
        last = [ln.strip() for ln in text.splitlines() if ln.strip()][-1]
        m = re.match(r"^[A-Za-z_][\w.]*(Error|Exception): (.*)$", last)
        if m:
            return f"{' '.join(head.split())}: {m.group(2)}"
    return " ".join(text.split())


def check_range(field: str, value, lo=None, hi=None, *, lo_open=False, hi_open=False,
                fix: str | None = None, source: str | None = None):
    """Raise :class:`ParameterError` unless ``lo <= value <= hi`` (bounds optional/open).

    NaN is always rejected. Returns ``value`` so that it can be used inline.

    Parameters
    ----------
    field : str
        Name of the checked field (dotted scenario name or argument), for the message.
    value : float or int
        The value, in the field's own unit; it must convert to float.
    lo, hi : float, optional
        Bounds, in the unit of ``value``; default None: unbounded on that side.
    lo_open, hi_open : bool, optional
        Exclude the bound itself; default False (closed).
    fix : str, optional
        How to fix a bad value, for the message; default None.
    source : str, optional
        File the value comes from, for the message; default None.

    Returns
    -------
    float or int
        ``value`` itself, unchanged.

    Raises
    ------
    ParameterError
        If ``value`` is not a number, is NaN or lies outside the bounds.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(field, value, "a number", fix, source) from None
    lo_s = "-inf" if lo is None else repr(lo)
    hi_s = "inf" if hi is None else repr(hi)
    allowed = f"{'(' if lo_open else '['}{lo_s}, {hi_s}{')' if hi_open else ']'}"
    bad = math.isnan(v)
    if lo is not None:
        bad |= v <= lo if lo_open else v < lo
    if hi is not None:
        bad |= v >= hi if hi_open else v > hi
    if bad:
        raise ParameterError(field, value, allowed, fix, source)
    return value


class DependencyError(MitsubaVegError, ImportError):
    """An optional dependency that a feature needs is not installed (the message names the
    ``pip install`` that adds it)."""


def unknown_field(field: str, value, known, source: str | None = None,
                  doc: str | None = None) -> ParameterError:
    """The error for a field a file or ``--set`` names but no schema knows.

    The fix names the closest known names (whole dotted names first, else the last part among its
    table's fields); the fields of the same table are given as what is allowed.

    Parameters
    ----------
    field : str
        The unknown dotted field name.
    value : object
        Its value, for the message.
    known : iterable of str
        Every known dotted field name.
    source : str, optional
        File the field comes from; default None.
    doc : str, optional
        Where the fields are listed (e.g. ``"docs/scenario.md"``); default None.

    Returns
    -------
    ParameterError
        The error to raise (not raised here).
    """
    known = sorted(set(known))
    head, _, last = field.rpartition(".")
    # a field of a table written at the top (``seed = 3``): the fields of that name first
    close = [k for k in known if "." in k and k.rpartition(".")[2] == field][:3] if not head \
        else []
    close = close or difflib.get_close_matches(field, known, n=3, cutoff=0.6)
    siblings = [k for k in known if k.rpartition(".")[0] == head]
    if not close:  # a misspelt last part: compare within the same table
        near = difflib.get_close_matches(last, [k.rpartition(".")[2] for k in siblings], n=3,
                                         cutoff=0.5)
        close = [k for k in siblings if k.rpartition(".")[2] in near]
    fix = ("did you mean " + " or ".join(repr(c) for c in close) + "?") if close else \
        "remove or rename it" + (f" ({doc} lists the fields)" if doc else "")
    pool = siblings or known
    allowed = "a known field (" + ", ".join(pool[:12]) + (", ..." if len(pool) > 12 else "") + ")"
    return ParameterError(field, value, allowed, fix, source)
