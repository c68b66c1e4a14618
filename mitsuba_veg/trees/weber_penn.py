"""Weber & Penn (1995) parametric trees with knots and smooth junctions (paper 004).

``generate(preset_or_params, seed=0)`` grows a tree from the parameters of Weber & Penn's
"Creation and Rendering of Realistic Trees" (SIGGRAPH '95) and returns the package's shared
:class:`~mitsuba_veg.trees.structure.Tree` (segments with radii, parents, levels and kinds, plus
leaves), so the growth / non-growth models and the renderer can use it. Knots from dormant buds
(paper 004 §3.3, :mod:`.knots`) are grown as stunted branches (``kind`` KNOT, SPROUTED_KNOT);
:func:`mesh` builds one bark mesh (UVs, junctions smoothed by paper 004 §4, :mod:`.junction`) and
one leaf mesh per tree, :func:`export` writes them as PLY / OBJ / GLB.

Conventions: Weber & Penn grow with +z up; the returned tree is in the package frame (+y up,
metres): (x, y, z)_WP -> (x, z, -y). Angles in the parameters are degrees.

Implementation: the tree is grown level by level. All stems of one level advance one segment per
step as NumPy arrays (curvature, attraction, splits into clones), pruning rescales whole stems
against the envelope, then the buds of the next level (branches, knots, leaves) are laid out for
all parents at once. There is no Python loop per branch.

Level parameters are lists indexed by level (0 = trunk); levels >= 3 use index 3. A stem of the
last level (``Levels - 1``) carries the leaves, oriented with the parameters of level ``Levels``.
"""
from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mitsuba_veg.errors import ParameterError

from . import knots as _kn
from .junction import tree_mesh
from .structure import KNOT, NORMAL, SPROUTED_KNOT, Leaves, Tree

__all__ = ["PRESETS", "WeberPennParams", "shape_ratio", "load_params", "generate", "mesh",
           "export", "preset_path", "SHAPES"]

DATA_DIR = Path(__file__).resolve().parents[1] / "data" / "weber_penn"
#: the Weber-Penn species shipped in ``data/weber_penn``
PRESETS = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak", "sassafras")
#: Weber & Penn's crown shapes, by the index of the ``Shape`` parameter
SHAPES = ("conical", "spherical", "hemispherical", "cylindrical", "tapered cylindrical", "flame",
          "inverse conical", "tend flame", "envelope")

# ---- parameters ------------------------------------------------------------------------------
# Defaults: the quaking aspen of the 1995 appendix (the paper's first example); knots off.
GLOBAL_DEFAULTS = {
    "Shape": 7, "BaseSize": 0.4, "Scale": 13.0, "ScaleV": 3.0, "ZScale": 1.0, "ZScaleV": 0.0,
    "Levels": 3, "Ratio": 0.015, "RatioPower": 1.2, "Lobes": 5, "LobeDepth": 0.07, "Flare": 0.6,
    "0Scale": 1.0, "0ScaleV": 0.0, "0BaseSplits": 0, "Leaves": 25, "LeafShape": 0,
    "LeafScale": 0.17, "LeafScaleX": 1.0, "LeafQuality": 1.0, "AttractionUp": 0.5,
    "PruneRatio": 0.0, "PruneWidth": 0.5, "PruneWidthPeak": 0.5, "PrunePowerLow": 0.5,
    "PrunePowerHigh": 0.5,
}
LEVEL_DEFAULTS = {
    "DownAngle": [0.0, 60.0, 45.0, 45.0], "DownAngleV": [0.0, -50.0, 10.0, 10.0],
    "Rotate": [0.0, 140.0, 140.0, 77.0], "RotateV": [0.0, 0.0, 0.0, 0.0],
    "Branches": [0.0, 50.0, 30.0, 10.0], "Length": [1.0, 0.3, 0.6, 0.0],
    "LengthV": [0.0, 0.0, 0.0, 0.0], "Taper": [1.0, 1.0, 1.0, 1.0],
    "SegSplits": [0.0, 0.0, 0.0, 0.0], "SplitAngle": [0.0, 0.0, 0.0, 0.0],
    "SplitAngleV": [0.0, 0.0, 0.0, 0.0], "CurveRes": [3, 5, 3, 1],
    "Curve": [0.0, -40.0, -40.0, 0.0], "CurveBack": [0.0, 0.0, 0.0, 0.0],
    "CurveV": [20.0, 50.0, 75.0, 0.0],
}
KNOT_DEFAULTS = {
    "KnotRate": 0.0, "KnotRateV": 0.0, "KnotRateDecay": 0.3, "KnotPosition": 0.3,
    "KnotPositionV": 0.0, "Contraction": 5.0, "ContractionV": 0.0, "Density": 1.5,
    "DensityV": 0.0, "DormancyBreak": 2.0, "DormancyBreakV": 0.0, "DormancyStep": 1.0,
}
KNOT_OPTIONS = {"enabled": False, "SproutVariation": "ContractionV"}
JUNCTION_DEFAULTS = {"Du": 6, "Stretch": 1.3, "Compress": 2.0, "Gain": 1.0, "KnotGain": 1.0}

_FIX = "see docs/weber_penn.md for the parameter list and ranges"
# name: (lo, hi, integer, note)
_RANGES = {
    "Shape": (0, 8, True, "0 conical .. 8 envelope"), "BaseSize": (0.0, 0.999, False, ""),
    "Scale": (1e-6, None, False, "metres"), "ScaleV": (0.0, None, False, ""),
    "ZScale": (1e-6, None, False, ""), "ZScaleV": (0.0, None, False, ""),
    "Levels": (1, 10, True, ""), "Ratio": (1e-9, None, False, ""),
    "RatioPower": (0.0, None, False, ""), "Lobes": (0, 64, True, ""),
    "LobeDepth": (0.0, 0.9, False, ""), "Flare": (-0.99, None, False, ""),
    "0Scale": (1e-9, None, False, ""), "0ScaleV": (0.0, None, False, ""),
    "0BaseSplits": (0, 32, True, ""), "Leaves": (None, None, False, "negative: fan at the tip"),
    "LeafShape": (0, 9, True, ""), "LeafScale": (1e-9, None, False, ""),
    "LeafScaleX": (1e-9, None, False, ""), "LeafQuality": (1e-9, None, False, ""),
    "AttractionUp": (None, None, False, ""), "PruneRatio": (0.0, 1.0, False, ""),
    "PruneWidth": (1e-9, None, False, ""), "PruneWidthPeak": (0.0, 0.999, False, ""),
    "PrunePowerLow": (0.0, None, False, ""), "PrunePowerHigh": (0.0, None, False, ""),
    # per level
    "DownAngle": (-180.0, 180.0, False, "degrees"), "DownAngleV": (-180.0, 180.0, False, ""),
    "Rotate": (-360.0, 360.0, False, "degrees; negative: alternating"),
    "RotateV": (0.0, 360.0, False, ""), "Branches": (0.0, 5000.0, False, ""),
    "Length": (0.0, 10.0, False, ""), "LengthV": (0.0, 10.0, False, ""),
    "Taper": (0.0, 3.0, False, "0..1 cone, 1..2 spherical end, 2..3 periodic"),
    "SegSplits": (0.0, 2.0, False, "clones per segment (more explodes exponentially)"),
    "SplitAngle": (0.0, 180.0, False, ""), "SplitAngleV": (0.0, 180.0, False, ""),
    "CurveRes": (1, 64, True, ""), "Curve": (-360.0, 360.0, False, ""),
    "CurveBack": (-360.0, 360.0, False, ""), "CurveV": (-89.9, 3600.0, False, "negative: helix"),
    # knots
    "KnotRate": (0.0, 1.0, False, "probability"), "KnotRateV": (0.0, 1.0, False, ""),
    "KnotRateDecay": (0.0, 1.0, False, "fraction of the rate lost per knot"),
    "KnotPosition": (0.0, 1.0, False, "fraction of the parent"),
    "KnotPositionV": (0.0, 1.0, False, ""), "Contraction": (1e-6, None, False, ""),
    "ContractionV": (0.0, None, False, ""), "Density": (1e-6, None, False, ""),
    "DensityV": (0.0, None, False, ""), "DormancyBreak": (0.0, None, False, "levels"),
    "DormancyBreakV": (0.0, None, False, ""), "DormancyStep": (1e-6, None, False, ""),
    # junction
    "Du": (1, 64, True, "subdivisions at level 1"), "Stretch": (1e-3, 20.0, False, ""),
    "Compress": (1e-3, 20.0, False, ""),
    "Gain": (0.0, None, False, "extra factor on the eq 4.2 scale; 1 = paper 004"),
    "KnotGain": (0.0, None, False, "the same for knots; 1 = paper 004"),
}


def _check(field_, value, source=None):
    lo, hi, integer, note = _RANGES[field_]
    allowed = f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
    if integer:
        allowed += " integer"
    if note:
        allowed += f" ({note})"
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(field_, value, allowed, _FIX, source) from None
    bad = math.isnan(v) or (lo is not None and v < lo) or (hi is not None and v > hi)
    if integer and not bad and v != int(v):
        bad = True
    if bad or isinstance(value, bool):
        raise ParameterError(field_, value, allowed, _FIX, source)
    return int(v) if integer else v


@dataclass
class WeberPennParams:
    """All parameters of one Weber-Penn tree (global, per level, knots, junction)."""

    params: dict = field(default_factory=lambda: dict(GLOBAL_DEFAULTS))
    levels: dict = field(default_factory=lambda: copy.deepcopy(LEVEL_DEFAULTS))
    knots: dict = field(default_factory=lambda: {k: [v] * 4 for k, v in KNOT_DEFAULTS.items()}
                        | dict(KNOT_OPTIONS))
    junction: dict = field(default_factory=lambda: dict(JUNCTION_DEFAULTS))
    name: str = "custom"
    source: str = ""

    def __getitem__(self, key):
        if key in self.params:
            return self.params[key]
        if key in self.junction:
            return self.junction[key]
        if key in self.knots:
            return self.knots[key]
        if key in self.levels:
            return self.levels[key]
        raise KeyError(key)

    def lv(self, key: str, level: int):
        """Per-level parameter ``nKey`` for level ``level`` (levels >= 3 reuse level 3).

        Parameters
        ----------
        key : str
            Level parameter name without its level prefix (e.g. ``"DownAngle"``).
        level : int
            Branching level (0 = trunk).

        Returns
        -------
        float or int
            The value (angles [degrees], lengths as fractions of the parent [-]).
        """
        return self.levels[key][min(int(level), 3)]

    def kn(self, key: str, level: int):
        """Per-level knot parameter ``key`` for level ``level`` (levels >= 3 reuse level 3).

        Parameters
        ----------
        key : str
            Knot parameter name (e.g. ``"KnotRate"``, ``"Contraction"``).
        level : int
            Branching level of the parent (0 = trunk).

        Returns
        -------
        float
            The value (see :mod:`mitsuba_veg.trees.knots` for meanings; mostly [-]).
        """
        return self.knots[key][min(int(level), 3)]

    def copy(self) -> "WeberPennParams":
        """A deep copy of the parameters.

        Returns
        -------
        WeberPennParams
            The copy.
        """
        return copy.deepcopy(self)

    def updated(self, values: dict | None = None, source=None, **kw) -> "WeberPennParams":
        """A validated copy with ``values`` applied (flat or sectioned keys, :func:`load_params`).

        Parameters
        ----------
        values : dict, optional
            Parameter values, sectioned (``params``, ``levels``, ``knots``, ``junction``) or flat
            with Weber-Penn names (default None: none).
        source : str, optional
            Where the values came from, named in errors (default None).
        **kw : dict
            More flat parameter values (applied after ``values``).

        Returns
        -------
        WeberPennParams
            The updated copy.

        Raises
        ------
        ParameterError
            For an unknown name or a value out of range.
        """
        out = self.copy()
        _apply(out, dict(values or {}) | kw, source)
        out.validate(source)
        return out

    def validate(self, source=None):
        """Check every parameter's range and normalise integer ones, in place.

        Also checks the knot options and that ``ContractionV < Contraction`` and
        ``DensityV < Density`` on every level (the denominators of eqs 3.1 and 3.4 stay positive).

        Parameters
        ----------
        source : str, optional
            Where the values came from, named in errors (default None).

        Returns
        -------
        WeberPennParams
            ``self``, for chaining.

        Raises
        ------
        ParameterError
            For a value out of range (see docs/weber_penn.md).
        """
        for k, v in self.params.items():
            self.params[k] = _check(k, v, source)
        for k, vals in self.levels.items():
            self.levels[k] = [_check_level(k, i, v, source) for i, v in enumerate(vals)]
        for k in KNOT_DEFAULTS:
            self.knots[k] = [_check_level(k, i, v, source, section="knots")
                             for i, v in enumerate(self.knots[k])]
        if not isinstance(self.knots["enabled"], bool):
            raise ParameterError("knots.enabled", self.knots["enabled"], "true or false",
                                 _FIX, source)
        if self.knots["SproutVariation"] not in ("ContractionV", "DensityV"):
            raise ParameterError("knots.SproutVariation", self.knots["SproutVariation"],
                                 "'ContractionV' (the text of eq 3.3) or 'DensityV' (as printed)",
                                 _FIX, source)
        for k, v in self.junction.items():
            self.junction[k] = _check(k, v, source)
        for i in range(4):   # denominators of eqs 3.1 and 3.4 must stay positive
            c, cv = self.knots["Contraction"][i], self.knots["ContractionV"][i]
            if cv >= c:
                raise ParameterError(f"knots.ContractionV[{i}]", cv,
                                     f"< Contraction = {c} (eq 3.1 divides by Contraction ± V)",
                                     "lower ContractionV", source)
            d, dv = self.knots["Density"][i], self.knots["DensityV"][i]
            if dv >= d:
                raise ParameterError(f"knots.DensityV[{i}]", dv,
                                     f"< Density = {d} (eq 3.4 divides by Density ± V)",
                                     "lower DensityV", source)
        return self

    def to_dict(self) -> dict:
        """The parameters as a sectioned dict (as in the preset files).

        Returns
        -------
        dict
            ``model`` ("weber_penn"), ``name``, ``source``, ``params``, ``levels``, ``knots``,
            ``junction`` (copies).
        """
        return {"model": "weber_penn", "name": self.name, "source": self.source,
                "params": dict(self.params), "levels": copy.deepcopy(self.levels),
                "knots": copy.deepcopy(self.knots), "junction": dict(self.junction)}


def _check_level(key, i, v, source, section="levels"):
    try:
        return _check(key, v, source)
    except ParameterError as e:
        raise ParameterError(f"{section}.{key}[{i}] ({i}{key})", v, e.allowed, _FIX, source) \
            from None


def _as_level_list(key, v, source, section):
    if isinstance(v, (list, tuple)):
        if not 1 <= len(v) <= 4:
            raise ParameterError(f"{section}.{key}", list(v),
                                 "1 to 4 values (levels 0..3; levels >= 3 reuse the last)",
                                 _FIX, source)
        vals = list(v)
        return vals + [vals[-1]] * (4 - len(vals))
    return [v] * 4


def _apply(p: WeberPennParams, d: dict, source=None):
    """Apply sectioned (``params``/``levels``/``knots``/``junction``) or flat keys to ``p``."""
    for sec in ("params", "levels", "knots", "junction"):
        sub = d.pop(sec, None)
        if sub is None:
            continue
        if not isinstance(sub, dict):
            raise ParameterError(sec, sub, "a table of parameters", _FIX, source)
        for k, v in sub.items():
            _apply_one(p, k, v, source, hint=sec)
    for k in ("model", "name", "source", "preset", "seed"):
        v = d.pop(k, None)
        if k == "model" and v not in (None, "weber_penn"):
            raise ParameterError("model", v, "'weber_penn'", "use the matching model", source)
        if k == "name" and v is not None:
            p.name = str(v)
        if k == "source" and v is not None:
            p.source = str(v)
    for k, v in d.items():
        _apply_one(p, k, v, source)


def _apply_one(p, k, v, source, hint=None):
    if k in GLOBAL_DEFAULTS:
        p.params[k] = v
    elif k in LEVEL_DEFAULTS:
        p.levels[k] = _as_level_list(k, v, source, "levels")
    elif k in KNOT_DEFAULTS:
        p.knots[k] = _as_level_list(k, v, source, "knots")
    elif k in KNOT_OPTIONS:
        p.knots[k] = v
    elif k in JUNCTION_DEFAULTS:
        p.junction[k] = v
    elif len(k) > 1 and k[0].isdigit() and k[1:] in LEVEL_DEFAULTS:   # WP style "1DownAngle"
        i = int(k[0])
        if i > 3:
            raise ParameterError(k, v, "a level prefix 0..3 (levels >= 3 reuse level 3)",
                                 _FIX, source)
        p.levels[k[1:]][i] = v
    else:
        known = (sorted(GLOBAL_DEFAULTS) + sorted(LEVEL_DEFAULTS) + sorted(KNOT_DEFAULTS)
                 + sorted(KNOT_OPTIONS) + sorted(JUNCTION_DEFAULTS))
        where = f"{hint}.{k}" if hint else k
        raise ParameterError(where, v, "a Weber-Penn / knot / junction parameter: "
                             + ", ".join(known), "check the spelling; " + _FIX, source)


def preset_path(name: str) -> Path:
    """Path of the TOML file of a shipped preset.

    Parameters
    ----------
    name : str
        A preset name from :data:`PRESETS`.

    Returns
    -------
    pathlib.Path
        The preset file (under ``mitsuba_veg/data/weber_penn``).

    Raises
    ------
    ParameterError
        For an unknown name or a missing preset file.
    """
    if name not in PRESETS:
        raise ParameterError("preset", name, "one of " + ", ".join(PRESETS),
                             "use a shipped preset name or pass a parameter dict / TOML path")
    path = DATA_DIR / f"{name}.toml"
    if not path.is_file():
        raise ParameterError("preset", name, f"a preset file at {path}",
                             "this installation lacks mitsuba_veg/data/weber_penn/*.toml; "
                             "reinstall the package (they are package data)")
    return path


def load_params(preset_or_params="quaking_aspen") -> WeberPennParams:
    """Parameters from a preset name, a TOML path, a dict or a :class:`WeberPennParams`.

    Dicts may be sectioned like the preset files (``params``, ``levels``, ``knots``,
    ``junction``; optional ``preset`` to start from and ``model = "weber_penn"``) or flat with
    Weber-Penn names (``"Shape": 2``, ``"1Length": 0.4``, ``"Length": [1, 0.3, 0.6, 0]``,
    ``"KnotRate": 0.2``, ``"Du": 4``). Unknown names raise :class:`ParameterError`.

    Parameters
    ----------
    preset_or_params : str, pathlib.Path, dict or WeberPennParams, optional
        The parameters (default ``"quaking_aspen"``); a WeberPennParams is copied.

    Returns
    -------
    WeberPennParams
        The validated parameters.

    Raises
    ------
    ParameterError
        For an unknown preset, a missing or invalid TOML file, an unknown name or a value out
        of range.
    """
    obj = preset_or_params
    if isinstance(obj, WeberPennParams):
        return obj.copy().validate()
    if isinstance(obj, (str, Path)):
        s = str(obj)
        if s in PRESETS:
            path = preset_path(s)
        elif s.endswith(".toml") or isinstance(obj, Path):
            path = Path(s)
            if not path.is_file():
                raise ParameterError("preset_or_params", s, "an existing .toml file or one of "
                                     + ", ".join(PRESETS), "check the path")
        else:
            raise ParameterError("preset", s, "one of " + ", ".join(PRESETS)
                                 + " or a path to a .toml file",
                                 "use a shipped preset name or a parameter file")
        try:
            # utf-8-sig: a byte-order mark (some editors write one) is not part of the TOML
            d = tomllib.loads(Path(path).read_text(encoding="utf-8-sig"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise ParameterError("file", str(path), "valid TOML (UTF-8 text)", str(e)) from None
        base = WeberPennParams(name=path.stem)
        if d.get("preset") and d.get("preset") != path.stem:
            base = load_params(d["preset"])
        _apply(base, d, str(path))
        return base.validate(str(path))
    if isinstance(obj, dict):
        d = copy.deepcopy(obj)
        base = load_params(d["preset"]) if d.get("preset") else WeberPennParams()
        _apply(base, d)
        return base.validate()
    raise ParameterError("preset_or_params", type(obj).__name__,
                         "a preset name, a .toml path, a dict or WeberPennParams")


# ---- ShapeRatio ------------------------------------------------------------------------------
def shape_ratio(shape, ratio, *, prune_width_peak=0.5, prune_power_low=0.5, prune_power_high=0.5):
    """Weber & Penn's ShapeRatio(shape, ratio), exactly as defined in the 1995 paper.

    ======  ===================  ==============================================================
    shape   name                 value
    ======  ===================  ==============================================================
    0       conical              0.2 + 0.8 ratio
    1       spherical            0.2 + 0.8 sin(pi ratio)
    2       hemispherical        0.2 + 0.8 sin(pi/2 ratio)
    3       cylindrical          1
    4       tapered cylindrical  0.5 + 0.5 ratio
    5       flame                ratio/0.7 (ratio <= 0.7), (1 - ratio)/0.3 otherwise
    6       inverse conical      1 - 0.8 ratio
    7       tend flame           0.5 + 0.5 ratio/0.7 (ratio <= 0.7), 0.5 + 0.5 (1 - ratio)/0.3
    8       envelope             0 outside [0, 1]; (ratio/(1 - PruneWidthPeak))^PrunePowerHigh
                                 for ratio < 1 - PruneWidthPeak, else
                                 ((1 - ratio)/(1 - PruneWidthPeak))^PrunePowerLow
    ======  ===================  ==============================================================

    ``ratio`` may be an array. The envelope branch is kept as printed: for PruneWidthPeak != 0.5
    it jumps at ratio = 1 - PruneWidthPeak (docs/deviations.md).

    Parameters
    ----------
    shape : int
        Shape number 0..8 (table above).
    ratio : float or array_like
        Position ratio [-] (0..1 along the stem or height).
    prune_width_peak : float, optional
        ``PruneWidthPeak`` [-], in [0, 0.999] (envelope only; default 0.5).
    prune_power_low : float, optional
        ``PrunePowerLow`` [-] (envelope only; default 0.5).
    prune_power_high : float, optional
        ``PrunePowerHigh`` [-] (envelope only; default 0.5).

    Returns
    -------
    float or numpy.ndarray
        ShapeRatio [-]: a float for a scalar ``ratio``, else an array of its shape.

    Raises
    ------
    ParameterError
        If ``shape`` is not an integer 0..8 (or ``prune_width_peak`` out of range).
    """
    try:
        s = int(shape)
    except (TypeError, ValueError):
        raise ParameterError("shape", shape, "an integer 0..8", _FIX) from None
    if s != shape or not 0 <= s <= 8:
        raise ParameterError("shape", shape, "an integer 0..8 (" + ", ".join(
            f"{i} {n}" for i, n in enumerate(SHAPES)) + ")", _FIX)
    r = np.asarray(ratio, dtype=float)
    if s == 0:
        out = 0.2 + 0.8 * r
    elif s == 1:
        out = 0.2 + 0.8 * np.sin(np.pi * r)
    elif s == 2:
        out = 0.2 + 0.8 * np.sin(0.5 * np.pi * r)
    elif s == 3:
        out = np.ones_like(r)
    elif s == 4:
        out = 0.5 + 0.5 * r
    elif s == 5:
        out = np.where(r <= 0.7, r / 0.7, (1.0 - r) / 0.3)
    elif s == 6:
        out = 1.0 - 0.8 * r
    elif s == 7:
        out = np.where(r <= 0.7, 0.5 + 0.5 * r / 0.7, 0.5 + 0.5 * (1.0 - r) / 0.3)
    else:
        _check("PruneWidthPeak", prune_width_peak)
        peak = 1.0 - prune_width_peak
        inside = (r >= 0.0) & (r <= 1.0)
        rc = np.clip(r, 0.0, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(rc < peak, (rc / peak) ** prune_power_high,
                           ((1.0 - rc) / peak) ** prune_power_low)
        out = np.where(inside, out, 0.0)
    return float(out) if np.ndim(out) == 0 else out


def _sr(p: WeberPennParams, shape, ratio):
    return shape_ratio(shape, ratio, prune_width_peak=p.params["PruneWidthPeak"],
                       prune_power_low=p.params["PrunePowerLow"],
                       prune_power_high=p.params["PrunePowerHigh"])


# ---- geometry helpers ------------------------------------------------------------------------
def _rot(v, axis, ang):
    """Rotate rows of ``v`` about unit rows of ``axis`` by ``ang`` [rad] (Rodrigues)."""
    c = np.cos(ang)[:, None]
    s = np.sin(ang)[:, None]
    d = np.sum(axis * v, axis=1, keepdims=True)
    return v * c + np.cross(axis, v) * s + axis * d * (1.0 - c)


def _rotx(Y, Z, ang):
    """Rotate a frame about its own x axis by ``ang`` [rad]: z turns towards y."""
    c = np.cos(ang)[:, None]
    s = np.sin(ang)[:, None]
    return Y * c - Z * s, Z * c + Y * s


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def taper_radius(r0, length, taper, z):
    """Weber & Penn's stem radius at fraction ``z`` (0 base .. 1 tip) for ``nTaper``.

    0 <= taper < 1: linear to ``r0 (1 - taper)``; 1 <= taper < 2: cone (unit taper
    ``2 - taper``) with a spherical end; 2 <= taper <= 3: periodic spheres of depth
    ``taper - 2``.

    Parameters
    ----------
    r0 : float or array_like
        Radius at the stem base [m].
    length : float or array_like
        Stem length [m].
    taper : float or array_like
        ``nTaper`` [-], in [0, 3].
    z : float or array_like
        Position along the stem, fraction 0 (base) .. 1 (tip) [-] (clipped to [0, 1]).

    Returns
    -------
    numpy.ndarray
        Radius [m] (broadcast shape of the inputs).
    """
    r0, length, taper, z = np.broadcast_arrays(*(np.asarray(a, float) for a in (r0, length,
                                                                               taper, z)))
    z = np.clip(z, 0.0, 1.0)
    unit = np.where(taper < 1, taper, np.where(taper < 2, 2.0 - taper, 0.0))
    tz = r0 * (1.0 - unit * z)
    out = tz.copy()
    m = taper >= 1
    if np.any(m):
        z2 = (1.0 - z[m]) * length[m]
        t = tz[m]
        tp = taper[m]
        depth = np.where((tp < 2) | (z2 < t), 1.0, tp - 2.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            z3 = np.where(tp < 2, z2,
                          np.abs(z2 - 2 * t * np.floor(z2 / np.maximum(2 * t, 1e-300) + 0.5)))
        sph = (1 - depth) * t + depth * np.sqrt(np.maximum(t * t - (z3 - t) ** 2, 0.0))
        out[m] = np.where((tp < 2) & (z3 >= t), t, sph)
    return out


def flare_factor(flare, z):
    """Trunk flare: ``1 + Flare (100^y - 1)/100`` with ``y = max(0, 1 - 8 z)``.

    Parameters
    ----------
    flare : float
        ``Flare`` [-] (> -1).
    z : float or array_like
        Position along the trunk, fraction 0 (base) .. 1 (tip) [-].

    Returns
    -------
    numpy.ndarray
        Factor on the trunk radius [-] (1 above z = 1/8).
    """
    y = np.maximum(0.0, 1.0 - 8.0 * np.asarray(z, float))
    return 1.0 + flare * (100.0 ** y - 1.0) / 100.0


def _sink(pos, d, axis, r_parent, r_knot):
    """Start point of a knot: on the parent's bark, from the parent's axis along the knot
    direction ``d`` (Weber-Penn stems start on the axis; a knot, much shorter than its parent is
    thick, would end inside it). Its whole length (eq 3.1) protrudes; the mesher closes its
    base under the bark."""
    sin = np.sqrt(np.maximum(1.0 - np.sum(d * axis, 1) ** 2, 0.0))
    s_exit = r_parent / np.maximum(sin, 0.25)
    return pos + s_exit[:, None] * d


def _errdiff(x, start=0.0):
    """Integer counts by error diffusion (running rounding) of the non-negative floats ``x``."""
    c = np.floor(np.cumsum(x) + start + 0.5)
    return np.diff(np.r_[math.floor(start + 0.5), c]).astype(np.int64)


# ---- the generator ---------------------------------------------------------------------------
@dataclass
class WeberPennInfo:
    """Generation record kept on the tree as ``tree.weber_penn``."""

    params: WeberPennParams
    seed: int | None
    knots: bool
    scale_tree: float
    stats: dict


class _Grower:
    KR = 6   # uniforms per stem segment

    def __init__(self, p: WeberPennParams, seed, knots_on: bool):
        self.p = p
        self.seed = seed
        self.ss_entropy = int(np.random.SeedSequence(seed).entropy) if seed is None else seed
        self.rng = self.stream(-1, 0)
        self.knots_on = bool(knots_on)
        g = p.params
        u = self.rng.random(8)
        self.scale_tree = max(g["Scale"] + g["ScaleV"] * (2 * u[0] - 1), 0.1 * g["Scale"])
        self.zscale = max(g["ZScale"] + g["ZScaleV"] * (2 * u[1] - 1), 1e-3)
        self.min_len = 1e-4 * self.scale_tree
        self.out = {k: [] for k in ("start", "end", "r0", "r1", "parent", "level", "kind", "stem",
                                    "attach", "fx", "arc", "slen", "srad", "dorm", "sprout",
                                    "clone")}
        self.n_out = 0
        self.n_stems = 0
        self.stats = {"levels": {}}
        self.leaves = None
        # trunk family
        L0 = (p.lv("Length", 0) + p.lv("LengthV", 0) * (2 * u[2] - 1)) * self.scale_tree
        r0 = L0 * g["Ratio"] * (g["0Scale"] + g["0ScaleV"] * (2 * u[3] - 1))
        phi = 2 * np.pi * u[4]
        self.trunk = self._fam(
            L=[L0], r_raw=[r0], r_cap=[np.inf], kind=[NORMAL], sprout=[False], dorm=[np.nan],
            parent_seg=[-1], parent_stem=[-1], attach=[0.0], offset=[0.0], L_par=[L0],
            lcm_par=[1.0], lcm=[p.lv("Length", 1) + p.lv("LengthV", 1) * (2 * u[5] - 1)],
            taper=[p.lv("Taper", 0)], pos=[[0.0, 0.0, 0.0]],
            X=[[math.cos(phi), math.sin(phi), 0.0]], Y=[[-math.sin(phi), math.cos(phi), 0.0]],
            Z=[[0.0, 0.0, 1.0]])

    def stream(self, lv: int, purpose: int):
        """Random stream keyed by (seed, level, purpose): 0 growth, 1 bud layout, 2 knots,
        3 knot buds, 4 leaves. Switching knots on leaves the streams of growth untouched."""
        return np.random.default_rng([self.ss_entropy, lv + 1, purpose])

    @staticmethod
    def _fam(**kw):
        f = {k: np.asarray(v, dtype=float if k not in ("kind", "parent_seg", "parent_stem")
                           else np.int64) for k, v in kw.items()}
        f["sprout"] = f["sprout"].astype(bool)
        f["r0"] = np.minimum(f["r_raw"], f["r_cap"])
        return f

    # -- one level: segments of all stems --------------------------------------------------
    def grow_level(self, lv: int, fam: dict):
        p, g = self.p, self.p.params
        N = int(p.lv("CurveRes", lv))
        nf = len(fam["L"])
        U = self.stream(lv, 0).random((nf, N, self.KR))
        rows = {"fam": np.arange(nf), "k0": np.zeros(nf, np.int64), "prow": np.full(nf, -1),
                "pos": fam["pos"].copy(), "X": fam["X"].copy(), "Y": fam["Y"].copy(),
                "Z": fam["Z"].copy(), "corr": np.zeros(nf), "dens": np.ones((nf, N)), "U": U}
        curve, back, cv = p.lv("Curve", lv), p.lv("CurveBack", lv), p.lv("CurveV", lv)
        segsplits, sangle, sanglev = (p.lv("SegSplits", lv), p.lv("SplitAngle", lv),
                                      p.lv("SplitAngleV", lv))
        attr_up = g["AttractionUp"]
        base_splits = int(g["0BaseSplits"]) if lv == 0 else 0
        k_base = max(0, math.ceil(g["BaseSize"] * N) - 1)
        gens = {}
        recs = []
        seglen_f = fam["L"] / N
        for k in range(N):
            act = np.nonzero(rows["k0"] <= k)[0]
            fa = rows["fam"][act]
            Ua = rows["U"][act, k]
            X, Y, Z = rows["X"][act], rows["Y"][act], rows["Z"][act]
            if k > 0:
                if back == 0:
                    delta = np.full(len(act), curve / N)
                else:
                    delta = np.full(len(act), (2 * curve if k < (N + 1) // 2 else 2 * back) / N)
                if cv > 0:
                    delta = delta + cv / N * (2 * Ua[:, 0] - 1)
                delta = delta + rows["corr"][act]
                Y, Z = _rotx(Y, Z, np.radians(delta))
                if attr_up != 0 and lv >= 2:
                    decl = np.arccos(np.clip(Z[:, 2], -1, 1))
                    orient = np.arccos(np.clip(Y[:, 2], -1, 1))
                    Y, Z = _rotx(Y, Z, attr_up * decl * np.cos(orient) / N)
            start = rows["pos"][act]
            end = start + Z * seglen_f[fa][:, None]
            recs.append((act, k, start, end, X, Y, Z))
            rows["pos"][act] = end
            rows["X"][act], rows["Y"][act], rows["Z"][act] = X, Y, Z
            if k >= N - 1:
                continue
            # splitting into clones
            nsp = np.floor(segsplits + Ua[:, 1]).astype(np.int64)
            nsp[fam["kind"][fa] == KNOT] = 0          # knots do not split
            if base_splits and k == k_base:
                orig = rows["prow"][act] < 0
                nsp[orig] = base_splits
            sp = np.nonzero(nsp > 0)[0]
            if not len(sp):
                continue
            r = act[sp]
            decl = np.degrees(np.arccos(np.clip(Z[sp, 2], -1, 1)))
            sa = np.maximum(0.0, sangle + sanglev * (2 * Ua[sp, 2] - 1) - decl)
            Ys, Zs = _rotx(Y[sp], Z[sp], np.radians(sa))
            rows["Y"][r], rows["Z"][r] = Ys, Zs
            rows["corr"][r] -= sa / (N - k - 1)
            rows["dens"][r, k + 1:] /= (nsp[sp] + 1)[:, None]
            c_row, c_j, c_div, c_U = [], [], [], []
            for j, row in enumerate(r):
                f = int(rows["fam"][row])
                gen = gens.get(f)
                if gen is None:
                    gen = gens[f] = np.random.default_rng([self.ss_entropy, 7919, lv, f])
                n = int(nsp[sp[j]])
                base_split = base_splits and k == k_base and rows["prow"][row] < 0
                for i in range(1, n + 1):
                    h = gen.random(3)
                    if base_split:
                        div = 360.0 * i / (n + 1) + sanglev * (2 * h[0] - 1)
                    else:
                        div = (20 + 0.75 * (30 + abs(decl[j] - 90)) * h[0] ** 2) * (
                            1 if h[1] < 0.5 else -1)
                    c_row.append(row)
                    c_j.append(j)
                    c_div.append(div)
                    c_U.append(gen.random((N, self.KR)))
            c_row, c_j = np.asarray(c_row), np.asarray(c_j)
            a = np.radians(np.asarray(c_div))
            up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (len(c_row), 3))
            new = {"fam": rows["fam"][c_row], "k0": np.full(len(c_row), k + 1),
                   "prow": c_row, "pos": rows["pos"][c_row],
                   "X": _rot(rows["X"][c_row], up, a), "Y": _rot(Ys[c_j], up, a),
                   "Z": _rot(Zs[c_j], up, a), "corr": rows["corr"][c_row],
                   "dens": rows["dens"][c_row], "U": np.stack(c_U)}
            for key, v in new.items():
                rows[key] = np.concatenate([rows[key], np.asarray(v).astype(rows[key].dtype)])
        # segment table sorted by (row, k): parents before children
        seg = {"row": np.concatenate([a for a, *_ in recs]),
               "k": np.concatenate([np.full(len(a), kk) for a, kk, *_ in recs])}
        for i, key in enumerate(("start", "end", "X", "Y", "Z")):
            seg[key] = np.concatenate([rc[2 + i] for rc in recs])
        order = np.lexsort((seg["k"], seg["row"]))
        seg = {key: v[order] for key, v in seg.items()}
        return rows, seg, N

    # -- pruning against the envelope -------------------------------------------------------
    def inside_envelope(self, pts):
        g = self.p.params
        S = self.scale_tree
        r = np.hypot(pts[:, 0], pts[:, 1])
        ratio = (S - pts[:, 2]) / (S * (1.0 - g["BaseSize"]))
        return r / S < g["PruneWidth"] * _sr(self.p, 8, ratio)

    def prune(self, lv, fam, rows, seg, N):
        g = self.p.params
        if lv == 0 or g["PruneRatio"] <= 0:
            return
        nf = len(fam["L"])
        sfam = rows["fam"][seg["row"]]
        base = fam["pos"][sfam]
        rel = seg["end"] - base
        L0 = fam["L"].copy()
        L = L0.copy()
        active = fam["kind"] != KNOT
        for _ in range(64):
            lam = (L / L0)[sfam]
            out = ~self.inside_envelope(base + lam[:, None] * rel) & active[sfam]
            if not out.any():
                break
            first = np.full(nf, N + 1)
            np.minimum.at(first, sfam[out], seg["k"][out])
            bad = (first <= N) & active & (L > 0.001 * self.scale_tree)
            if not bad.any():
                break
            seglen = L / N
            Lnew = np.minimum(np.maximum(seglen * first, L / 2), L - L0 / 15)
            L = np.where(bad, Lnew, L)
        Lf = L0 - (L0 - L) * g["PruneRatio"]
        lam = Lf / L0
        if np.all(lam == 1.0):
            return
        ls = lam[sfam][:, None]
        seg["start"] = base + ls * (seg["start"] - base)
        seg["end"] = base + ls * (seg["end"] - base)
        fam["L"] = Lf
        fam["r_raw"] = fam["r_raw"] * lam ** g["RatioPower"]
        fam["r0"] = np.minimum(fam["r_raw"], fam["r_cap"])

    # -- radii and output segments -----------------------------------------------------------
    def radius(self, lv, fam, f, s):
        """Radius of family rows ``f`` at arc length ``s`` from their base."""
        L = fam["L"][f]
        z = np.clip(s / np.maximum(L, 1e-300), 0, 1)
        r = taper_radius(fam["r0"][f], L, fam["taper"][f], z)
        if lv == 0 and self.p.params["Flare"] != 0:
            r = r * flare_factor(self.p.params["Flare"], z)
        return r

    def emit(self, lv, fam, rows, seg, N):
        """Append the level's segments (subdivided where needed) to the output arrays."""
        p, g = self.p, self.p.params
        nseg = len(seg["row"])
        f = rows["fam"][seg["row"]]
        k = seg["k"]
        taper = fam["taper"][f]
        m = np.ones(nseg, np.int64)
        if lv == 0 and g["Flare"] != 0:
            m = np.where(k < N / 8.0, 6, m)
        m = np.where((taper > 1) & (taper <= 2) & (k == N - 1), 4, m)
        m = np.where(taper > 2, 8, m)
        helix = p.lv("CurveV", lv) < 0
        if helix:
            m[:] = 8
        tot = int(m.sum())
        first = self.n_out + np.r_[0, np.cumsum(m)[:-1]]
        si = np.repeat(np.arange(nseg), m)                  # WP segment of each sub-segment
        j = np.arange(tot) - np.repeat(first - self.n_out, m)
        mm = m[si]
        L = fam["L"][f]
        sl = (L / N)[si]
        s0 = (k[si] + j / mm) * sl
        s1 = (k[si] + (j + 1) / mm) * sl
        a0 = seg["start"][si]
        d = seg["end"][si] - a0
        start = a0 + d * (j / mm)[:, None]
        end = a0 + d * ((j + 1) / mm)[:, None]
        if helix:   # one helix turn per segment around the segment's axis
            ang = abs(p.lv("CurveV", lv)) * np.pi / 180
            rad = math.sqrt(1.0 / math.cos(ang) ** 2 - 1.0) * sl / (2 * np.pi)
            X, Y = seg["X"][si], seg["Y"][si]

            def hx(t):
                return ((rad * (np.cos(2 * np.pi * t) - 1))[:, None] * X
                        + (rad * np.sin(2 * np.pi * t))[:, None] * Y)
            start = start + hx(j / mm)
            end = end + hx((j + 1) / mm)
        ff = f[si]
        r0 = self.radius(lv, fam, ff, s0)
        r1 = self.radius(lv, fam, ff, s1)
        # parents
        parent = np.arange(self.n_out - 1, self.n_out - 1 + tot)   # previous sub-segment
        attach = np.ones(tot)
        clone = np.zeros(tot, bool)
        last = first + m - 1
        idx = -np.ones((len(rows["fam"]), N), np.int64)
        idx[seg["row"], k] = np.arange(nseg)
        seg["first"], seg["m"], seg["idx"] = first, m, idx
        heads = first                                        # first sub-seg of each WP segment
        row = seg["row"]
        is_k0 = k == rows["k0"][row]
        prow = rows["prow"][row]
        # continuation inside a row
        cont = ~is_k0
        parent[heads[cont] - self.n_out] = last[idx[row[cont], k[cont] - 1]]
        # first segment of an original stem: its bud on the parent
        orig = is_k0 & (prow < 0)
        parent[heads[orig] - self.n_out] = fam["parent_seg"][f[orig]]
        attach[heads[orig] - self.n_out] = fam["attach"][f[orig]]
        # first segment of a clone: the end of the parent row's segment k - 1
        cl = is_k0 & (prow >= 0)
        parent[heads[cl] - self.n_out] = last[idx[prow[cl], k[cl] - 1]]
        clone[heads[cl] - self.n_out] = True
        stem_of_row = self.n_stems + np.arange(len(rows["fam"]))
        self.n_stems += len(rows["fam"])
        rows["stem"] = stem_of_row
        o = self.out
        o["start"].append(start)
        o["end"].append(end)
        o["r0"].append(r0)
        o["r1"].append(r1)
        o["parent"].append(parent)
        o["level"].append(np.full(tot, lv))
        o["kind"].append(fam["kind"][ff])
        o["stem"].append(stem_of_row[row[si]])
        o["attach"].append(attach)
        o["fx"].append(seg["X"][si])
        o["arc"].append(s0)
        o["slen"].append(L[si])
        o["srad"].append(fam["r0"][ff])
        o["dorm"].append(fam["dorm"][ff])
        o["sprout"].append(fam["sprout"][ff])
        o["clone"].append(clone)
        seg["sub_start"], seg["sub_end"] = start, end
        seg["sub_base"] = self.n_out
        self.n_out += tot

    # -- buds of the next level ----------------------------------------------------------
    def _point(self, seg, si, frac):
        """Global sub-segment id, its parameter t and the position of WP segment ``si`` at
        ``frac``."""
        m = seg["m"][si]
        j = np.minimum((frac * m).astype(np.int64), m - 1)
        t = np.clip(frac * m - j, 0.0, 1.0)
        gid = seg["first"][si] + j
        loc = gid - seg["sub_base"]
        pos = seg["sub_start"][loc] + t[:, None] * (seg["sub_end"][loc] - seg["sub_start"][loc])
        return gid, t, pos

    def _down_angle(self, lvc, u, L_par, s, base_frac):
        p = self.p
        da, dav = p.lv("DownAngle", lvc), p.lv("DownAngleV", lvc)
        if dav >= 0:
            return da + dav * (2 * u - 1)
        ratio = np.clip((L_par - s) / np.maximum(L_par * (1 - base_frac), 1e-300), 0, 1)
        return da + dav * (1 - 2 * shape_ratio(0, ratio))

    @staticmethod
    def _child_frame(X, Y, Z, rot_deg, down_deg):
        a = np.radians(rot_deg)[:, None]
        Xr = X * np.cos(a) + Y * np.sin(a)
        Yr = Y * np.cos(a) - X * np.sin(a)
        Yc, Zc = _rotx(Yr, Z, np.radians(down_deg))
        return Xr, Yc, Zc

    def buds(self, lv, fam, rows, seg, N):
        """Next-level families (branches, knots, sprouts) and, on the last level, leaves."""
        p, g = self.p, self.p.params
        levels = int(g["Levels"])
        nr = len(rows["fam"])
        f = rows["fam"]
        L = fam["L"][f]
        seglen = L / N
        st = {"parents": int(nr)}
        self.stats["levels"][lv] = st
        fams = []
        if lv == levels - 1:
            if lv >= 1:
                self.make_leaves(lv, fam, rows, seg, N)
            return None
        lvc = lv + 1
        # -- branch buds: Weber-Penn count per row and per segment ----------------------------
        a = g["BaseSize"] if lv == 0 else 0.0
        kk = np.arange(N)
        owned = kk[None, :] >= rows["k0"][:, None]
        bearing = np.clip((kk + 1) - a * N, 0.0, 1.0)[None, :] * np.ones((nr, 1))
        stems_max = p.lv("Branches", lvc)
        normal = fam["kind"][f] != KNOT
        if lv == 0:
            base = np.full(nr, stems_max / (N * (1.0 - a)))
        elif lv == 1:
            lcm_par = np.where(fam["lcm_par"][f] > 0, fam["lcm_par"][f], 1.0)
            base = stems_max * (0.2 + 0.8 * (L / fam["L_par"][f]) / lcm_par) / N
        else:
            base = stems_max * (1.0 - 0.5 * fam["offset"][f] / fam["L_par"][f]) / N
        base = np.where(normal, np.maximum(base, 0.0), 0.0)
        dens = base[:, None] * rows["dens"] * owned * bearing
        n_row = dens.sum(1)
        kn_on = self.knots_on
        rng_b = self.stream(lv, 1)
        u = self.stream(lv, 2).random((nr, 4))
        if kn_on:
            kp = np.clip(p.kn("KnotPosition", lvc) + p.kn("KnotPositionV", lvc) * (2 * u[:, 0] - 1),
                         0.0, 1.0)
            rate = np.clip(p.kn("KnotRate", lvc) + p.kn("KnotRateV", lvc) * (2 * u[:, 1] - 1),
                           0.0, 1.0)
            decay = p.kn("KnotRateDecay", lvc)
            zstart = np.maximum(kp, a)
            zone = np.clip((kk + 1)[None, :] - zstart[:, None] * N, 0.0, 1.0)
            dens_zone = base[:, None] * rows["dens"] * owned * zone
            n_zone = dens_zone.sum(1)
            E = _kn.expected_knots(n_zone, rate, decay) if nr else np.zeros(0)
            E = np.where(normal, E, 0.0)
            dorm = p.kn("DormancyBreak", lvc) + p.kn("DormancyBreakV", lvc) * (2 * u[:, 2] - 1)
        else:
            kp = np.ones(nr)
            rate = np.zeros(nr)
            decay = 0.0
            dens_zone = np.zeros_like(dens)
            n_zone = np.zeros(nr)
            E = np.zeros(nr)
            dorm = np.full(nr, np.nan)
        count = _errdiff(n_row + E)
        st.update(expected=float(n_row.sum()), expected_knots=float(E.sum()),
                  buds=int(count.sum()), expected_per_row=n_row + E, weber_penn_per_row=n_row,
                  buds_per_row=count.copy())
        # positions: quantiles of the (knot-augmented) density, ordered base -> tip
        aug = dens + dens_zone * np.where(n_zone > 0, E / np.maximum(n_zone, 1e-300), 0.0)[:, None]
        cum = np.concatenate([np.zeros((nr, 1)), np.cumsum(aug, 1)], 1)
        tot = cum[:, -1]
        brow = np.repeat(np.arange(nr), count)
        jj = np.arange(len(brow)) - np.repeat(np.r_[0, np.cumsum(count)[:-1]], count)
        q = (jj + 0.5) / np.maximum(count[brow], 1) * tot[brow]
        big = (tot.max() if nr else 0.0) * 2 + 1.0
        keyed = (cum + big * np.arange(nr)[:, None]).ravel()
        pos_flat = np.searchsorted(keyed, q + big * brow, side="right") - 1
        bk = np.clip(pos_flat - brow * (N + 1), 0, N - 1)
        lo = np.clip(a * N - bk, 0.0, 1.0)
        seg_d = np.maximum(aug[brow, bk], 1e-300)
        within = np.clip((q - cum[brow, bk]) / seg_d, 0.0, 1.0)
        bfrac = lo + within * (1.0 - lo)
        bs = (bk + bfrac) * seglen[brow]
        forced = np.zeros(len(brow), bool)
        # BaseSize interaction: buds between the knot position and BaseSize are all knots
        if kn_on and lv == 0:
            n_ext = np.where((rows["k0"] == 0) & (kp < a) & normal,
                             stems_max / (1.0 - a) * (a - kp), 0.0)
            c_ext = _errdiff(n_ext)
            erow = np.repeat(np.arange(nr), c_ext)
            ej = np.arange(len(erow)) - np.repeat(np.r_[0, np.cumsum(c_ext)[:-1]], c_ext)
            es = (kp[erow] + (ej + 0.5) / np.maximum(c_ext[erow], 1) * (a - kp[erow])) * L[erow]
            ek = np.clip((es / seglen[erow]).astype(np.int64), 0, N - 1)
            brow = np.r_[erow, brow]
            bk = np.r_[ek, bk]
            bs = np.r_[es, bs]
            bfrac = np.r_[np.clip(es / seglen[erow] - ek, 0, 1), bfrac]
            forced = np.r_[np.ones(len(erow), bool), forced]
            st["forced_knots"] = int(len(erow))
        order = np.lexsort((bs, brow))
        brow, bk, bs, bfrac, forced = brow[order], bk[order], bs[order], bfrac[order], forced[order]
        in_zone = bs >= (kp * L)[brow] - 1e-12
        ub = rng_b.random((len(brow), 8))
        if kn_on:
            is_knot, _ = _kn.assign_knots(brow, in_zone, forced, rate, decay, ub[:, 0])
        else:
            is_knot = np.zeros(len(brow), bool)
        st["knots"] = int(is_knot.sum())
        st["branches"] = int((~is_knot).sum())
        st["per_row"] = np.bincount(brow, minlength=nr)
        st["knots_per_row"] = np.bincount(brow[is_knot], minlength=nr)
        if len(brow):
            fams.append(self._bud_families(lv, fam, rows, seg, N, brow, bk, bfrac, bs, is_knot,
                                           ub, dorm))
        # -- the dormant bud of each knot ------------------------------------------------------
        krows = np.nonzero(fam["kind"][f] == KNOT)[0]
        krows = krows[rows["prow"][krows] < 0]
        if len(krows) and kn_on:
            fams.append(self._knot_buds(lv, fam, rows, seg, N, krows))
        fams = [x for x in fams if x is not None and len(x["L"])]
        if not fams:
            return None
        out = {k: np.concatenate([x[k] for x in fams]) for k in fams[0]}
        keep = (out["L"] > self.min_len) & (out["r0"] > 0)
        st["dropped_short"] = int((~keep).sum())
        return {k: v[keep] for k, v in out.items()}

    def _bud_families(self, lv, fam, rows, seg, N, brow, bk, bfrac, bs, is_knot, ub, dorm):
        p, g = self.p, self.p.params
        lvc = lv + 1
        f = rows["fam"][brow]
        L_par = fam["L"][f]
        si = seg["idx"][brow, bk]
        gid, t, pos = self._point(seg, si, bfrac)
        # rotation: cumulative per parent row (or alternating for negative nRotate)
        rot_p, rotv = p.lv("Rotate", lvc), p.lv("RotateV", lvc)
        step = rot_p + rotv * (2 * ub[:, 1] - 1)
        first = np.r_[True, brow[1:] != brow[:-1]]
        rank = np.arange(len(brow)) - np.maximum.accumulate(np.where(first, np.arange(len(brow)),
                                                                     0))
        if rot_p >= 0:
            cs = np.cumsum(step)
            startv = np.maximum.accumulate(np.where(first, np.arange(len(brow)), 0))
            rot = cs - cs[startv] + step[startv]
            rot = np.mod(rot, 360.0)
        else:
            sign = np.where(rank % 2 == 0, 1.0, -1.0)
            rot = sign * (180.0 + rot_p + rotv * (2 * ub[:, 1] - 1))
        a = g["BaseSize"] if lv == 0 else 0.0
        down = self._down_angle(lvc, ub[:, 2], L_par, bs, a)
        X, Y, Z = self._child_frame(seg["X"][si], seg["Y"][si], seg["Z"][si], rot, down)
        # lengths (Weber-Penn) and radii
        lcm_p = fam["lcm"][f]
        if lv == 0:
            ratio = np.clip((L_par - bs) / np.maximum(L_par * (1 - a), 1e-300), 0.0, 1.0)
            Lb = L_par * lcm_p * _sr(p, g["Shape"], ratio)
        else:
            Lb = lcm_p * (L_par - 0.6 * bs)
        Lb = np.maximum(Lb, 0.0)
        cap = self.radius(lv, fam, f, bs)
        rb_raw = fam["r0"][f] * (Lb / np.maximum(L_par, 1e-300)) ** g["RatioPower"]
        rb = np.minimum(rb_raw, cap)
        Lc, r_raw = Lb.copy(), rb_raw.copy()
        kind = np.where(is_knot, KNOT, NORMAL)
        dm = np.full(len(brow), np.nan)
        taper = np.full(len(brow), p.lv("Taper", lvc))
        if is_knot.any():
            kI = is_knot
            Lc[kI] = _kn.knot_length(Lb[kI], bs[kI] / L_par[kI], p.kn("Contraction", lvc),
                                     p.kn("ContractionV", lvc), 2 * ub[kI, 3] - 1)
            r_raw[kI] = _kn.knot_radius(rb[kI], p.kn("Density", lvc), p.kn("DensityV", lvc),
                                        2 * ub[kI, 4] - 1)
            dm[kI] = dorm[brow[kI]]
            taper[kI] = 1.0
            pos[kI] = _sink(pos[kI], Z[kI], seg["Z"][si[kI]], cap[kI],
                            np.minimum(r_raw[kI], cap[kI]))
        lcm = p.lv("Length", lvc + 1) + p.lv("LengthV", lvc + 1) * (2 * ub[:, 5] - 1)
        return self._fam(L=Lc, r_raw=r_raw, r_cap=cap, kind=kind, sprout=np.zeros(len(brow)),
                         dorm=dm, parent_seg=gid, parent_stem=rows["stem"][brow], attach=t,
                         offset=bs, L_par=L_par, lcm_par=lcm_p, lcm=lcm, taper=taper, pos=pos,
                         X=X, Y=Y, Z=Z)

    def _knot_buds(self, lv, fam, rows, seg, N, krows):
        """One dormant bud per knot: a sub-knot, or a sprouted branch once dormancy breaks."""
        p, g = self.p, self.p.params
        lvc = lv + 1
        f = rows["fam"][krows]
        n = len(krows)
        u = self.stream(lv, 3).random((n, 8))
        Lk = fam["L"][f]
        s = (0.5 + 0.45 * u[:, 0]) * Lk
        k = np.clip((s / (Lk / N)).astype(np.int64), 0, N - 1)
        frac = np.clip(s / (Lk / N) - k, 0, 1)
        si = seg["idx"][krows, k]
        ok = si >= 0
        if not ok.all():   # bud fell past a clone start; keep it on the row's last segment
            si = np.where(ok, si, seg["idx"][krows, N - 1])
        gid, t, pos = self._point(seg, si, frac)
        down = self._down_angle(lvc, u[:, 1], Lk, s, 0.0)
        X, Y, Z = self._child_frame(seg["X"][si], seg["Y"][si], seg["Z"][si], 360.0 * u[:, 2],
                                    down)
        v_new = _kn.dormancy_after(fam["dorm"][f], p.kn("DormancyStep", lvc))
        spr = v_new <= 0.0
        cap = self.radius(lv, fam, f, s)
        rk = fam["r0"][f]
        # sprouted branch: eqs 3.3-3.4 with the knot's own Contraction/Density
        C, CV = p.kn("Contraction", lv), p.kn("ContractionV", lv)
        D, DV = p.kn("Density", lv), p.kn("DensityV", lv)
        V = CV if p.knots["SproutVariation"] == "ContractionV" else DV
        Ls = _kn.sprout_length(Lk, C, V, p.lv("Length", lvc), 2 * u[:, 3] - 1)
        rs = _kn.sprout_radius(rk, Ls, Lk, D, DV, g["RatioPower"], 2 * u[:, 4] - 1)
        # sub-knot: Weber-Penn child of the knot, then eqs 3.1-3.2 at the next level
        Lb = np.maximum(fam["lcm"][f] * (Lk - 0.6 * s), 0.0)
        rb = np.minimum(rk * (Lb / np.maximum(Lk, 1e-300)) ** g["RatioPower"], cap)
        Lsk = _kn.knot_length(Lb, s / Lk, p.kn("Contraction", lvc), p.kn("ContractionV", lvc),
                              2 * u[:, 3] - 1)
        rsk = _kn.knot_radius(rb, p.kn("Density", lvc), p.kn("DensityV", lvc), 2 * u[:, 4] - 1)
        sub = ~spr
        pos[sub] = _sink(pos[sub], Z[sub], seg["Z"][si[sub]], cap[sub],
                         np.minimum(rsk[sub], cap[sub]))
        st = self.stats["levels"][lv]
        st["sprouts"] = int(spr.sum())
        st["subknots"] = int((~spr).sum())
        self.sprouted_rows = krows[spr]
        lcm = p.lv("Length", lvc + 1) + p.lv("LengthV", lvc + 1) * (2 * u[:, 5] - 1)
        return self._fam(L=np.where(spr, Ls, Lsk), r_raw=np.where(spr, rs, rsk), r_cap=cap,
                         kind=np.where(spr, NORMAL, KNOT), sprout=spr,
                         dorm=np.where(spr, np.nan, v_new), parent_seg=gid,
                         parent_stem=rows["stem"][krows], attach=t, offset=s, L_par=Lk,
                         lcm_par=fam["lcm"][f], lcm=lcm,
                         taper=np.where(spr, p.lv("Taper", lvc), 1.0), pos=pos, X=X, Y=Y, Z=Z)

    # -- leaves -----------------------------------------------------------------------------
    def make_leaves(self, lv, fam, rows, seg, N):
        p, g = self.p, self.p.params
        nl = g["Leaves"]
        if nl == 0:
            return
        f = rows["fam"]
        ok = fam["kind"][f] != KNOT
        nr = len(f)
        L = fam["L"][f]
        seglen = L / N
        share = (N - rows["k0"]) / N
        per = (abs(nl) * _sr(p, 4, fam["offset"][f] / np.maximum(fam["L_par"][f], 1e-300))
               * g["LeafQuality"])
        lvl = min(int(g["Levels"]), 3)
        q = g["LeafQuality"]
        if nl > 0:
            cnt = _errdiff(np.where(ok, per * share, 0.0))
            lrow = np.repeat(np.arange(nr), cnt)
            jj = np.arange(len(lrow)) - np.repeat(np.r_[0, np.cumsum(cnt)[:-1]], cnt)
            own = N - rows["k0"][lrow]
            s = (rows["k0"][lrow] + (jj + 0.5) / np.maximum(cnt[lrow], 1) * own) * seglen[lrow]
            u = self.stream(lv, 4).random((len(lrow), 3))
            step = p.lv("Rotate", lvl) + p.lv("RotateV", lvl) * (2 * u[:, 0] - 1)
            first = np.r_[True, lrow[1:] != lrow[:-1]] if len(lrow) else np.zeros(0, bool)
            startv = np.maximum.accumulate(np.where(first, np.arange(len(lrow)), 0))
            if p.lv("Rotate", lvl) >= 0:
                cs = np.cumsum(step)
                rot = np.mod(cs - cs[startv] + step[startv], 360.0)
            else:
                rank = np.arange(len(lrow)) - startv
                rot = np.where(rank % 2 == 0, 1.0, -1.0) * (180.0 + step)
            down = self._down_angle(lvl, u[:, 1], L[lrow], s, 0.0)
            k = np.clip((s / seglen[lrow]).astype(np.int64), 0, N - 1)
            frac = np.clip(s / seglen[lrow] - k, 0, 1)
            si = seg["idx"][lrow, k]
            bad = si < 0
            if bad.any():
                si[bad] = seg["idx"][lrow[bad], N - 1]
            gid, _, pos = self._point(seg, si, frac)
            X, Y, Z = self._child_frame(seg["X"][si], seg["Y"][si], seg["Z"][si], rot, down)
        else:   # fan of leaves at the stem tip
            cnt = _errdiff(np.where(ok, per, 0.0))
            lrow = np.repeat(np.arange(nr), cnt)
            jj = np.arange(len(lrow)) - np.repeat(np.r_[0, np.cumsum(cnt)[:-1]], cnt)
            u = self.stream(lv, 4).random((len(lrow), 3))
            si = seg["idx"][lrow, N - 1]
            gid, _, pos = self._point(seg, si, np.ones(len(lrow)))
            c = cnt[lrow]
            fan = (jj - (c - 1) / 2.0) * p.lv("Rotate", lvl) / np.maximum(c, 1) \
                + p.lv("RotateV", lvl) / np.maximum(c, 1) * (2 * u[:, 0] - 1)
            Xs, Ys, Zs = seg["X"][si], seg["Y"][si], seg["Z"][si]
            a = np.radians(fan)[:, None]      # rotate about the stem's y axis
            Zf = Zs * np.cos(a) + Xs * np.sin(a)
            Y, Z = _rotx(Ys, Zf, np.radians(p.lv("DownAngle", lvl)
                                            + p.lv("DownAngleV", lvl) * (2 * u[:, 1] - 1)))
        length = g["LeafScale"] / math.sqrt(q)
        width = g["LeafScale"] * g["LeafScaleX"] / math.sqrt(q)
        normal = np.where((Y[:, 2] < 0)[:, None], -Y, Y)
        self.leaves = {"pos": pos + 0.5 * length * Z, "normal": normal, "up": Z,
                       "seg": gid, "size": np.full(len(gid), length),
                       "width": np.full(len(gid), width)}
        self.stats["leaves"] = int(len(gid))

    # -- driver -----------------------------------------------------------------------------
    def run(self) -> Tree:
        p = self.p
        fam = self.trunk
        levels = int(p.params["Levels"])
        self.sprouted_rows = np.zeros(0, np.int64)
        for lv in range(levels):
            if fam is None or not len(fam["L"]):
                break
            rows, seg, N = self.grow_level(lv, fam)
            self.prune(lv, fam, rows, seg, N)
            self.sprouted_rows = np.zeros(0, np.int64)
            self.emit(lv, fam, rows, seg, N)
            nxt = self.buds(lv, fam, rows, seg, N)
            if len(self.sprouted_rows):   # knots whose bud broke dormancy
                st = rows["stem"][self.sprouted_rows]
                kind = self.out["kind"][-1]
                kind[np.isin(self.out["stem"][-1], st)] = SPROUTED_KNOT
            fam = nxt
        return self.assemble()

    def assemble(self) -> Tree:
        o = {k: np.concatenate(v) if v else np.zeros(0) for k, v in self.out.items()}
        zs = self.zscale

        def conv(v):   # WP z-up -> package y-up: (x, y, z) -> (x, z, -y)
            v = np.asarray(v, float).reshape(-1, 3)
            return np.stack([v[:, 0], v[:, 2] * zs, -v[:, 1]], 1)

        def convdir(v):
            return _unit(np.stack([v[:, 0], v[:, 2] * zs, -v[:, 1]], 1))
        g = self.p.params
        lvl = o["level"].astype(np.int64)
        attrs = {
            "stem": o["stem"].astype(np.int64), "attach": o["attach"],
            "frame_x": convdir(o["fx"]), "arc": o["arc"], "stem_length": o["slen"],
            "stem_radius": o["srad"], "dormancy": o["dorm"], "sprout": o["sprout"].astype(bool),
            "clone": o["clone"].astype(bool),
            "lobe_depth": np.where(lvl == 0, g["LobeDepth"], 0.0),
            "lobes": np.where(lvl == 0, g["Lobes"], 0).astype(np.int64),
        }
        if self.leaves is not None and len(self.leaves["seg"]):
            lv_ = self.leaves
            leaves = Leaves(conv(lv_["pos"]), convdir(lv_["normal"]), lv_["size"],
                            lv_["seg"].astype(np.int64), convdir(lv_["up"]),
                            {"width": lv_["width"]})
        else:
            leaves = Leaves.empty()
            leaves.attrs["width"] = np.zeros(0)
        tree = Tree(conv(o["start"]), conv(o["end"]), o["r0"], o["r1"], o["parent"], lvl,
                    None, o["kind"].astype(np.int8), leaves, attrs, self.p.name)
        self.stats["segments"] = len(tree)
        self.stats["stems"] = int(self.n_stems)
        self.stats["knots"] = int(sum(s.get("knots", 0) + s.get("subknots", 0)
                                      for s in self.stats["levels"].values()))
        tree.weber_penn = WeberPennInfo(self.p, self.seed, self.knots_on, self.scale_tree,
                                        self.stats)
        return tree


def generate(preset_or_params="quaking_aspen", seed=0, *, knots: bool | None = None,
             overrides: dict | None = None) -> Tree:
    """Grow one Weber-Penn tree.

    Per-segment extras in ``tree.attrs``: ``stem`` (stem id), ``attach`` (where on its parent
    segment a stem starts, 0..1), ``frame_x`` (cross-section reference axis), ``arc`` (distance
    from the stem base [m]), ``stem_length`` [m], ``stem_radius`` [m], ``dormancy`` (knots),
    ``sprout`` (branch grown from a knot), ``clone`` (first segment of a split clone),
    ``lobes``/``lobe_depth`` (trunk). Leaves carry ``attrs["width"]`` [m].
    ``tree.weber_penn`` records the parameters, seed and counts.

    Parameters
    ----------
    preset_or_params : str, pathlib.Path, dict or WeberPennParams, optional
        A preset name (:data:`PRESETS`), a TOML path, a dict or a :class:`WeberPennParams`
        (default ``"quaking_aspen"``).
    seed : int or None, optional
        Integer seed >= 0 (the same seed gives the same tree; default 0); None for a random tree.
    knots : bool, optional
        Grow knots (default None: the parameters' ``knots.enabled``).
    overrides : dict, optional
        Extra parameter values (flat Weber-Penn names or sections); default None.

    Returns
    -------
    Tree
        The tree in metres (+y up, trunk base at the origin).

    Raises
    ------
    ParameterError
        For invalid parameters or a seed that is not an integer >= 0.
    """
    p = load_params(preset_or_params)
    if overrides:
        p = p.updated(overrides)
    if seed is not None:
        try:
            seed = int(seed)
        except (TypeError, ValueError):
            raise ParameterError("seed", seed, "an integer >= 0 (or None for a random tree)") \
                from None
        if seed < 0:
            raise ParameterError("seed", seed, "an integer >= 0 (or None for a random tree)")
    on = p.knots["enabled"] if knots is None else bool(knots)
    return _Grower(p, seed, on).run()


def mesh(tree: Tree, *, smooth: bool = True, **kw):
    """``(bark, leaves)`` trimesh meshes of a tree (see :func:`junction.tree_mesh`).

    Parameters
    ----------
    tree : Tree
        The tree (e.g. from :func:`generate`).
    smooth : bool, optional
        Smooth the junctions with eq 4.2 (paper 004 §4); default True.
    **kw : dict
        Further keyword arguments of :func:`~mitsuba_veg.trees.junction.tree_mesh`.

    Returns
    -------
    bark : trimesh.Trimesh
        Bark mesh [m].
    leaves : trimesh.Trimesh
        Leaf mesh [m].
    """
    return tree_mesh(tree, smooth=smooth, **kw)


def export(tree: Tree, path, *, smooth: bool = True, **kw) -> list[str]:
    """Write the bark and leaf meshes of a tree.

    ``.glb``/``.gltf``/``.obj`` hold both (named ``bark`` and ``leaves``); ``.ply`` writes
    ``name.ply`` (bark) and ``name_leaves.ply`` (when the tree has leaves). Parent folders are
    created.

    Parameters
    ----------
    tree : Tree
        The tree.
    path : str or pathlib.Path
        Output file; the extension picks the format.
    smooth : bool, optional
        Smooth the junctions (default True).
    **kw : dict
        Further keyword arguments of :func:`~mitsuba_veg.trees.junction.tree_mesh`.

    Returns
    -------
    list of str
        The paths written.

    Raises
    ------
    ParameterError
        If the extension is not .ply, .obj, .glb or .gltf.
    """
    import trimesh

    path = Path(path)
    ext = path.suffix.lower().lstrip(".")
    if ext not in ("ply", "obj", "glb", "gltf"):
        raise ParameterError("path", str(path), "a .ply, .obj, .glb or .gltf file name",
                             "change the extension")
    bark, leaves = mesh(tree, smooth=smooth, **kw)
    path.parent.mkdir(parents=True, exist_ok=True)
    if ext == "ply":
        bark.export(str(path))
        out = [str(path)]
        if len(leaves.faces):
            lp = path.with_name(path.stem + "_leaves.ply")
            leaves.export(str(lp))
            out.append(str(lp))
        return out
    scene = trimesh.Scene()
    scene.add_geometry(bark, node_name="bark", geom_name="bark")
    if len(leaves.faces):
        scene.add_geometry(leaves, node_name="leaves", geom_name="leaves")
    scene.export(str(path))
    return [str(path)]
