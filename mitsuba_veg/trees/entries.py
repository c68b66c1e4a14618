"""Checks of a scenario's ``[[render.trees]]`` entries without building the trees.

``mitsuba-veg run`` checks them before the first day (a typo in a Weber-Penn override is
refused by the run, not only later by the render); :func:`mitsuba_veg.render.trees.make_tree`
builds the tree from a checked entry.
"""
from __future__ import annotations

import dataclasses
import difflib

from ..errors import ParameterError
from . import weber_penn
from .growth import GrowthParams

__all__ = ["RENDER_TREE_FIELDS", "RENDER_TREE_MODELS", "check_render_tree", "check_render_trees"]

#: fields of a ``[[render.trees]]`` entry
RENDER_TREE_FIELDS = ("preset", "model", "seed", "position", "height", "autumn", "overrides",
                      "generations", "growth")
#: tree models of the render
RENDER_TREE_MODELS = ("weber_penn", "growth", "simple")


def check_render_tree(cfg: dict, source: str | None = None, field: str = "render.trees") -> None:
    """Refuse a ``[[render.trees]]`` entry the render would refuse: an unknown field or model,
    an unknown Weber-Penn preset or parameter in ``overrides``, an unknown ``growth`` field.

    Parameters
    ----------
    cfg : dict
        The entry.
    source : str, optional
        The scenario file, for messages; default None.
    field : str, optional
        The entry's dotted name, for messages; default ``"render.trees"``.

    Raises
    ------
    ParameterError
        Naming the field (``render.trees.overrides.LeafScal``), the value and the known names.
    """
    if not isinstance(cfg, dict):
        raise ParameterError(field, cfg, "a table of " + ", ".join(RENDER_TREE_FIELDS), None,
                             source)
    for k in cfg:
        if k not in RENDER_TREE_FIELDS:
            raise ParameterError(f"{field}.{k}", cfg[k], "one of " +
                                 ", ".join(sorted(RENDER_TREE_FIELDS)),
                                 "remove or rename the field", source)
    model = cfg.get("model", "weber_penn")
    if model not in RENDER_TREE_MODELS:
        raise ParameterError(f"{field}.model", model, "one of " + ", ".join(RENDER_TREE_MODELS),
                             None, source)
    if model == "weber_penn":
        try:
            p = weber_penn.load_params(cfg.get("preset", "quaking_aspen"))
            if cfg.get("overrides"):
                p.updated(cfg["overrides"])
        except ParameterError as e:
            name = e.field if e.field == "preset" else f"overrides.{e.field}"
            known = e.allowed.split(": ", 1)[-1].split(", ")
            close = difflib.get_close_matches(str(e.field).rpartition(".")[2], known, n=2,
                                              cutoff=0.6)
            fix = ("did you mean " + " or ".join(repr(c) for c in close) + "? " if close
                   else "") + (e.fix or "")
            raise ParameterError(f"{field}.{name}", e.value, e.allowed, fix, source) from None
    elif model == "growth":
        growth = cfg.get("growth") or {}
        known = [f.name for f in dataclasses.fields(GrowthParams)]
        if not isinstance(growth, dict):
            raise ParameterError(f"{field}.growth", growth, "a table of growth parameters",
                                 None, source)
        for k in growth:
            if k not in known:
                raise ParameterError(f"{field}.growth.{k}", growth[k], "one of " +
                                     ", ".join(known), "check the spelling (docs/trees.md)",
                                     source)


def check_render_trees(entries, source: str | None = None) -> None:
    """:func:`check_render_tree` for every entry of ``[[render.trees]]``.

    Parameters
    ----------
    entries : list of dict or dict or None
        The scenario's ``render.trees`` (None: nothing to check).
    source : str, optional
        The scenario file, for messages; default None.

    Raises
    ------
    ParameterError
        For the first entry the render would refuse.
    """
    if isinstance(entries, dict):
        entries = [entries]
    for cfg in entries or ():
        check_render_tree(cfg, source)
