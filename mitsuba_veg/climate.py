"""Daily weather from a climate table (paper 000 table 4.3) or a per-day CSV series.

Paper 000 drives its soil model with daily means (table 3.3): air temperature T [K], relative
humidity rh [-], precipitation P [mm/day], wind speed U [m/s], possible sunshine hours N0 [h] and
sunshine hours N [h]. Its table 4.3 gives one set of yearly values used for every experiment:
T 288.15 K, rh 0.73, 1861.2 mm/yr over 180 rain days, U 0.2 m/s, N0 8 h, N 6 h.

The paper gives no absolute scale for the insolation S. We use a physical one: the daily global
horizontal irradiation H [J m-2 day-1] from the Angstrom-Prescott relation (FAO-56 eq 35)

    H = H0 (a_s + b_s N/N0),   a_s = 0.25, b_s = 0.50,

with H0 the extraterrestrial irradiation for the latitude and day of year (FAO-56 eq 21), split
into beam and diffuse with the daily diffuse-fraction correlation of Erbs, Klein & Duffie (1982)
in the clearness index K_T = H/H0. The photon pass then gives each triangle its fraction of the
unobstructed horizontal beam and diffuse irradiance, and

    S_tri = B f_sun,tri + D f_sky,tri      [W m-2, daily mean over 24 h]

(see docs/moss.md). Rain: the yearly precipitation falls in equal amounts on ``rain_days`` days
per year chosen reproducibly from the seed.
"""
from __future__ import annotations

import csv
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ParameterError, check_range

__all__ = ["GSC", "SECONDS_PER_DAY", "ClimateTable", "DailyWeather", "solar_declination",
           "extraterrestrial_irradiation", "sunset_hour_angle", "diffuse_fraction_daily",
           "rain_schedule", "daily_weather", "load_csv"]

#: solar constant [W m-2] (Kopp & Lean 2011; FAO-56 uses 1367)
GSC = 1361.0
#: seconds in a day [s]
SECONDS_PER_DAY = 86400.0


@dataclass
class ClimateTable:
    """Yearly climate of paper 000 table 4.3 (defaults) with validation.

    Every value is range-checked on construction (:class:`~mitsuba_veg.errors.ParameterError`
    naming ``source``).

    Attributes
    ----------
    temperature : float
        Air temperature T [K]; default 288.15, allowed [200, 340].
    humidity : float
        Relative humidity rh [-]; default 0.73, allowed [0, 1].
    precipitation : float
        Yearly precipitation [mm yr-1]; default 1861.2.
    rain_days : int
        Rain days per year [days yr-1]; default 180, allowed [0, 365].
    wind : float
        Wind speed U [m s-1]; default 0.2, allowed (0, 60].
    possible_sunshine : float
        Possible sunshine hours N0 [h]; default 8, allowed (0, 24].
    sunshine : float
        Sunshine hours N [h]; default 6, at most ``possible_sunshine``.
    angstrom_a, angstrom_b : float
        Angstrom-Prescott coefficients a_s, b_s [-]; defaults 0.25, 0.50.
    source : str
        Where the values come from, for error messages; default ``"climate"``.
    """

    temperature: float = 288.15      # T [K]
    humidity: float = 0.73           # rh [-]
    precipitation: float = 1861.2    # [mm/yr]
    rain_days: int = 180             # [days/yr]
    wind: float = 0.2                # U [m/s]
    possible_sunshine: float = 8.0   # N0 [h]
    sunshine: float = 6.0            # N [h]
    angstrom_a: float = 0.25         # a_s [-]
    angstrom_b: float = 0.50         # b_s [-]
    source: str = "climate"

    def __post_init__(self):
        src = self.source
        check_range("climate.temperature", self.temperature, 200.0, 340.0, source=src,
                    fix="air temperature in kelvin, e.g. 288.15")
        check_range("climate.humidity", self.humidity, 0.0, 1.0, source=src,
                    fix="relative humidity as a fraction, e.g. 0.73")
        check_range("climate.precipitation", self.precipitation, 0.0, 20000.0, source=src)
        check_range("climate.rain_days", self.rain_days, 0, 365, source=src)
        check_range("climate.wind", self.wind, 0.0, 60.0, lo_open=True, source=src,
                    fix="mean wind speed in m/s (> 0: the bulk transfer needs wind)")
        check_range("climate.possible_sunshine", self.possible_sunshine, 0.0, 24.0,
                    lo_open=True, source=src)
        check_range("climate.sunshine", self.sunshine, 0.0, self.possible_sunshine, source=src,
                    fix="sunshine hours cannot exceed the possible sunshine hours")


@dataclass
class DailyWeather:
    """Weather of every simulated day (arrays of length n_days).

    Attributes
    ----------
    day_of_year : numpy.ndarray
        Day of the year [1..365].
    T : numpy.ndarray
        Daily-mean air temperature [K].
    rh : numpy.ndarray
        Relative humidity [-].
    P : numpy.ndarray
        Precipitation [mm day-1].
    U : numpy.ndarray
        Wind speed [m s-1].
    A : numpy.ndarray
        Sunshine ratio N/N0 [-].
    ghi : numpy.ndarray
        Daily-mean global horizontal irradiance [W m-2].
    beam : numpy.ndarray
        Daily-mean beam irradiance on the horizontal [W m-2].
    diffuse : numpy.ndarray
        Daily-mean diffuse horizontal irradiance [W m-2].
    extra : dict
        ``H0_J_m2`` (extraterrestrial irradiation [J m-2 day-1]) and ``clearness`` (K_T [-]).
    """

    day_of_year: np.ndarray   # [1..365]
    T: np.ndarray             # [K]
    rh: np.ndarray            # [-]
    P: np.ndarray             # [mm/day]
    U: np.ndarray             # [m/s]
    A: np.ndarray             # N/N0 [-]
    ghi: np.ndarray           # daily-mean global horizontal irradiance [W m-2]
    beam: np.ndarray          # daily-mean beam on the horizontal [W m-2]
    diffuse: np.ndarray       # daily-mean diffuse horizontal [W m-2]
    extra: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.T)

    def day(self, i: int) -> dict:
        """The weather of one simulated day as plain floats.

        Parameters
        ----------
        i : int
            Index of the simulated day (0-based, not the day of year).

        Returns
        -------
        dict
            ``day_of_year`` [1..365], ``T`` [K], ``rh`` [-], ``P`` [mm day-1], ``U`` [m s-1],
            ``A`` = N/N0 [-], ``ghi``, ``beam``, ``diffuse`` (daily means on the horizontal
            [W m-2]), all as float.
        """
        return {k: float(getattr(self, k)[i]) for k in
                ("day_of_year", "T", "rh", "P", "U", "A", "ghi", "beam", "diffuse")}


def solar_declination(day_of_year):
    """Solar declination delta [rad] of a day (FAO-56 eq 24): ``0.409 sin(2 pi J / 365 - 1.39)``.

    The daily declination of every day-of-year formula in the package (H0, the sunset hour
    angle, the world's noon sun); the hourly sun positions come from NREL SPA
    (:mod:`mitsuba_veg.light.solar_position`).

    Parameters
    ----------
    day_of_year : int or array_like
        Day of the year J [1..366].

    Returns
    -------
    numpy.ndarray
        Declination delta [rad], in [-0.409, 0.409].
    """
    return 0.409 * np.sin(2 * np.pi / 365 * np.asarray(day_of_year, float) - 1.39)


def extraterrestrial_irradiation(latitude_deg, day_of_year):
    """Daily extraterrestrial irradiation on a horizontal plane H0 [J m-2 day-1] (FAO-56 eqs 21-25).

    ``H0 = 86400/pi Gsc dr (ws sin(phi) sin(delta) + cos(phi) cos(delta) sin(ws))`` with
    Gsc = ``GSC`` = 1361 W m-2 (FAO-56 uses 1367).

    Parameters
    ----------
    latitude_deg : float or array_like
        Latitude phi [degrees], north positive.
    day_of_year : int or array_like
        Day of the year J [1..365].

    Returns
    -------
    numpy.ndarray
        H0 [J m-2 day-1] (broadcast shape of the inputs; 0 in polar night).
    """
    phi = np.radians(np.asarray(latitude_deg, float))
    J = np.asarray(day_of_year, float)
    dr = 1 + 0.033 * np.cos(2 * np.pi / 365 * J)
    delta = solar_declination(J)
    ws = np.arccos(np.clip(-np.tan(phi) * np.tan(delta), -1.0, 1.0))
    return SECONDS_PER_DAY / np.pi * GSC * dr * (
        ws * np.sin(phi) * np.sin(delta) + np.cos(phi) * np.cos(delta) * np.sin(ws))


def sunset_hour_angle(latitude_deg, day_of_year):
    """Sunset hour angle ws [rad] (FAO-56 eq 25).

    Parameters
    ----------
    latitude_deg : float or array_like
        Latitude [degrees], north positive.
    day_of_year : int or array_like
        Day of the year [1..365].

    Returns
    -------
    numpy.ndarray
        Sunset hour angle ws [rad], in [0, pi] (0: polar night, pi: midnight sun).
    """
    phi = np.radians(np.asarray(latitude_deg, float))
    delta = solar_declination(day_of_year)
    return np.arccos(np.clip(-np.tan(phi) * np.tan(delta), -1.0, 1.0))


def diffuse_fraction_daily(kt, ws=None):
    """Daily diffuse fraction Hd/H from the clearness index K_T (Erbs, Klein & Duffie 1982).

    For ws <= 81.4 deg: 1.391 - 3.560 K + 4.189 K^2 - 2.137 K^3 (K < 0.715), else 0.175;
    for ws > 81.4 deg: 1.311 - 3.022 K + 3.427 K^2 - 1.821 K^3 (K < 0.722), else 0.175.
    The result is clipped to [0, 1].

    Parameters
    ----------
    kt : float or array_like
        Daily clearness index K_T = H/H0 [-].
    ws : float or array_like, optional
        Sunset hour angle [rad] (compared with 81.4 degrees); None (default) uses the
        ws <= 81.4 deg branch everywhere.

    Returns
    -------
    numpy.ndarray
        Diffuse fraction Hd/H [-], in [0, 1].
    """
    k = np.asarray(kt, float)
    low = np.ones_like(k, bool) if ws is None else np.asarray(ws) <= np.radians(81.4)
    f1 = np.where(k < 0.715, 1.391 - 3.560 * k + 4.189 * k**2 - 2.137 * k**3, 0.175)
    f2 = np.where(k < 0.722, 1.311 - 3.022 * k + 3.427 * k**2 - 1.821 * k**3, 0.175)
    return np.clip(np.where(low, f1, f2), 0.0, 1.0)


def rain_schedule(n_days: int, rain_days_per_year: int, seed: int, start_day: int = 1):
    """Boolean per simulated day: is it a rain day?

    Each calendar year (of 365 days) gets exactly ``rain_days_per_year`` rain days at positions
    drawn from ``seed`` (reproducible).

    Parameters
    ----------
    n_days : int
        Number of simulated days.
    rain_days_per_year : int
        Rain days per calendar year [days yr-1] (at most 365 are used).
    seed : int
        Seed of the draw.
    start_day : int, optional
        Day of year of the first simulated day [1..365]; default 1.

    Returns
    -------
    numpy.ndarray of bool
        Shape ``(n_days,)``, True on rain days.
    """
    out = np.zeros(n_days, bool)
    day0 = start_day - 1
    years = (day0 + n_days + 364) // 365
    for y in range(years):  # one draw per calendar year (a handful), not per day
        rng = np.random.default_rng([seed, 7919, y])
        doy = rng.choice(365, size=min(rain_days_per_year, 365), replace=False)
        idx = y * 365 + doy - day0
        idx = idx[(idx >= 0) & (idx < n_days)]
        out[idx] = True
    return out


def daily_weather(table: ClimateTable, latitude: float, n_days: int, seed: int = 0,
                  start_day: int = 1) -> DailyWeather:
    """Weather for ``n_days`` days starting on day-of-year ``start_day`` from a yearly table.

    Every day has the table's T, rh, U and A = N/N0; the yearly precipitation falls in equal
    amounts on the rain days of :func:`rain_schedule`; the insolation is Angstrom-Prescott
    (FAO-56 eq 35) split into beam and diffuse (Erbs et al. 1982).

    Parameters
    ----------
    table : ClimateTable
        Yearly climate (paper 000 table 4.3 by default).
    latitude : float
        Site latitude [degrees], in [-90, 90].
    n_days : int
        Number of days to simulate, in [1, 100000].
    seed : int, optional
        Seed of the rain-day draw; default 0.
    start_day : int, optional
        Day of year of the first day [1..365]; default 1.

    Returns
    -------
    DailyWeather
        Arrays of length ``n_days`` (T [K], rh [-], P [mm day-1], U [m s-1], A [-], ghi / beam /
        diffuse [W m-2] daily means; ``extra`` holds ``H0_J_m2`` [J m-2 day-1] and ``clearness``
        [-]).

    Raises
    ------
    ParameterError
        If ``latitude`` or ``n_days`` is out of range.
    """
    check_range("site.latitude", latitude, -90.0, 90.0)
    check_range("days", n_days, 1, 100_000)
    doy = (np.arange(n_days) + start_day - 1) % 365 + 1
    rain = rain_schedule(n_days, table.rain_days, seed, start_day)
    per_rain_day = table.precipitation / table.rain_days if table.rain_days else 0.0
    A = table.sunshine / table.possible_sunshine
    return _radiation(doy, np.full(n_days, table.temperature), np.full(n_days, table.humidity),
                      np.where(rain, per_rain_day, 0.0), np.full(n_days, table.wind),
                      np.full(n_days, A), latitude, table.angstrom_a, table.angstrom_b)


def _radiation(doy, T, rh, P, U, A, latitude, a_s=0.25, b_s=0.5, ghi=None) -> DailyWeather:
    H0 = extraterrestrial_irradiation(latitude, doy)
    if ghi is None:
        H = H0 * (a_s + b_s * A)
        ghi = H / SECONDS_PER_DAY
    else:
        H = np.asarray(ghi, float) * SECONDS_PER_DAY
    kt = np.where(H0 > 0, H / np.maximum(H0, 1e-9), 0.0)
    fd = diffuse_fraction_daily(kt, sunset_hour_angle(latitude, doy))
    diffuse = ghi * fd
    return DailyWeather(doy, T, rh, P, U, A, ghi, ghi - diffuse, diffuse,
                        {"H0_J_m2": H0, "clearness": kt})


_CSV_FIELDS = {"T": (200.0, 340.0), "rh": (0.0, 1.0), "P": (0.0, 2000.0), "U": (0.0, 60.0),
               "A": (0.0, 1.0), "ghi": (0.0, 600.0), "day_of_year": (1, 366)}


def load_csv(path, latitude: float, table: ClimateTable | None = None,
             start_day: int = 1) -> DailyWeather:
    """Per-day weather from a CSV with a header.

    Columns (any order): ``P`` [mm] (required: rain drives the soil water, and a table's monthly
    total cannot be placed on the CSV's days), ``T`` [K], ``rh`` [-], ``U`` [m/s], and either
    ``A`` (= N/N0) or ``N`` and ``N0`` [h]; optional ``ghi`` [W m-2, daily mean] (else
    Angstrom-Prescott) and ``day_of_year`` (else ``start_day``, ``start_day`` + 1, ...). Missing
    T, rh, U, A take the table's values. Every value is checked; a bad cell names the file, row
    and column.

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file (UTF-8, one row per day).
    latitude : float
        Site latitude [degrees] (for H0 and the beam/diffuse split).
    table : ClimateTable, optional
        Values for missing columns; default ``ClimateTable()`` (paper 000 table 4.3).
    start_day : int
        Day of the year (1-365) of the first row when there is no ``day_of_year`` column
        (default 1; the daily loop passes its ``simulation.start_date``).

    Returns
    -------
    DailyWeather
        One entry per CSV row (T [K], rh [-], P [mm day-1], U [m s-1], A [-], ghi / beam /
        diffuse [W m-2] daily means).

    Raises
    ------
    ParameterError
        If the file is missing, unreadable or empty, a column is unknown or repeated, the
        ``P`` column is missing, a row has more or fewer cells than the header, a cell is not a
        number in its range, a ``day_of_year`` is not a whole number, or N > N0 / N0 <= 0.
    """
    table = table or ClimateTable()
    path = Path(path)
    if not path.exists():
        raise ParameterError("climate.csv", str(path), "an existing CSV file", "check the path")
    try:
        with path.open(newline="", encoding="utf-8") as f:
            table_rows = [r for r in csv.reader(f) if r]   # empty lines only
    except (UnicodeDecodeError, csv.Error, OSError) as e:
        raise ParameterError("climate.csv", str(path), "a UTF-8 text CSV file with a header",
                             f"it cannot be read as CSV ({type(e).__name__}); export it as "
                             "CSV") from None
    if len(table_rows) < 2:
        raise ParameterError("climate.csv", str(path), "a CSV with a header and >= 1 row")
    header = [c.strip() for c in table_rows[0]]
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise ParameterError(f"{path.name} columns", ", ".join(header), "each column once "
                             f"({twice[0] or 'an unnamed column'} appears "
                             f"{header.count(twice[0])} times)", "remove or rename the "
                             "repeated column", str(path))
    for i, r in enumerate(table_rows[1:]):
        if len(r) != len(header):
            raise ParameterError(f"{path.name} row {i + 2}", ",".join(r), f"{len(header)} "
                                 f"cells, one per column ({', '.join(header)}; it has "
                                 f"{len(r)})", "remove the extra cells or fill the missing "
                                 "ones", str(path))
    rows = [dict(zip(header, r)) for r in table_rows[1:]]
    cols = {c: c for c in header}
    known = set(_CSV_FIELDS) | {"N", "N0"}
    unknown = [c for c in cols if c not in known]
    if unknown:
        close = difflib.get_close_matches(unknown[0], sorted(known), n=2, cutoff=0.4)
        raise ParameterError(f"{path.name} column", unknown[0], "one of " +
                             ", ".join(sorted(known)), ("did you mean " + " or ".join(
                                 f"`{c}`" for c in close) + "?") if close else
                             "rename or remove the column", str(path))
    if "P" not in cols:
        raise ParameterError(f"{path.name} columns", ", ".join(cols), "a P column",
                             "add a column P with the day's precipitation [mm] (0 on dry days)",
                             str(path))
    check_range("start_day", start_day, 1, 365)
    n = len(rows)

    def column(name, default):
        if name not in cols:
            return np.full(n, default, float)
        vals = np.empty(n)
        lo, hi = _CSV_FIELDS.get(name, (-np.inf, np.inf))
        for i, r in enumerate(rows):
            txt = (r[cols[name]] or "").strip()
            try:
                v = float(txt)
            except ValueError:
                v = math.nan
            if not (lo <= v <= hi):
                raise ParameterError(f"{path.name} row {i + 2} column {name}", txt,
                                     f"a number in [{lo}, {hi}]", "fix or fill the cell",
                                     str(path))
            vals[i] = v
        return vals

    if "A" in cols:
        A = column("A", 0.0)
    elif "N" in cols and "N0" in cols:
        N, N0 = column("N", 0.0), column("N0", 1.0)
        if np.any(N > N0) or np.any(N0 <= 0):
            raise ParameterError(f"{path.name} columns N/N0", "N > N0 or N0 <= 0",
                                 "0 <= N <= N0, N0 > 0", None, str(path))
        A = N / N0
    else:
        A = np.full(n, table.sunshine / table.possible_sunshine)
    if "day_of_year" in cols:
        doy = column("day_of_year", 0)
        frac = np.flatnonzero(doy != np.round(doy))
        if frac.size:
            raise ParameterError(f"{path.name} row {frac[0] + 2} column day_of_year",
                                 rows[frac[0]][cols["day_of_year"]].strip(),
                                 "a whole day of the year in [1, 366]", "write the day's "
                                 "number without a fraction", str(path))
        doy = doy.astype(int)
    else:
        doy = (np.arange(n) + int(start_day) - 1) % 365 + 1
    ghi = column("ghi", 0.0) if "ghi" in cols else None
    return _radiation(doy, column("T", table.temperature), column("rh", table.humidity),
                      column("P", 0.0), column("U", table.wind), A, latitude, table.angstrom_a,
                      table.angstrom_b, ghi)
