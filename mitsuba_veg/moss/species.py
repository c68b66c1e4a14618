"""Moss species parameters of paper 000 (table 3.7 meanings, table 4.2 values).

The three species of the paper ship in ``mitsuba_veg/data/moss_species.toml`` and are loaded into
:data:`SPECIES` (keys ``"bryum_argenteum"``, ``"hypnum_plumaeforme"``, ``"polytrichum"``). Users
define their own with ``Species(...)`` or a TOML file of the same layout and
:func:`load_species`. Every value is validated at construction; a bad one raises
:class:`~mitsuba_veg.errors.ParameterError` naming the field, the value, the allowed range and
the fix.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

try:  # Python >= 3.11
    import tomllib as _toml
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as _toml  # type: ignore[no-redef]

from ..errors import ParameterError, check_range

__all__ = ["Species", "SPECIES", "load_species", "get_species", "SPECIES_FILE", "PARAMETER_FIELDS"]

#: Numeric fields of a species, in the order of table 4.2.
PARAMETER_FIELDS = ("T0", "T1", "nT", "rh0", "rh1", "nrh", "S0", "S1", "nS",
                    "alpha_g", "tau_g", "tau_b", "tau_d")
_TEXT_FIELDS = ("name", "name_ja")

_T_MIN = 150.0  # [K]: a lower bound that catches temperatures given in degrees Celsius


def _number(v):
    """A float for validation; width-1 Dr.Jit arrays (tuning) are read back."""
    try:
        import drjit as dr
        if dr.is_array_v(v):
            if dr.width(v) != 1:
                return v  # let check_range report it
            return float(v[0])
    except ImportError:  # pragma: no cover
        pass
    return v


@dataclass(frozen=True)
class Species:
    """Growth parameters of one moss species (paper 000, table 3.7; values of table 4.2).

    T0 < T1 temperature range [K]; rh0 < rh1 surface-humidity range [-]; S0 < S1 daily-mean
    insolation range [W m-2]; nT, nrh, nS tolerances of eq 3.19 in (0, 1]; alpha_g growth
    coefficient, tau_g growth threshold (eq 3.20), tau_b germination threshold (eq 3.24),
    tau_d death threshold on G_moss (eq 3.21), all in (0, 1). ``name``/``name_ja`` are labels.
    """
    T0: float
    T1: float
    nT: float
    rh0: float
    rh1: float
    nrh: float
    S0: float
    S1: float
    nS: float
    alpha_g: float
    tau_g: float
    tau_b: float
    tau_d: float
    name: str = "custom"
    name_ja: str = ""
    source: str | None = dataclasses.field(default=None, compare=False, repr=False)

    def __post_init__(self):
        src = self.source or f"species {self.name!r}"
        v = {f: _number(getattr(self, f)) for f in PARAMETER_FIELDS}
        for f in PARAMETER_FIELDS:
            check_range(f, v[f], source=src,
                        fix=f"give {f} as a finite number (table 3.7)")
        check_range("T0", v["T0"], _T_MIN, source=src,
                    fix="temperatures are in kelvin (degrees Celsius + 273.15)")
        check_range("rh0", v["rh0"], 0.0, source=src, fix="relative humidity is a fraction >= 0")
        check_range("S0", v["S0"], 0.0, source=src, fix="insolation is >= 0 W m-2")
        for lo, hi, what in (("T0", "T1", "temperature"), ("rh0", "rh1", "humidity"),
                             ("S0", "S1", "insolation")):
            if not v[lo] < v[hi]:
                raise ParameterError(lo, v[lo], f"< {hi} = {v[hi]!r} ({lo} < {hi}, table 3.7)",
                                     f"the {what} range needs {lo} < {hi}; swap them?", src)
        for f in ("nT", "nrh", "nS"):
            check_range(f, v[f], 0.0, 1.0, lo_open=True, source=src,
                        fix=f"the tolerance {f} of eq 3.19 must satisfy 0 < {f} <= 1 (table 3.7)")
        for f in ("alpha_g", "tau_g", "tau_b", "tau_d"):
            check_range(f, v[f], 0.0, 1.0, lo_open=True, hi_open=True, source=src,
                        fix=f"{f} must satisfy 0 < {f} < 1 (table 3.7)")

    @property
    def ranges(self) -> dict[str, tuple[float, float, float]]:
        """``{"T": (T0, T1, nT), "rh": (rh0, rh1, nrh), "S": (S0, S1, nS)}``."""
        return {"T": (self.T0, self.T1, self.nT), "rh": (self.rh0, self.rh1, self.nrh),
                "S": (self.S0, self.S1, self.nS)}

    def replace(self, **changes) -> "Species":
        """A copy with some fields changed (validated again).

        Parameters
        ----------
        **changes : float or str
            New values of fields, by name (``T0=280.0`` [K], ``S1=120.0`` [W m-2], ``name="x"`` ...;
            units as in the class docstring).

        Returns
        -------
        Species
            The changed copy.

        Raises
        ------
        ParameterError
            If a changed value fails validation.
        """
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The fields as a plain dict (the TOML layout of one species).

        Returns
        -------
        dict
            ``{field: value}`` for the 13 numeric fields (units as in the class docstring) and
            ``"name"``, plus ``"name_ja"`` when it is set.
        """
        d = {f: getattr(self, f) for f in PARAMETER_FIELDS}
        d["name"] = self.name
        if self.name_ja:
            d["name_ja"] = self.name_ja
        return d


def _species_from_table(key: str, table: Mapping[str, Any], source: str) -> Species:
    where = f"{source} [species.{key}]"
    if not isinstance(table, Mapping):
        raise ParameterError(f"species.{key}", table, "a table of species parameters",
                             "write [species.<key>] followed by the fields", source)
    allowed = set(PARAMETER_FIELDS) | set(_TEXT_FIELDS)
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ParameterError(unknown[0], table[unknown[0]], "one of " + ", ".join(PARAMETER_FIELDS + _TEXT_FIELDS),
                             "remove or rename the field", where)
    missing = [f for f in PARAMETER_FIELDS if f not in table]
    if missing:
        raise ParameterError(missing[0], None, "a number (required)",
                             f"add the missing field(s) {', '.join(missing)}", where)
    kw: dict[str, Any] = {}
    for f in PARAMETER_FIELDS:
        val = table[f]
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise ParameterError(f, val, "a number", "write the value as a number", where)
        kw[f] = float(val)
    return Species(**kw, name=str(table.get("name", key)), name_ja=str(table.get("name_ja", "")),
                   source=where)


def load_species(path) -> dict[str, Species]:
    """Load species from a TOML file with one ``[species.<key>]`` table per species.

    Parameters
    ----------
    path : str or pathlib.Path
        The TOML file (layout of ``mitsuba_veg/data/moss_species.toml``).

    Returns
    -------
    dict
        ``{key: Species}``, one entry per ``[species.<key>]`` table.

    Raises
    ------
    ParameterError
        On a missing file, TOML syntax errors and unknown, missing or invalid fields, naming the
        file, the species and the field.
    """
    p = Path(path)
    try:
        # utf-8-sig: a byte-order mark (some editors write one) is not part of the TOML
        data = _toml.loads(p.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise ParameterError("path", str(p), "an existing TOML file", "check the file name") from None
    except (_toml.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError("toml", str(exc), "valid TOML", "fix the syntax", str(p)) from None
    return _species_from_mapping(data, str(p))


def _species_from_mapping(data: Mapping[str, Any], source: str) -> dict[str, Species]:
    table = data.get("species")
    if not isinstance(table, Mapping) or not table:
        raise ParameterError("species", table, "at least one [species.<key>] table",
                             "add e.g. [species.my_moss] with the fields of table 4.2", source)
    return {str(k): _species_from_table(str(k), v, source) for k, v in table.items()}


#: Path of the shipped table (paper 000, table 4.2).
SPECIES_FILE = Path(__file__).resolve().parent.parent / "data" / "moss_species.toml"


def _load_builtin() -> dict[str, Species]:
    return load_species(SPECIES_FILE)


#: The paper's species (table 4.2): "bryum_argenteum", "hypnum_plumaeforme", "polytrichum".
SPECIES: dict[str, Species] = _load_builtin()


def get_species(species) -> Species:
    """A :class:`Species` from an instance or a key of :data:`SPECIES`.

    Parameters
    ----------
    species : Species or str
        A species, returned as it is, or a key of :data:`SPECIES` (e.g. ``"bryum_argenteum"``).

    Returns
    -------
    Species
        The species.

    Raises
    ------
    ParameterError
        If ``species`` is not a key of :data:`SPECIES`.
    """
    if isinstance(species, Species):
        return species
    try:
        return SPECIES[str(species)]
    except KeyError:
        raise ParameterError("species", species, "one of " + ", ".join(SPECIES),
                             "use a built-in key or pass a Species(...)") from None
