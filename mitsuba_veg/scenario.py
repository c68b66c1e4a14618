"""Scenario files (TOML): load, validate at the boundary, apply ``--set`` overrides, build scenes.

A scenario names a Mitsuba scene file and the settings of a run. Every value is checked when the
file is read; a bad one raises :class:`~mitsuba_veg.errors.ParameterError` naming the file, the
field (dotted name), the value, the allowed range and the fix.

Sections used so far (paths relative to the scenario file):

``[scene] file``            Mitsuba XML scene; loaded with ``optimize=False`` to keep shape ids.
``[site] latitude, longitude``  [deg] north/east positive.
``[light]``                 photons, max_depth, seed, indirect, and optionally ``when`` (ISO
                            date-time): then the scene's own emitters are replaced by a physical
                            daylight sun + sky (:func:`mitsuba_veg.light.daylight`).
``[terrain]``               ground (shape id), geology_texture, soil_base_y [m],
                            ``[terrain.soil_depth_mm]`` per-shape soil depth.
``[regions.NAME]``          shapes, min, max: boxes [m] naming parts of the terrain.
"""
from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass
from pathlib import Path

from .errors import ParameterError, SceneError, check_range

#: field -> (type, lower, upper) for the numeric fields checked here
_NUMERIC = {
    "site.latitude": (float, -90.0, 90.0),
    "site.longitude": (float, -180.0, 180.0),
    "light.photons": (int, 1, 10**10),
    "light.max_depth": (int, 1, 1000),
    "light.seed": (int, 0, 2**31 - 1),
}
_DEFAULTS = {
    "light": {"photons": 1_000_000, "max_depth": 8, "seed": 0, "indirect": True},
    "site": {"latitude": 35.0, "longitude": 139.0},
}


@dataclass
class Scenario:
    """A validated scenario: ``data`` is the TOML content with defaults, ``path`` its file."""

    path: Path
    data: dict

    @property
    def root(self) -> Path:
        return self.path.parent

    def get(self, dotted: str, default=None):
        node = self.data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                return default
            node = node[part]
        return node

    def file(self, dotted: str) -> Path:
        """A path field resolved against the scenario's folder; it must exist."""
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
        """The Mitsuba scene; with ``light.when`` set (or ``daylight=True``) its emitters are
        replaced by daylight for the site and time."""
        import mitsuba as mi

        path = self.file("scene.file")
        try:
            scene = mi.load_file(str(path), optimize=False)
        except Exception as e:  # Mitsuba's own message names the XML problem
            raise SceneError(f"{self.path}: scene.file = {path.name}: Mitsuba could not load it: "
                             f"{e}") from None
        when = self.get("light.when")
        if daylight is False or (daylight is None and when is None):
            return scene
        if when is None:
            raise ParameterError("light.when", None, "an ISO date-time like "
                                 "'2026-06-21T12:00:00+09:00'", "set light.when", str(self.path))
        from .light.daylight import daylight as _daylight
        emitters = _daylight(self.get("site.latitude"), self.get("site.longitude"), when)
        if not emitters:
            raise ParameterError("light.when", when, "a time when the sun is above the horizon",
                                 "choose a daytime", str(self.path))
        d = {"type": "scene"}
        for sh in scene.shapes():
            d[sh.id()] = sh
        for sensor in scene.sensors():
            d[sensor.id() or "camera"] = sensor
        d.update(emitters)
        return mi.load_dict(d, optimize=False)


def _parse_value(text: str):
    """A --set value: TOML syntax (numbers, true/false, strings, arrays), bare words as strings."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(data: dict, overrides, source: str = "--set") -> dict:
    """Apply ``KEY=VALUE`` overrides with dotted keys (``light.photons=2000000``)."""
    data = copy.deepcopy(data)
    for item in overrides or ():
        if "=" not in item:
            raise ParameterError(source, item, "KEY=VALUE with a dotted key",
                                 "e.g. --set light.photons=2000000")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        node = data
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ParameterError(source, key, "a key inside a table", None)
        node[parts[-1]] = _parse_value(text.strip())
    return data


def validate(data: dict, source: str) -> dict:
    for sec, vals in _DEFAULTS.items():
        data.setdefault(sec, {})
        for k, v in vals.items():
            data[sec].setdefault(k, v)
    if "scene" not in data or "file" not in data.get("scene", {}):
        raise ParameterError("scene.file", None, "a Mitsuba XML file path",
                             "add [scene] file = \"scene.xml\"", source)
    for key, (typ, lo, hi) in _NUMERIC.items():
        sec, name = key.split(".")
        v = data[sec].get(name)
        if isinstance(v, bool) or (typ is int and not isinstance(v, int)) or \
                (typ is float and not isinstance(v, (int, float))):
            raise ParameterError(key, v, f"{'an integer' if typ is int else 'a number'} in "
                                 f"[{lo}, {hi}]", None, source)
        check_range(key, v, lo, hi, source=source)
    if not isinstance(data["light"]["indirect"], bool):
        raise ParameterError("light.indirect", data["light"]["indirect"], "true or false", None,
                             source)
    for name, reg in data.get("regions", {}).items():
        for k in ("shapes", "min", "max"):
            if k not in reg:
                raise ParameterError(f"regions.{name}.{k}", None, "present",
                                     "a region needs shapes, min and max", source)
        for k in ("min", "max"):
            v = reg[k]
            if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float))
                                                                for x in v)):
                raise ParameterError(f"regions.{name}.{k}", v, "[x, y, z] in metres", None, source)
    return data


def load_scenario(path, overrides=None) -> Scenario:
    """Read, override (``["light.photons=2e6", ...]``) and validate a scenario file."""
    path = Path(path)
    if not path.exists():
        raise ParameterError("scenario", str(path), "an existing TOML file",
                             "check the path (e.g. scenes/moss_garden/scenario.toml)")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ParameterError("scenario", str(path), "valid TOML", str(e)) from None
    data = apply_overrides(data, overrides, source=f"{path} (--set)")
    return Scenario(path, validate(data, str(path)))
