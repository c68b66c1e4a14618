"""Scenario files (TOML): load, validate at the boundary, apply ``--set`` overrides, build scenes.

A scenario names a Mitsuba scene file and the settings of a run. Every value is checked when the
file is read; a bad one raises :class:`~mitsuba_veg.errors.ParameterError` naming the file, the
field (dotted name), the value, the allowed range and the fix.

Sections used so far (paths relative to the scenario file)::

    [scene] file                Mitsuba XML scene; loaded with optimize=False to keep shape ids.
    [site] latitude, longitude  [deg] north/east positive.
    [light]                     photons, max_depth, seed, indirect, and optionally when (ISO
                                date-time): then the scene's own emitters are replaced by a physical
                                daylight sun + sky (:func:`mitsuba_veg.light.daylight`).
    [terrain]                   ground (shape id), geology_texture, soil_base_y [m],
                                [terrain.soil_depth_mm] per-shape soil depth.
    [regions.NAME]              shapes, min, max: boxes [m] naming parts of the terrain.
    [[sensors]]                 virtual light sensors: points and grids (docs/sensors.md).
    [[hemiphotos]]              hemispherical photographs at fixed floor points (docs/hemiphoto.md).
"""
from __future__ import annotations

import copy
import datetime as _dt
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import mitsuba as mi

from .defaults import LIGHT, MAX_PHOTONS  # noqa: F401  (MAX_PHOTONS: part of this API)
from .errors import ParameterError, plugin_error, unknown_field
from .inputs import check_scene_files, input_hashes
from .light.clear_sky import daylight as _daylight

__all__ = ["Field", "SCHEMA", "known_fields", "schema_markdown", "field_spec", "Scenario",
           "load_scene_file", "XML_SET_FIELDS", "light_overrides", "apply_overrides", "validate",
           "site_offset_hours", "site_time", "load_scenario"]

_DEFAULTS = {
    "light": {k: LIGHT[k].default for k in ("photons", "max_depth", "seed", "indirect")},
    "site": {"latitude": 35.0, "longitude": 139.0},
}


# --------------------------------------------------------------------------------------------
# The schema: every field a scenario may hold. Unknown fields are refused (with the closest
# known names), so that a typo never runs silently with a default.
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Field:
    """One scenario field: ``kind`` is int, float, bool, str, date, datetime, file, vec3,
    floats (a list of numbers), strs (a list of strings), choice, table (fixed ``fields``),
    map (user-named keys, each value checked against ``item``) or tables (an array of tables
    with ``fields``). ``lo``/``hi`` bound numbers (and list lengths via ``length``)."""

    kind: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple = ()
    fields: dict | None = None
    item: "Field | None" = None
    length: int | None = None
    doc: str = ""


def _num(kind, lo, hi, doc=""):
    return Field(kind, lo, hi, doc=doc)


_GEOLOGIES = ("humus", "sand", "asphalt")
_VEC3 = Field("vec3", doc="[x, y, z] in metres")

#: every scenario field by its dotted name (docs/scenario.md is generated from it)
SCHEMA: dict[str, Field] = {
    "scene": Field("table", fields={"file": Field("file", doc="Mitsuba XML scene")}),
    "site": Field("table", fields={
        "latitude": _num("float", -90.0, 90.0, "[deg] north positive"),
        "longitude": _num("float", -180.0, 180.0, "[deg] east positive"),
        "timezone": _num("float", -14.0, 14.0, "[h] offset from UTC (default: longitude / 15, "
                         "rounded)"),
    }),
    "light": Field("table", fields={
        "photons": _num("int", LIGHT["photons"].lo, LIGHT["photons"].hi, LIGHT["photons"].doc),
        "max_depth": _num("int", LIGHT["max_depth"].lo, LIGHT["max_depth"].hi,
                          LIGHT["max_depth"].doc),
        "seed": _num("int", LIGHT["seed"].lo, LIGHT["seed"].hi,
                     "random seed of the light, weather and moss"),
        "indirect": Field("bool", doc="false: direct light only (paper 000 fig 4.2)"),
        "when": Field("datetime", doc="ISO 8601 date-time, e.g. 2026-04-20T10:00:00+09:00 "
                      "(no offset: the site's local time)"),
    }),
    "terrain": Field("table", fields={
        "ground": Field("str", doc="shape id of the soil-bearing terrain"),
        "geology_texture": Field("file", doc="image over the ground's UVs: humus (70,50,35), sand "
                                 "(200,160,80), asphalt (110,110,110)"),
        "soil_base_y": _num("float", -1e4, 1e4, "[m]"),
        "soil_depth_mm": Field("map", item=_num("float", 1.0, 1000.0, "[mm]"),
                               doc="soil depth h [mm] per shape id, 1-1000"),
        "geology": Field("map", item=Field("choice", choices=_GEOLOGIES),
                         doc="geology per shape id: humus, sand or asphalt"),
    }),
    "regions": Field("map", item=Field("table", fields={
        "shapes": Field("strs", doc="shape ids"), "min": _VEC3, "max": _VEC3})),
    "simulation": Field("table", fields={
        "days": _num("int", 1, 100_000, "simulated days"),
        "start_date": Field("date", doc="YYYY-MM-DD"),
        "checkpoint_every": _num("int", 0, 100_000, "days between checkpoints (0: at the end)"),
        "frame_every": _num("int", 1, 100_000, "days between maps and snapshots"),
        "light_every": _num("int", 1, 365, "days between photon passes (1: every day); the "
                            "days between reuse the last pass's fractions with their own "
                            "weather"),
    }),
    "climate": Field("table", fields={
        "temperature": _num("float", 200.0, 340.0, "[K]"),
        "humidity": _num("float", 0.0, 1.0, "[-]"),
        "precipitation": _num("float", 0.0, 20000.0, "[mm/yr]"),
        "rain_days": _num("int", 0, 365, "[days/yr]"),
        "wind": _num("float", 0.0, 60.0, "[m/s]"),
        "possible_sunshine": _num("float", 0.0, 24.0, "[h]"),
        "sunshine": _num("float", 0.0, 24.0, "[h]"),
        "angstrom_a": _num("float", 0.0, 1.0, "Angstrom-Prescott a_s [-]"),
        "angstrom_b": _num("float", 0.0, 1.0, "Angstrom-Prescott b_s [-]"),
        "csv": Field("file", doc="daily weather CSV (T, rh, P, U, A or N and N0, ghi, day_of_year)"),
    }),
    "moss": Field("table", fields={
        "species": Field("strs", doc="species keys"),
        "capacity": _num("int", 16, 50_000_000, "individuals (moss + waiting propagules)"),
        "initial": _num("int", 0, 50_000_000, "moss placed at random on day 0"),
        "initial_growth": _num("float", 0.0, 1000.0, "G_moss [-]"),
        "size": _num("float", 1e-4, 1.0, "[m] moss size = spot of the occupancy grid"),
        "gemma_distance": _num("float", 0.0, 100.0, "k of eq 3.22 [m]"),
        "spore_distance": _num("float", 0.0, 100.0, "l of eq 3.23 [m]"),
        "external_spore_interval": _num("int", 0, 100_000, "days between spores from outside "
                                        "(0: none)"),
        "clump_neighbours": _num("int", 1, 26, "moss neighbours that make a clump"),
        "albedo": Field("floats", 0.0, 1.0, length=4, doc="moss reflectance: total, PAR, red, "
                                                          "far-red"),
        "priority": Field("floats", -1e6, 1e6, doc="occupancy priority, one per species"),
        "shapes": Field("strs", doc="shape ids moss may live on"),
    }),
    "species_file": Field("file", doc="TOML of extra species (docs/moss.md)"),
    "trees": Field("tables", doc="trees of the simulated world (docs/world.md)", fields={
        "name": Field("str", doc="name in summaries (default treeN)"),
        "model": Field("choice", choices=("growth", "weber_penn", "mesh")),
        "position": _VEC3,
        "seed": _num("int", 0, 2**31 - 1),
        "preset": Field("str", doc="Weber-Penn preset"),
        "overrides": Field("any", doc="Weber-Penn parameters"),
        "height": _num("float", 0.05, 200.0, "[m] scale a Weber-Penn tree to this height"),
        "adapt": Field("bool", doc="Weber-Penn: deform by paper 002's rules in the scene"),
        "adapt_yearly": Field("bool", doc="Weber-Penn: paper 002's death rule every 31 "
                              "December from its leaves' light in the year's passes "
                              "(death_threshold; docs/forest.md)"),
        "age": _num("float", 0.5, 1000.0, "[years] Weber-Penn: its age at the start; it then "
                    "grows every 31 December along a Chapman-Richards curve through its "
                    "height (docs/world.md)"),
        "age_rate": _num("float", 1e-4, 2.0, "[1/year] k of that curve (default 0.05)"),
        "voxel_size": _num("float", 0.01, 10.0, "[m] voxels of the non-growth light"),
        "death_threshold": _num("float", 0.0, 1.0, "adapt: paper 002's T/N threshold "
                                "(mean leaf light, default 0.5)"),
        "generations": _num("int", 0, 20, "growth model generations G"),
        "growth": Field("any", doc="GrowthParams fields (unit [m] sets the size)"),
        "file": Field("file", doc="mesh: the wood (PLY/OBJ/GLB)"),
        "leaves_file": Field("file", doc="mesh: the foliage, one leaf element per triangle"),
        "scale": _num("float", 1e-4, 1e4, "mesh: scale factor"),
    }),
    "stand": Field("table", doc="trees laid out over the terrain: Weber-Penn presets and/or "
                   "trees grown together by paper 001's model (docs/forest.md)", fields={
        "plot": Field("any", doc="[x0, z0, x1, z1] [m] or [[x, z], ...] (a polygon)"),
        "density": _num("float", 1e-3, 1e5, "[trees/ha] of map area"),
        "mix": Field("any", doc="{species = weight}: Weber-Penn presets and \"growth\""),
        "placement": Field("choice", choices=("poisson_disc", "clumped")),
        "min_spacing": _num("float", 0.0, 1e3, "[m] smallest distance between two trees"),
        "cluster": Field("choice", choices=("thomas", "matern")),
        "cluster_radius": _num("float", 1e-3, 1e4, "[m] clumped placement"),
        "parent_density": _num("float", 1e-3, 1e5, "[1/ha] cluster centres"),
        "height_mean": _num("float", 0.05, 200.0, "[m] (Weber-Penn stand trees)"),
        "height_cv": _num("float", 0.0, 2.0, "[-]"),
        "height_range": Field("any", doc="[lo, hi] [m]"),
        "variants": _num("int", 1, 1000, "geometry variants per preset"),
        "seed": _num("int", 0, 2**31 - 1),
        "generations": _num("int", 0, 20, "growth model generations G at set-up"),
        "growth": Field("any", doc="GrowthParams fields (unit [m] sets the size)"),
        "age": _num("float", 0.5, 1000.0, "[years] Weber-Penn members: their age at the start; "
                    "they grow every 31 December along a Chapman-Richards curve through their "
                    "height (docs/world.md)"),
        "age_rate": _num("float", 1e-4, 2.0, "[1/year] k of that curve (default 0.05)"),
        "adapt_yearly": Field("bool", doc="Weber-Penn members: paper 002's death rule every 31 "
                              "December from their leaves' light (docs/forest.md)"),
        "death_threshold": _num("float", 0.0, 1.0, "adapt_yearly: T/N, the mean leaf light "
                                "relative to the open below which a subtree dies (default "
                                "0.5)"),
    }),
    "phenology": Field("table", fields={
        "leaf_out_doy": _num("int", 1, 366, "day of year leaf-out starts"),
        "leaf_out_days": _num("int", 1, 180, "days from bud to full blade"),
        "autumn_onset_doy": _num("int", 1, 366, "day of year the autumn clock starts"),
        "insolation_full": _num("float", 1e-3, 1e5, "H_full [MJ m-2] (paper 003)"),
        "time_weight": _num("float", 0.0, 1.0, "beta: share of aging with time [-]"),
        "days_full": _num("float", 1e-3, 1000.0, "D_full [days]"),
        "rate_sigma": _num("float", 0.0, 2.0, "log-sd of the per-leaf rate"),
        "fall_tau": _num("float", 1e-3, 100.0, "median tau_raw at leaf fall"),
        "fall_sigma": _num("float", 0.0, 2.0, "log-sd of the fall threshold"),
        "stage_bins": _num("int", 1, 7, "leaf meshes (stage bins) of the light scene, "
                                           "default 4"),
    }),
    "sensors": Field("tables", doc="virtual light sensors (docs/sensors.md)", fields={
        "name": Field("str", doc="sensor name (grids: NAME_iii_jjj)"),
        "kind": Field("choice", choices=("cosine", "hemispherical", "spherical"),
                      doc="default cosine (planar); spherical: fluence rate; hemispherical: "
                          "dome"),
        "layout": Field("choice", choices=("point", "ground_grid", "plane_grid"),
                        doc="default point"),
        "position": Field("vec3", doc="point: centre [x, y, z] [m]"),
        "normal": Field("vec3", doc="axis: front of a cosine sensor, dome axis (default up; "
                                    "plane_grid: u x v)"),
        "size": _num("float", 0.001, 10.0, "[m] side / diameter (default 0.1)"),
        "spacing": _num("float", 0.001, 1e4, "[m] grid spacing"),
        "height": _num("float", -100.0, 1000.0, "ground_grid: [m] above the ground (default "
                                                 "0.5)"),
        "x": Field("floats", -1e5, 1e5, length=2, doc="ground_grid: [min, max] [m] (default: "
                                                      "the ground)"),
        "z": Field("floats", -1e5, 1e5, length=2, doc="ground_grid: [min, max] [m] (default: "
                                                      "the ground)"),
        "ground": Field("str", doc="ground_grid: terrain shape id (default terrain.ground)"),
        "origin": Field("vec3", doc="plane_grid: a corner [m]"),
        "u": Field("vec3", doc="plane_grid: first edge [m]"),
        "v": Field("vec3", doc="plane_grid: second edge [m]"),
    }),
    "hemiphotos": Field("tables", doc="hemispherical photographs at fixed floor points, taken "
                        "by a run on their days (docs/hemiphoto.md)", fields={
        "name": Field("str", doc="name in file names and tables (default photoN)"),
        "at": Field("floats", -1e5, 1e5, length=2, doc="[x, z] [m]: the floor position"),
        "height": _num("float", 0.01, 100.0, "[m] lens above the ground (default 1)"),
        "on": Field("strs", doc="days of the year \"MM-DD\" (default [\"07-15\"])"),
        "size": _num("int", 16, 8192, "[px] image side (default 1024)"),
        "projection": Field("choice", choices=("equidistant", "equisolid"),
                            doc="fisheye projection (default equidistant)"),
        "ring_width": _num("float", 0.5, 90.0, "[deg] zenith rings of the table besides the "
                           "LAI-2000's (default 5)"),
    }),
    "render": Field("table", fields={
        "when": Field("datetime", doc="daylight of the render (default: the day at 10:00; "
                      "no offset: the site's local time)"),
        "materials": Field("map", item=Field("str"), doc="render material per shape id or "
                           "pattern (log_*)"),
        "surround": Field("str", doc="ground around the scene to the horizon: 'ground' (the "
                          "ground's material), a material name, or 'none'"),
        "cameras": Field("map", item=Field("table", fields={
            "origin": _VEC3, "target": _VEC3, "up": _VEC3,
            "fov": _num("float", 1.0, 170.0, "[deg]"),
            "fov_axis": Field("choice", choices=("x", "y", "smaller", "larger", "diagonal"))})),
        "trees": Field("tables", fields={
            "preset": Field("str", doc="Weber-Penn preset"), "model": Field("choice", choices=("weber_penn", "growth",
                                                                       "simple")),
            "seed": _num("int", 0, 2**31 - 1), "position": _VEC3,
            "height": _num("float", 0.05, 200.0, "[m]"), "autumn": Field("bool"),
            "overrides": Field("any"), "generations": _num("int", 0, 20),
            "growth": Field("any")}),
    }),
}


def known_fields(schema: dict | None = None, prefix: str = "") -> list[str]:
    """Every dotted field name of the schema (user-named map keys shown as ``NAME``).

    Parameters
    ----------
    schema : dict of str to Field, optional
        The (sub-)schema to list; default None: :data:`SCHEMA`.
    prefix : str, optional
        Prefix of the names (``"terrain."`` for a sub-table); default ``""``.

    Returns
    -------
    list of str
        Dotted names such as ``"light.photons"`` or ``"regions.NAME.min"``, tables before their
        fields.
    """
    out = []
    for k, f in (SCHEMA if schema is None else schema).items():
        name = f"{prefix}{k}"
        out.append(name)
        if f.kind in ("table", "tables") and f.fields:
            out += known_fields(f.fields, name + ".")
        elif f.kind == "map" and f.item is not None and f.item.fields:
            out += known_fields(f.item.fields, name + ".NAME.")
    return out


def schema_markdown() -> str:
    """The table of every scenario field (docs/scenario.md holds it; a test keeps them equal).

    Returns
    -------
    str
        A Markdown table (field, kind, allowed values, meaning with units), one row per field,
        ending with a newline.
    """
    rows = ["| field | kind | allowed | meaning |", "|---|---|---|---|"]

    def walk(schema, prefix):
        for k, f in schema.items():
            name = f"{prefix}{k}"
            if f.kind in ("int", "float"):
                fmt = (lambda x: f"{int(x):,d}") if f.kind == "int" else (lambda x: f"{x:g}")
                allowed = f"[{fmt(f.lo)}, {fmt(f.hi)}]"
            elif f.kind == "floats":
                allowed = (f"{f.length} numbers" if f.length else "numbers") + \
                    f" in [{f.lo:g}, {f.hi:g}]"
            elif f.kind == "choice":
                allowed = ", ".join(map(str, f.choices))
            else:
                allowed = {"bool": "true, false", "str": "text", "file": "path (relative to the "
                           "scenario)", "date": "YYYY-MM-DD", "datetime": "ISO 8601",
                           "vec3": "[x, y, z]", "strs": "list of text", "table": "table",
                           "map": "table of NAME = ...", "tables": "array of tables",
                           "any": "table (checked by the model)"}[f.kind]
            kind = {"tables": "[[array]]", "map": "table", "strs": "list", "floats": "list",
                    "vec3": "list", "choice": "text", "file": "text", "date": "text",
                    "datetime": "text"}.get(f.kind, f.kind)
            if f.kind not in ("table", "map") or f.item is not None and not f.item.fields:
                rows.append(f"| `{name}` | {kind} | {allowed} | {f.doc} |".replace("|  |", "| |"))
            if f.kind in ("table", "tables") and f.fields:
                walk(f.fields, name + ".")
            elif f.kind == "map" and f.item is not None and f.item.fields:
                walk(f.item.fields, name + ".NAME.")
    walk(SCHEMA, "")
    return "\n".join(rows) + "\n"


def _unknown(field: str, value, known: list[str], source):
    """An unknown scenario field (``NAME`` in the schema's names stands for the field's own
    user-chosen part, e.g. the region's name)."""
    parts = field.split(".")

    def concrete(k):  # "regions.NAME.min" -> "regions.open.min" for field regions.open.x
        return ".".join(parts[i] if p == "NAME" and i < len(parts) else p
                        for i, p in enumerate(k.split(".")))
    return unknown_field(field, value, [concrete(k) for k in known], source, "docs/scenario.md")


def _check_value(name: str, f: Field, v, source, known: list[str]):
    """Check one value against its field (recursively for tables)."""
    def bad(allowed, fix=None):
        return ParameterError(name, v, allowed, fix or f"set {name} to a value in the allowed "
                              "range (docs/scenario.md lists every field)", source)

    k = f.kind
    if k == "any":
        return
    if k in ("int", "float"):
        rng = f"[{f.lo:g}, {f.hi:g}]" + (f" {f.doc}" if f.doc else "")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (k == "int" and
                                                                      not isinstance(v, int)):
            raise bad(f"{'an integer' if k == 'int' else 'a number'} in {rng}")
        if isinstance(v, float) and not math.isfinite(v):
            raise bad(f"a finite number in {rng}")
        if not f.lo <= v <= f.hi:
            fix = ("at most 1e9 photons per pass (about 2 minutes on 2 CPU cores); run more "
                   "days or seeds to average the noise") if name == "light.photons" else None
            raise bad(f"{'an integer' if k == 'int' else 'a number'} in {rng}", fix)
    elif k == "bool":
        if not isinstance(v, bool):
            raise bad("true or false")
    elif k in ("str", "file"):
        if not isinstance(v, str) or not v.strip():
            raise bad("a non-empty string" + (" (a path relative to the scenario)"
                                              if k == "file" else ""))
    elif k == "choice":
        if v not in f.choices:
            raise bad("one of " + ", ".join(map(str, f.choices)))
    elif k == "date":
        try:
            _dt.date.fromisoformat(str(v))
        except ValueError:
            raise bad("a date YYYY-MM-DD", 'e.g. "2026-03-01"') from None
    elif k == "datetime":
        try:
            t = str(v).strip()
            _dt.datetime.fromisoformat(t[:-1] + "+00:00" if t.endswith(("Z", "z")) else t)
        except ValueError:
            raise bad("an ISO 8601 date-time", 'e.g. "2026-04-20T10:00:00+09:00"') from None
    elif k == "vec3":
        if not (isinstance(v, list) and len(v) == 3 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in v)):
            raise bad("[x, y, z]: three finite numbers in metres")
    elif k == "floats":
        ok = isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                         and math.isfinite(x) for x in v)
        if ok and f.length is not None:
            ok = len(v) == f.length
        if ok and f.lo is not None:
            ok = all(f.lo <= x <= f.hi for x in v)
        if not ok:
            n = f" of {f.length}" if f.length is not None else ""
            raise bad(f"a list{n} numbers in [{f.lo:g}, {f.hi:g}]" + (f" ({f.doc})" if f.doc
                                                                       else ""))
    elif k == "strs":
        if not (isinstance(v, list) and v and all(isinstance(x, str) for x in v)):
            raise bad("a non-empty list of strings" + (f" ({f.doc})" if f.doc else ""))
    elif k == "table":
        if not isinstance(v, dict):
            raise bad("a table with fields " + ", ".join(f.fields), f"write {name}.FIELD = ...")
        for key, val in v.items():
            sub = f"{name}.{key}"
            if key not in f.fields:
                raise _unknown(sub, val, known, source)
            _check_value(sub, f.fields[key], val, source, known)
    elif k == "tables":
        items = [v] if isinstance(v, dict) else v
        if not isinstance(items, list) or not all(isinstance(t, dict) for t in items):
            raise bad("an array of tables ([[" + name + "]] entries)")
        for t in items:
            _check_value(name, Field("table", fields=f.fields), t, source, known)
    elif k == "map":
        if not isinstance(v, dict):
            raise bad("a table of NAME = value entries", f"write {name}.NAME = ...")
        for key, val in v.items():
            _check_value(f"{name}.{key}", f.item, val, source, known)


def field_spec(dotted: str) -> Field:
    """The schema entry of a dotted field name (user-named map keys allowed).

    Parameters
    ----------
    dotted : str
        Dotted field name, e.g. ``"light.photons"`` or ``"regions.open.min"``.

    Returns
    -------
    Field
        The field's schema entry (kind, bounds, documentation).

    Raises
    ------
    ParameterError
        For an unknown field (with the closest known names).
    """
    parts = dotted.split(".")
    node = Field("table", fields=SCHEMA)
    known = known_fields()
    for i, p in enumerate(parts):
        if node.kind in ("table", "tables") and node.fields is not None and p in node.fields:
            node = node.fields[p]
        elif node.kind == "map" and node.item is not None:
            node = node.item
        else:
            raise _unknown(".".join(parts[:i + 1]), None, known, None)
    return node


@dataclass
class Scenario:
    """A validated scenario.

    Parameters
    ----------
    path : pathlib.Path
        The scenario file; relative paths in it resolve against its folder.
    data : dict
        The TOML content, validated, with defaults.
    """

    path: Path
    data: dict

    @property
    def root(self) -> Path:
        """The folder of the scenario file: relative paths in it resolve against this."""
        return self.path.parent

    def get(self, dotted: str, default=None):
        """A value of the scenario by dotted name.

        Parameters
        ----------
        dotted : str
            Dotted field name, e.g. ``"site.latitude"``.
        default : object, optional
            What to return when the field is absent; default None.

        Returns
        -------
        object
            The value (a table comes back as a dict), or ``default``.
        """
        node = self.data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                return default
            node = node[part]
        return node

    def file(self, dotted: str) -> Path:
        """A path field resolved against the scenario's folder; it must exist.

        Parameters
        ----------
        dotted : str
            Dotted name of a ``file`` field, e.g. ``"scene.file"``.

        Returns
        -------
        pathlib.Path
            The absolute, resolved path.

        Raises
        ------
        ParameterError
            If the field is not set or the file does not exist.
        """
        value = self.get(dotted)
        if value is None:
            raise ParameterError(dotted, None, "a file path", f"set {dotted} in the scenario",
                                 str(self.path))
        p = (self.root / str(value)).resolve()
        if not p.exists():
            raise ParameterError(dotted, value, "an existing file (relative to the scenario)",
                                 f"check the path; looked for {p}", str(self.path))
        return p

    def load_scene(self, daylight: bool | None = None):
        """The Mitsuba scene of the scenario, loaded with ``optimize=False`` (shape ids kept).

        With ``light.when`` set (or ``daylight=True``) its emitters are replaced by daylight
        (sun and sky of :func:`mitsuba_veg.light.clear_sky.daylight`) for the site and time.

        Parameters
        ----------
        daylight : bool, optional
            True: replace the emitters by daylight (``light.when`` must be set); False: keep the
            scene's emitters; None (default): daylight exactly when ``light.when`` is set.

        Returns
        -------
        mi.Scene
            The loaded scene.

        Raises
        ------
        ParameterError
            If the XML does not load, ``daylight=True`` without ``light.when``, or the sun is below
            the horizon at ``light.when``.
        """
        path = self.file("scene.file")
        input_hashes(self)   # the files the run reads, as it reads them (resumes compare them)
        scene = load_scene_file(path, "scene.file", str(self.path))
        when = self.get("light.when")
        if daylight is False or (daylight is None and when is None):
            return scene
        if when is None:
            raise ParameterError("light.when", None, "an ISO date-time like "
                                 "'2026-06-21T12:00:00+09:00'", "set light.when", str(self.path))
        emitters = _daylight(self.get("site.latitude"), self.get("site.longitude"), when)
        if not emitters:
            raise ParameterError("light.when", when, "a time when the sun is above the horizon",
                                 "choose a daytime", str(self.path))
        d = {"type": "scene"}
        # every shape and sensor under its own key: objects without an id (or sharing one) get
        # a numbered key instead of overwriting each other
        for i, obj in enumerate(list(scene.shapes()) + list(scene.sensors())):
            key = obj.id() or ("camera" if isinstance(obj, mi.Sensor) else f"shape_{i}")
            if key in d:
                key = f"{key}_{i}"
            d[key] = obj
        d.update(emitters)
        return mi.load_dict(d, optimize=False)


def load_scene_file(path, field: str = "scene.file", source: str | None = None):
    """Load a Mitsuba XML scene with ``optimize=False`` (shape ids kept), after checking the
    files it references (:func:`mitsuba_veg.inputs.check_scene_files`).

    Parameters
    ----------
    path : str or pathlib.Path
        The XML file.
    field : str, optional
        The field or argument that named it, for messages (default ``"scene.file"``).
    source : str, optional
        The scenario file, for messages; default None.

    Returns
    -------
    mi.Scene
        The scene, its shape ids kept.

    Raises
    ------
    ParameterError
        Naming a referenced file that is missing, empty or truncated, or with Mitsuba's message
        for an XML that does not load.
    """
    check_scene_files(path, field, source)
    try:
        return mi.load_file(str(path), optimize=False)
    except Exception as e:  # Mitsuba's own message names the XML problem (a plugin's own
        # error without Mitsuba's traceback around it)
        raise ParameterError(field, str(path), "a Mitsuba 3 XML scene that loads",
                             f"correct the XML: {plugin_error(e)[:600]}", source) from None


def _parse_value(text: str):
    """A --set value: TOML syntax (numbers, true/false, strings, arrays), bare words as strings."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _check_key(item: str, key: str, source) -> None:
    """Refuse a ``--set`` key that is empty or has an empty name between its dots (the whole
    item is named: ``--set light..photons=5``, ``--set =1``)."""
    if not key or any(not p.strip() for p in key.split(".")):
        raise ParameterError("--set", item, "KEY=VALUE with a dotted key of non-empty names "
                             "(e.g. light.photons=2000000)", "write the field's full dotted "
                             "name before the = (docs/scenario.md lists them)", source)


#: the scenario fields ``--set`` may give with a bare Mitsuba XML scene (no scenario)
XML_SET_FIELDS = ("light.photons", "light.seed", "light.max_depth", "light.indirect")


def light_overrides(overrides, source: str = "--set") -> dict:
    """The light settings of ``--set`` items given with a bare XML scene (no scenario).

    Every key is checked like a scenario's (unknown fields refused with the closest names, values
    against their range); fields other than :data:`XML_SET_FIELDS` need a scenario and are
    refused.

    Parameters
    ----------
    overrides : iterable of str
        ``"KEY=VALUE"`` items.
    source : str, optional
        Where they come from, for messages; default ``"--set"``.

    Returns
    -------
    dict
        ``{"photons": ..., "seed": ..., "max_depth": ..., "indirect": ...}`` (those given).

    Raises
    ------
    ParameterError
        For a malformed item, an unknown field, a value out of range or a field that needs a
        scenario.
    """
    out = {}
    known = known_fields()
    for item in overrides or ():
        if "=" not in item:
            raise ParameterError(source, item, "KEY=VALUE with a dotted key",
                                 "e.g. --set light.photons=2000000")
        key, text = (x.strip() for x in item.split("=", 1))
        _check_key(item, key, source)
        f = field_spec(key) if key in XML_SET_FIELDS else None
        if f is None:
            try:
                field_spec(key)
            except ParameterError as e:
                raise ParameterError(e.field, _parse_value(text), e.allowed, e.fix,
                                     source) from None
            raise ParameterError(key, _parse_value(text), "with an XML scene only "
                                 + ", ".join(XML_SET_FIELDS), "pass a scenario TOML as SCENE "
                                 "to set other fields", source)
        value = _parse_value(text)
        _check_value(key, f, value, source, known)
        out[key.split(".", 1)[1]] = value
    return out


def apply_overrides(data: dict, overrides, source: str = "--set") -> dict:
    """Apply ``KEY=VALUE`` overrides with dotted keys (``light.photons=2000000``).

    Values are parsed as TOML (numbers, true/false, strings, arrays); bare words stay strings.
    Missing tables on the way are created. The result is not validated (see :func:`validate`).

    Parameters
    ----------
    data : dict
        Scenario content (not modified: a deep copy is changed).
    overrides : iterable of str, optional
        ``"KEY=VALUE"`` items; None or empty: no change.
    source : str, optional
        Where the overrides come from, for error messages; default ``"--set"``.

    Returns
    -------
    dict
        A copy of ``data`` with the overrides applied.

    Raises
    ------
    ParameterError
        If an item has no ``=`` or its key goes through a value or an array of tables.
    """
    data = copy.deepcopy(data)
    for item in overrides or ():
        if "=" not in item:
            raise ParameterError(source, item, "KEY=VALUE with a dotted key",
                                 "e.g. --set light.photons=2000000")
        key, text = item.split("=", 1)
        _check_key(item, key.strip(), source)
        parts = key.strip().split(".")
        node = data
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ParameterError(key.strip(), text.strip(), "a field inside a table (not "
                                     "inside an array or a value)", "edit array entries such "
                                     "as [[render.trees]] in the file itself", source)
        node[parts[-1]] = _parse_value(text.strip())
    return data


def validate(data: dict, source: str) -> dict:
    """Check every field of ``data`` against :data:`SCHEMA` and fill in the defaults.

    Unknown fields are refused (with the closest known names). Defaults: ``light`` photons
    1e6, max_depth 8, seed 0, indirect true; ``site`` latitude 35, longitude 139 [degrees].
    Also checks that regions have shapes, min and max, that ``moss.priority`` has one entry per
    species and that ``moss.initial <= moss.capacity``.

    Parameters
    ----------
    data : dict
        Scenario content (TOML tables); filled in place.
    source : str
        The scenario file, for error messages.

    Returns
    -------
    dict
        ``data`` itself, with the defaults filled in.

    Raises
    ------
    ParameterError
        For a missing ``scene.file``, an unknown field or a value out of its range.
    """
    known = known_fields()
    if "scene" not in data or not isinstance(data.get("scene"), dict) or \
            "file" not in data["scene"]:
        raise ParameterError("scene.file", None, "a Mitsuba XML file path",
                             "add [scene] file = \"scene.xml\"", source)
    for key, val in data.items():
        if key not in SCHEMA:
            raise _unknown(key, val, known, source)
        _check_value(key, SCHEMA[key], val, source, known)
    for sec, vals in _DEFAULTS.items():
        data.setdefault(sec, {})
        for k, v in vals.items():
            data[sec].setdefault(k, v)
    for name, reg in data.get("regions", {}).items():
        for k in ("shapes", "min", "max"):
            if k not in reg:
                raise ParameterError(f"regions.{name}.{k}", None, "present",
                                     "a region needs shapes, min and max", source)
        bad = [a for a, lo, hi in zip("xyz", reg["min"], reg["max"]) if lo > hi]
        if bad:
            raise ParameterError(f"regions.{name}.min", reg["min"], f"<= regions.{name}.max "
                                 f"{reg['max']} in x, y and z (not in {', '.join(bad)}: the "
                                 "box would be empty)", "min is the lower corner and max the "
                                 "upper one: swap the values that are the wrong way round",
                                 source)
    moss = data.get("moss", {})
    species = moss.get("species")
    if isinstance(species, list):
        twice = sorted({k for k in species if species.count(k) > 1})
        if twice:
            raise ParameterError("moss.species", species, f"each species once ({twice[0]} is "
                                 "listed more than once)", "remove the repeated entry", source)
    if moss.get("priority") is not None:
        n = len(moss.get("species", ("bryum_argenteum", "hypnum_plumaeforme", "polytrichum")))
        if len(moss["priority"]) != n:
            raise ParameterError("moss.priority", moss["priority"],
                                 f"one number per species ({n} values)",
                                 "give as many priorities as moss.species has entries", source)
    if "initial" in moss and "capacity" in moss and moss["initial"] > moss["capacity"]:
        raise ParameterError("moss.initial", moss["initial"], f"<= moss.capacity "
                             f"({moss['capacity']})", "no more initial moss than the capacity",
                             source)
    for sec in ("light", "render"):      # a time without a UTC offset is the site's local time
        if isinstance(data.get(sec), dict) and data[sec].get("when") is not None:
            data[sec]["when"] = site_time(data[sec]["when"], data["site"])
    return data


def site_offset_hours(site: dict) -> float:
    """The site's offset from UTC [h]: ``site.timezone``, else its longitude / 15 rounded (the
    render's rule).

    Parameters
    ----------
    site : dict
        The scenario's ``[site]`` (``timezone`` [h], ``longitude`` [deg]).

    Returns
    -------
    float
        Hours east of UTC.
    """
    tz = site.get("timezone")
    return float(tz) if tz is not None else float(round(float(site.get("longitude", 0.0)) / 15.0))


def site_time(when, site: dict) -> str:
    """An ISO 8601 date-time with its UTC offset: a time without one is local time at the site
    (:func:`site_offset_hours`); a time with one is kept.

    Parameters
    ----------
    when : str or datetime.datetime
        The date-time (``Z`` for UTC allowed).
    site : dict
        The scenario's ``[site]``.

    Returns
    -------
    str
        The date-time with an offset, e.g. ``2026-06-21T10:00:00+09:00``.
    """
    t = str(when).strip() if not isinstance(when, _dt.datetime) else when.isoformat()
    v = _dt.datetime.fromisoformat(t[:-1] + "+00:00" if t.endswith(("Z", "z")) else t)
    if v.tzinfo is not None:
        return t
    tz = _dt.timezone(_dt.timedelta(hours=site_offset_hours(site)))
    return v.replace(tzinfo=tz).isoformat()


def load_scenario(path, overrides=None) -> Scenario:
    """Read, override (``["light.photons=2e6", ...]``) and validate a scenario file.

    Parameters
    ----------
    path : str or pathlib.Path
        The scenario TOML file.
    overrides : iterable of str, optional
        ``"KEY=VALUE"`` items with dotted keys (the CLI's ``--set``); default None.

    Returns
    -------
    Scenario
        The validated scenario with defaults.

    Raises
    ------
    ParameterError
        If the file is missing, not a file, unreadable or not valid TOML, an override names an
        unknown field, or a value is invalid.
    """
    path = Path(path)
    if not path.exists():
        raise ParameterError("scenario", str(path), "an existing TOML file",
                             "check the path (e.g. scenes/moss_garden/scenario.toml)")
    if not path.is_file():
        raise ParameterError("scenario", str(path), "a TOML file (not a folder)",
                             "pass the scenario file, e.g. scenes/moss_garden/scenario.toml")
    try:
        # utf-8-sig: a byte-order mark (some editors write one) is not part of the TOML
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ParameterError("scenario", str(path), "a valid TOML text file",
                             f"fix the syntax: {e}") from None
    except OSError as e:
        raise ParameterError("scenario", str(path), "a readable file", e.strerror) from None
    for item in overrides or ():
        key = str(item).split("=", 1)[0].strip()
        if "=" in str(item):
            _check_key(str(item), key, f"{path} (--set)")
            try:
                field_spec(key)
            except ParameterError as e:
                raise ParameterError(e.field, _parse_value(str(item).split("=", 1)[1].strip()),
                                     e.allowed, e.fix, f"{path} (--set)") from None
    data = apply_overrides(data, overrides, source=f"{path} (--set)")
    return Scenario(path, validate(data, str(path)))
