"""Sweep files (TOML): a base scenario, the axes to vary, the seeds; validated before any run.

A sweep file looks like this (paths relative to the sweep file)::

    [sweep]
    scenario = "scenario.toml"          # the base scenario
    days = 20                           # days of every run (default: the scenario's)
    seeds = [0, 1]                      # light.seed of the runs (or {start = 0, stop = 3})
    set = ["light.photons=200000"]      # overrides of every run, as with --set
    frames = true                       # maps/day_NNNN.png + days.gif in every run folder

    [axes]                              # every dotted scenario field, as with --set
    "climate.temperature" = [288.15, 293.15]
    "climate.humidity" = {start = 0.6, stop = 0.8, num = 3}     # 0.6, 0.7, 0.8
    "moss.species" = [["bryum_argenteum"], ["polytrichum"]]

The runs are the Cartesian product of the axes (in file order), then the seeds. Unknown keys of
the sweep file and axis fields that the scenario does not have are refused with one line naming
the file, the field and the closest known names (:class:`~mitsuba_veg.errors.ParameterError`),
before any run starts, and so is every combination whose scenario or run settings (field
values, species, weather, days) do not validate: the line names the run's swept values. A run
id is a hash of the base scenario, the run's values and the content of every file the run reads
(:func:`mitsuba_veg.inputs.input_hashes`), so an edited scene, mesh or weather file gives new
runs. What only the run can find (e.g. a shape id missing from the scene) fails that run, which
is reported in the sweep's table with its error.

Nothing here imports Dask.
"""
from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..daily import MOSS_DEFAULTS, SIM_DEFAULTS, MossConfig
from ..errors import ParameterError, unknown_field
from ..inputs import input_hashes
from ..scenario import load_scenario

__all__ = ["SWEEP_KEYS", "TOP_KEYS", "RANGE_KEYS", "SEED_FIELD", "RunSpec", "Sweep", "toml_value",
           "known_fields", "load_sweep"]

#: keys of the [sweep] table
SWEEP_KEYS = ("scenario", "days", "seeds", "set", "frames")
#: top-level tables of a sweep file
TOP_KEYS = ("sweep", "axes")
#: keys of a range table: {start, stop, num} or {start, stop, step}
RANGE_KEYS = {"start", "stop", "num", "step"}
#: the scenario field a sweep's seeds set
SEED_FIELD = "light.seed"


def _closest(name: str, known) -> str:
    m = difflib.get_close_matches(name, list(known), n=3, cutoff=0.5)
    return ("did you mean " + " or ".join(repr(x) for x in m) + "?") if m else \
        "remove or rename it"


def _unknown(source: str, field_: str, value, known) -> ParameterError:
    return unknown_field(field_, value, known, source, "README.md (Sweeps on Dask)")


@dataclass
class RunSpec:
    """One run of a sweep.

    Attributes
    ----------
    index : int
        Position in the sweep's order (axes product, then seeds).
    run_id : str
        Folder name under ``OUT/runs/``: a hash of the base scenario and the run's values, so
        that the same run keeps its folder when the sweep file grows.
    values : dict
        Swept field (dotted name) -> value of this run.
    overrides : list of str
        ``KEY=VALUE`` overrides of the run (the sweep's ``set`` first, then the axes).
    """

    index: int
    run_id: str
    values: dict
    overrides: list


@dataclass
class Sweep:
    """A validated sweep file.

    Attributes
    ----------
    path : Path
        The sweep file.
    scenario : Path
        The base scenario (absolute).
    days : int or None
        Days of every run [d]; None: the scenario's ``simulation.days``.
    axes : dict
        Dotted field -> list of values, in file order; the seeds are the last axis
        (``light.seed``) when given.
    base_set : list of str
        Overrides of every run (``[sweep] set``, then the caller's).
    frames : bool
        Whether runs write maps and ``days.gif`` (the checkpoint and summary.json always).
    """

    path: Path
    scenario: Path
    days: int | None
    axes: dict
    base_set: list
    frames: bool = True
    base_fingerprint: str = ""
    runs: list = field(default_factory=list)

    @property
    def fields(self) -> list[str]:
        """The swept fields (dotted names), seeds last."""
        return list(self.axes)


def toml_value(v) -> str:
    """A value as ``--set`` text (TOML syntax).

    Booleans as ``true``/``false``, strings quoted, non-finite floats as ``nan``/``inf``/``-inf``,
    lists as arrays and dicts as inline tables (recursively).

    Parameters
    ----------
    v : bool, int, float, str, list, tuple or dict
        The value.

    Returns
    -------
    str
        Its TOML text.
    """
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else
                                                 ("inf" if v > 0 else "-inf"))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    return str(v)


def _expand_range(field_: str, spec: dict, source: str) -> list:
    """``{start, stop, num}`` (evenly spaced, both ends) or ``{start, stop, step}`` (start,
    start + step, ... up to stop inclusive)."""
    bad = set(spec) - RANGE_KEYS
    if bad:
        k = sorted(bad)[0]
        raise ParameterError(f"axes.{field_}.{k}", spec[k], "start, stop and num or step",
                             _closest(k, RANGE_KEYS), source)
    for k in ("start", "stop"):
        if k not in spec or isinstance(spec[k], bool) or not isinstance(spec[k], (int, float)):
            raise ParameterError(f"axes.{field_}.{k}", spec.get(k), "a number",
                                 "a range is {start = A, stop = B, num = N} or "
                                 "{start = A, stop = B, step = S}", source)
    if ("num" in spec) == ("step" in spec):
        raise ParameterError(f"axes.{field_}", spec, "a range with either num or step",
                             "give num (count of values) or step (spacing)", source)
    a, b = spec["start"], spec["stop"]
    if "num" in spec:
        n = spec["num"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100_000:
            raise ParameterError(f"axes.{field_}.num", n, "an integer in [1, 100000]", None,
                                 source)
        if n == 1:
            return [a]
        vals = [a + (b - a) * i / (n - 1) for i in range(n)]
        if all(isinstance(x, int) for x in (a, b)) and all(float(v).is_integer() for v in vals):
            return [int(v) for v in vals]
        return [round(float(v), 12) for v in vals]
    s = spec["step"]
    if isinstance(s, bool) or not isinstance(s, (int, float)) or s == 0 or \
            (b - a) / s < 0 or (b - a) / s > 100_000:
        raise ParameterError(f"axes.{field_}.step", s, "a non-zero number of the sign of "
                             "stop - start, giving at most 100000 values", None, source)
    n = int(math.floor((b - a) / s + 1e-9)) + 1
    if all(isinstance(x, int) for x in (a, b, s)):
        return [a + i * s for i in range(n)]
    return [round(a + i * s, 12) for i in range(n)]


def _axis_values(field_: str, raw, source: str) -> list:
    if isinstance(raw, dict):
        return _expand_range(field_, raw, source)
    if isinstance(raw, list):
        if not raw:
            raise ParameterError(f"axes.{field_}", raw, "a non-empty list or a range table",
                                 None, source)
        return list(raw)
    return [raw]


def _flatten_axes(node: dict, prefix: str = "") -> dict:
    """``[axes]`` with quoted dotted keys (``"climate.temperature" = [...]``) or nested tables
    (``climate.temperature = [...]``): field -> raw values."""
    out = {}
    for k, v in node.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict) and not (set(v) <= RANGE_KEYS and "start" in v):
            out.update(_flatten_axes(v, name + "."))
        else:
            out[name] = v
    return out


def known_fields(data: dict) -> tuple[set, tuple]:
    """Dotted scenario fields a sweep may vary.

    Those of the (defaulted) base scenario, the documented defaults of the run, and free-keyed
    tables (per-shape settings).

    Parameters
    ----------
    data : dict
        The base scenario's (defaulted) data, nested tables.

    Returns
    -------
    fields : set of str
        Known dotted field names.
    open_prefixes : tuple of str
        Prefixes under which any name is accepted (``terrain.soil_depth_mm.``,
        ``terrain.geology.``: one entry per shape id).
    """
    fields = set()

    def walk(node, prefix):
        for k, v in node.items():
            if isinstance(v, dict) and v:
                walk(v, f"{prefix}{k}.")
            else:
                fields.add(f"{prefix}{k}")

    walk(data, "")
    fields |= {f"moss.{k}" for k in MOSS_DEFAULTS}
    fields |= {f"simulation.{k}" for k in SIM_DEFAULTS}
    fields |= {f"climate.{k}" for k in ("temperature", "humidity", "precipitation", "rain_days",
                                        "wind", "possible_sunshine", "sunshine", "angstrom_a",
                                        "angstrom_b", "csv")}
    fields |= {f"light.{k}" for k in ("photons", "max_depth", "seed", "indirect", "when")}
    fields |= {"site.latitude", "site.longitude", "scene.file", "species_file",
               "terrain.ground", "terrain.geology_texture", "terrain.soil_base_y"}
    return fields, ("terrain.soil_depth_mm.", "terrain.geology.")


def _fingerprint(obj) -> str:
    return hashlib.sha1(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def _check_run(scenario: Path, overrides: list, days, values: dict, source: str):
    """Load and check one run's scenario and settings (fields, species, weather, days) before
    any run starts; an error names the run's swept values."""
    try:
        scn = load_scenario(scenario, overrides)
        MossConfig(scn, days)
    except ParameterError as e:
        where = ", ".join(f"{k}={toml_value(v)}" for k, v in values.items())
        raise ParameterError(e.field, e.value, e.allowed, e.fix,
                             f"{source} (the run with {where})" if where else source) from None
    return scn


def load_sweep(path, overrides=()) -> Sweep:
    """Read and validate a sweep file; expand its runs.

    Parameters
    ----------
    path : str or Path
        The sweep TOML file.
    overrides : sequence of str
        ``KEY=VALUE`` overrides of the base scenario for every run (after the file's ``set``).

    Returns
    -------
    Sweep
        With ``runs``: one :class:`RunSpec` per run, in order.

    Raises
    ------
    ParameterError
        Unknown keys (with the closest known names), a bad range, an axis field the scenario
        does not have, a base scenario that does not validate, or a combination whose
        scenario or run settings do not validate.
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        raise ParameterError("SWEEP", src, "an existing sweep TOML file",
                             "check the path (e.g. scenes/moss_garden/sweep.toml)")
    try:
        # utf-8-sig: a byte-order mark (some editors write one) is not part of the TOML
        doc = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ParameterError("SWEEP", src, "valid TOML (UTF-8 text)", str(e)) from None
    for k in doc:
        if k not in TOP_KEYS:
            raise ParameterError(k, doc[k], "the tables [sweep] and [axes]", _closest(k, TOP_KEYS),
                                 src)
    sw = doc.get("sweep", {})
    if not isinstance(sw, dict):
        raise ParameterError("sweep", sw, "a table [sweep]", None, src)
    for k in sw:
        if k not in SWEEP_KEYS:
            raise _unknown(src, f"sweep.{k}", sw[k], [f"sweep.{x}" for x in SWEEP_KEYS])
    if "scenario" not in sw or not isinstance(sw["scenario"], str):
        raise ParameterError("sweep.scenario", sw.get("scenario"), "a scenario TOML path "
                             "(relative to the sweep file)",
                             'add scenario = "scenario.toml" under [sweep]', src)
    scen = (path.parent / sw["scenario"]).resolve()
    if not scen.is_file():
        raise ParameterError("sweep.scenario", sw["scenario"], "an existing scenario file "
                             "(relative to the sweep file)", f"looked for {scen}", src)
    days = sw.get("days")
    if days is not None and (isinstance(days, bool) or not isinstance(days, int)
                             or not 1 <= days <= 100_000):
        raise ParameterError("sweep.days", days, "an integer in [1, 100000]", None, src)
    base_set = sw.get("set", [])
    if isinstance(base_set, str):
        base_set = [base_set]
    if not isinstance(base_set, list) or not all(isinstance(s, str) and "=" in s
                                                 for s in base_set):
        raise ParameterError("sweep.set", base_set, "a list of \"KEY=VALUE\" strings",
                             'e.g. set = ["light.photons=200000"]', src)
    base_set = list(base_set) + list(overrides or ())
    frames = sw.get("frames", True)
    if not isinstance(frames, bool):
        raise ParameterError("sweep.frames", frames, "true or false", None, src)

    base = load_scenario(scen, base_set)      # the base must validate on its own
    fields, open_prefixes = known_fields(base.data)

    raw_axes = doc.get("axes", {})
    if not isinstance(raw_axes, dict):
        raise ParameterError("axes", raw_axes, "a table [axes] of FIELD = [values]", None, src)
    axes = {}
    for f_, raw in _flatten_axes(raw_axes).items():
        if f_ not in fields and not f_.startswith(open_prefixes):
            raise _unknown(src, f"axes.{f_}", raw, sorted(fields))
        axes[f_] = _axis_values(f_, raw, src)
    if "seeds" in sw:
        if SEED_FIELD in axes:
            raise ParameterError("sweep.seeds", sw["seeds"], f"seeds or an axis {SEED_FIELD}, "
                                 "not both", "keep one of them", src)
        seeds = _axis_values("seeds", sw["seeds"], src)
        for s in seeds:
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s <= 2**31 - 1:
                raise ParameterError("sweep.seeds", s, "integers in [0, 2147483647]", None, src)
        axes[SEED_FIELD] = seeds
    if days is not None and "simulation.days" in axes:
        raise ParameterError("sweep.days", days, "sweep.days or an axis simulation.days, not "
                             "both", "keep one of them", src)
    base_fp = _fingerprint({"scenario": base.data, "set": base_set})
    out = Sweep(path.resolve(), scen, days, axes, base_set, frames, base_fp)
    names = list(axes)
    seen = {}
    for i, combo in enumerate(itertools.product(*[axes[n] for n in names]) if names else [()]):
        values = dict(zip(names, combo))
        ov = base_set + [f"{k}={toml_value(v)}" for k, v in values.items()]
        scn = _check_run(scen, ov, days, values, src)
        # the content of every file the run reads is part of its id: an edited scene, mesh or
        # weather file makes new runs instead of taking the old ones as finished
        rid = _fingerprint({"base": base_fp, "values": {k: toml_value(v)
                                                        for k, v in values.items()},
                            "inputs": input_hashes(scn)})[:12]
        if rid in seen:
            raise ParameterError("axes", values, "distinct runs", "an axis repeats a value", src)
        seen[rid] = i
        out.runs.append(RunSpec(i, f"run-{rid}", values, ov))
    return out
