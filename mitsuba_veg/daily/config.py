"""The settings of a moss run, read and checked from its scenario: days and start date, the
[moss] fields, the species, the light settings and the daily weather."""
from __future__ import annotations

import datetime as _dt

from ..climate import ClimateTable, daily_weather, load_csv
from ..errors import ParameterError, check_range
from ..moss.species import SPECIES, Species, load_species
from ..scenario import Scenario
from ..trees.entries import check_render_trees
from ..world.phenology import PhenologyParams

__all__ = ["BANDS", "MOSS_DEFAULTS", "SIM_DEFAULTS", "MossConfig"]

#: the bands of the daily photon pass
BANDS = ("total", "par", "red", "far_red")
_PCG_STREAM = 0xDA3E39CB94B95BDB  # Dr.Jit's default PCG32 stream (lane i adds i)

#: [moss] defaults (scenario fields, documented in docs/moss.md)
MOSS_DEFAULTS = {
    "species": ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"],
    "capacity": 16384,          # slots (paper: at most 16384 moss)
    "initial": 200,             # moss placed at random on the surfaces at the start
    "initial_growth": 1.0,      # their G_moss (established moss)
    "size": 0.01,               # [m] moss size = cell of the spot grid (paper: 1 cm)
    "gemma_distance": 0.02,     # k of eq 3.22 [m]
    "spore_distance": 0.25,     # l of eq 3.23 [m]
    "external_spore_interval": 5,   # days between spores arriving from outside (0 = none)
    "clump_neighbours": 8,      # occupied neighbour cells that make a moss "inside a clump"
    "albedo": [0.10, 0.07, 0.05, 0.45],   # moss reflectance per band (total, par, red, far-red)
    "priority": None,           # species priority for occupancy conflicts (default all 0)
    "shapes": None,             # shapes moss may live on (default: all meshes)
}
#: defaults of ``[simulation]`` (days, start date, checkpoint and map intervals, ...)
SIM_DEFAULTS = {"days": 300, "start_date": "2026-03-01", "checkpoint_every": 10,
                "frame_every": 10, "light_every": 1}


class MossConfig:
    """The settings of a moss run (``scenario`` checked field by field).

    Parameters
    ----------
    scenario : Scenario
        The loaded scenario.
    days : int, optional
        Simulated days [d] (default: the scenario's ``simulation.days``).

    Attributes
    ----------
    days : int
        Simulated days [d].
    start : datetime.date
        The date of day 0.
    light_every : int
        Days between photon passes (``simulation.light_every``; 1: every day).
    moss_cfg, light_cfg : dict
        The scenario's [moss] (with defaults) and light settings; ``seed`` the light seed.
    species : list of Species
        The run's species, in the order of ``moss.species``.
    weather : climate.DailyWeather
        One row per day; ``climate`` the climate table it came from.
    phenology : PhenologyParams
        The world's leaf phenology (``[phenology]``); ``stage_bins`` its autumn-stage bins.
    """

    def __init__(self, scenario: Scenario, days: int | None = None):
        self.scn = scenario
        src = str(scenario.path)
        sim = {**SIM_DEFAULTS, **scenario.get("simulation", {})}
        self.days = int(days if days is not None else sim["days"])
        check_range("simulation.days", self.days, 1, 100_000, source=src)
        try:
            self.start = _dt.date.fromisoformat(str(sim["start_date"]))
        except ValueError:
            raise ParameterError("simulation.start_date", sim["start_date"], "YYYY-MM-DD",
                                 None, src) from None
        self.checkpoint_every = int(sim["checkpoint_every"])
        self.frame_every = int(sim["frame_every"])
        self.light_every = int(sim["light_every"])
        check_range("simulation.light_every", self.light_every, 1, 365, source=src,
                    fix="1 traces the light every day; e.g. 3 every third day")
        m = {**MOSS_DEFAULTS, **scenario.get("moss", {})}
        self.moss_cfg = m
        check_range("moss.capacity", m["capacity"], 16, 50_000_000, source=src)
        check_range("moss.initial", m["initial"], 0, m["capacity"], source=src,
                    fix="no more initial moss than the capacity")
        check_range("moss.size", m["size"], 1e-4, 1.0, source=src, fix="moss size in metres")
        check_range("moss.gemma_distance", m["gemma_distance"], 0.0, 100.0, source=src)
        check_range("moss.spore_distance", m["spore_distance"], 0.0, 100.0, source=src)
        check_range("moss.external_spore_interval", m["external_spore_interval"], 0, 100_000,
                    source=src)
        check_range("moss.clump_neighbours", m["clump_neighbours"], 1, 26, source=src)
        if len(m["albedo"]) != len(BANDS) or any(not (0 <= a <= 1) for a in m["albedo"]):
            raise ParameterError("moss.albedo", m["albedo"], f"{len(BANDS)} values in [0, 1] "
                                 f"(bands {', '.join(BANDS)})", None, src)
        self.species = self._species(m, src)
        self.light_cfg = {"photons": scenario.get("light.photons"),
                          "max_depth": scenario.get("light.max_depth"),
                          "indirect": scenario.get("light.indirect"),
                          "seed": scenario.get("light.seed")}
        self.seed = int(self.light_cfg["seed"])
        self._setup_climate(src)
        self._setup_phenology(src)
        check_render_trees(scenario.get("render.trees"), src)  # refused now, not by the render

    def _setup_phenology(self, src):
        """The world's ``[phenology]`` (leaf-out, autumn, leaf fall) and its stage bins."""
        ph = dict(self.scn.get("phenology", {}) or {})
        self.stage_bins = int(ph.pop("stage_bins", 4))
        try:
            self.phenology = PhenologyParams(**ph).validate(src)
        except ParameterError as e:
            if e.source:
                raise
            raise ParameterError(f"phenology.{e.field}", e.value, e.allowed, e.fix,
                                 src) from None


    def date(self, day: int) -> _dt.date:
        """The calendar date of simulated day ``day`` (0-based).

        Parameters
        ----------
        day : int
            Day number, counted from the start date (day 0) [d].

        Returns
        -------
        datetime.date
            ``start + day`` days.
        """
        return self.start + _dt.timedelta(days=day)

    def grid_cell(self) -> float:
        """The cell of the spot grid, one moss [m].

        Returns
        -------
        float
            Side of a grid cell = the moss size ``moss.size`` [m] (default 0.01 m).
        """
        return float(self.moss_cfg["size"])

    def _species(self, m, src) -> list[Species]:
        known = dict(SPECIES)
        custom = self.scn.get("species_file")
        if custom:
            known.update(load_species(self.scn.file("species_file")))
        out = []
        names = m["species"]
        if isinstance(names, str) or not names:
            raise ParameterError("moss.species", names, "a non-empty list of species keys", None,
                                 src)
        for k in names:
            if k not in known:
                raise ParameterError("moss.species", k, "one of " + ", ".join(sorted(known)),
                                     "use a built-in species or add it in a species_file", src)
            out.append(known[k])
        return out

    def _setup_climate(self, src):
        c = self.scn.get("climate", {}) or {}
        allowed = {"temperature", "humidity", "precipitation", "rain_days", "wind",
                   "possible_sunshine", "sunshine", "angstrom_a", "angstrom_b", "csv"}
        for k in c:
            if k not in allowed:
                raise ParameterError(f"climate.{k}", c[k], "one of " + ", ".join(sorted(allowed)),
                                     "remove or rename the field", src)
        table = ClimateTable(**{k: v for k, v in c.items() if k != "csv"}, source=src)
        lat = float(self.scn.get("site.latitude"))
        if c.get("csv"):
            w = load_csv(self.scn.file("climate.csv"), lat, table,
                         start_day=min(self.start.timetuple().tm_yday, 365))
            if len(w) < self.days:
                raise ParameterError("climate.csv", f"{len(w)} rows", f">= {self.days} rows "
                                     "(one per simulated day)", "add rows or run fewer days", src)
        else:
            w = daily_weather(table, lat, self.days, seed=self.seed,
                              start_day=self.start.timetuple().tm_yday)
        self.weather = w
        self.climate = table
