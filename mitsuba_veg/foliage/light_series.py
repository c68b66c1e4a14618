"""Sensor light studies over time: ``mitsuba-veg light-study SCENARIO --year`` (or ``--from
DATE --to DATE --step hourly|daily``).

:func:`run_sensor_study` reads the scenario's ``[[sensors]]`` through clear-sky daylight of its
site (:func:`mitsuba_veg.light.sensor_study.run_series`) and writes into the output folder:

- ``sensors.csv``, ``sensors.parquet``: the tidy table, one row per time step × sensor × band
  × component: ``time`` (step start, local time with UTC offset), ``sensor``, ``band`` (par,
  red, far_red, rfr, shortwave), ``component`` (direct, diffuse, total), ``value`` (mean over
  the step), ``unit``;
- ``sensors_hourly.csv``, ``sensors_hourly.parquet``: the same for the hourly passes of the
  hour × day heat map (daily steps with ``heatmap_every`` > 0), point sensors only (and the
  plotted sensor);
- ``dli.csv``: per day and sensor the daily light integral of PAR [mol m-2 d-1] (total, direct,
  diffuse), the open-sky DLI and, on days with hourly values, the hours with PPFD above the
  threshold;
- ``summary.json``: settings, site, timings, per-sensor means (DLI, R:FR, hours above the
  threshold) and the open-sky reference;
- figures: ``dli_map.png`` and ``rfr_map.png`` (mean DLI and R:FR of the first grid),
  ``sensor_year.png`` (daily DLI and R:FR of one sensor with the open-sky DLI) and
  ``heatmap.png`` (PPFD of that sensor, hour × day).
"""
from __future__ import annotations

import datetime as _dt
import time
from pathlib import Path

import numpy as np

from mitsuba_veg.atomic import atomic_write
from mitsuba_veg.errors import ParameterError, check_range
from mitsuba_veg.light import sensor_study as SS
from mitsuba_veg.light import sensors as S
from mitsuba_veg.outputs import OutputFolder, write_json
from mitsuba_veg.plots import _mpl
from mitsuba_veg.defaults import check_light
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.backend import versions

__all__ = ["FILES", "SERIES_PHOTONS", "run_sensor_study", "year_figure", "heatmap_figure",
           "grid_map_figure"]

#: the files a sensor study writes
FILES = ("sensors.csv", "sensors.parquet", "sensors_hourly.csv", "sensors_hourly.parquet",
         "dli.csv", "summary.json", "dli_map.png", "rfr_map.png", "sensor_year.png",
         "heatmap.png")
#: default photons per sun pass of a time series
SERIES_PHOTONS = 500_000


def _date(field, text):
    try:
        return text if isinstance(text, _dt.date) else _dt.date.fromisoformat(str(text))
    except ValueError:
        raise ParameterError(field, text, "a date YYYY-MM-DD", "e.g. 2026-06-21") from None


def _write_table(series_or_readings, stem: Path, keep=None, time=None) -> dict:
    """``stem``.csv and ``stem``.parquet (the tidy table), atomically: a
    :class:`~mitsuba_veg.light.sensor_study.SensorSeries` (rows ``keep``) or a
    :class:`~mitsuba_veg.light.sensors.SensorReadings` at ``time``."""
    x = series_or_readings
    rows = np.arange(len(x.sensors)) if keep is None else np.arange(len(x.sensors))[keep]
    if hasattr(x, "times"):
        values, times, df = x.values[:, rows], x.iso_times(), x.table(rows)
    else:
        values = x.values[None, rows]
        times = None if time is None else [str(time)]
        df = S.tidy_table(values, x.sensors.names[rows], times)
    out = {"csv": S.write_tidy_csv(stem.with_suffix(".csv"), values, x.sensors.names[rows],
                                   times)}
    with atomic_write(stem.with_suffix(".parquet"), stem.with_suffix(".tmp.parquet")) as tmp:
        df.to_parquet(tmp, index=False)
    out["parquet"] = str(stem.with_suffix(".parquet"))
    return out


def run_sensor_study(scenario, out_dir, *, start=None, end=None, year=None,
                     step: str = "daily", photons: int = SERIES_PHOTONS,
                     sky_photons: int | None = None, seed: int | None = None,
                     max_depth: int | None = None, indirect: bool | None = None,
                     heatmap_every: int = 7, par_threshold: float = 200.0,
                     sensor: str | None = None, overrides=(), progress: bool = False,
                     segments=None, scenario_obj=None) -> dict:
    """Sensor time series of a scenario and its files (module docstring). Returns the summary.

    Parameters
    ----------
    scenario : str or Path
        Scenario TOML with ``[[sensors]]`` and ``[site]`` (with ``[[trees]]`` or a ``[stand]``
        only together with ``segments``).
    out_dir : str or Path
        Output folder (a ``light-study`` folder).
    start, end : date or str, optional
        First and last local day (ISO ``YYYY-MM-DD``); or
    year : int, optional
        A whole calendar year.
    step : str
        ``"daily"`` or ``"hourly"``.
    photons : int
        Photons per sun pass (one pass per step with the sun up).
    sky_photons : int, optional
        Photons of the one sky pass (default 10 x photons).
    seed, max_depth, indirect : optional
        Random seed (int), most bounces of a photon path (int) and whether scattered light is
        traced (bool). Default: the scenario's ``[light]``.
    heatmap_every : int
        Daily steps: also trace hourly passes every this many days (0: none) for the
        hour × day heat map and the hours above ``par_threshold``.
    par_threshold : float
        PPFD threshold [µmol m-2 s-1] of the hours-above count.
    sensor : str, optional
        Sensor of the year plot and heat map (default: the first point sensor, else the first).
    overrides : sequence of str
        ``--set`` overrides of the scenario.
    progress : bool
        Progress bars.
    segments : callable, optional
        A world's light scenes over the period: ``segments(start, end)`` returns
        ``[(first day, last day, scene)]`` covering the days in order, each scene holding the
        scene's shapes and the trees as they stand with their leaves on those days
        (:func:`mitsuba_veg.canopy_photo.world_light.run_world_sensor_study` makes them);
        each segment is traced with its own scene (its own sky pass).
    scenario_obj : Scenario, optional
        The loaded scenario (a run's own), instead of loading ``scenario``.

    Returns
    -------
    dict
        The summary written to ``summary.json``: settings, site, period, per-sensor means (DLI
        [mol m-2 d-1], R:FR [-], hours above the threshold [h d-1]), the open-sky DLI, passes,
        timings [s] and the files written.

    Raises
    ------
    ParameterError
        When the scenario is not a ``.toml`` with ``[[sensors]]`` (and, without ``segments``,
        without ``[[trees]]``), the period is missing, reversed or given twice, or a setting is
        out of range.
    """

    t0 = time.perf_counter()
    p = Path(scenario)
    if scenario_obj is None and p.suffix.lower() != ".toml":
        raise ParameterError("SCENE", str(p), "a scenario .toml with [[sensors]] for a time "
                             "series", "write a scenario (docs/sensors.md)")
    check_light("photons", photons)
    check_range("heatmap_every", heatmap_every, 0, 366, fix="days between hourly heat-map "
                "days, 0 for none")
    check_range("par_threshold", par_threshold, 0.0, 5000.0, fix="PPFD in µmol m-2 s-1")
    if step not in ("daily", "hourly"):
        raise ParameterError("--step", step, "daily or hourly")
    if year is not None:
        check_range("--year", year, 1, 9999)
        if start is not None or end is not None:
            raise ParameterError("--year", year, "either --year or --from/--to",
                                 "give one of them")
        start, end = _dt.date(int(year), 1, 1), _dt.date(int(year), 12, 31)
    if start is None or end is None:
        raise ParameterError("--from/--to", (start, end), "both dates, or --year",
                             "e.g. --from 2026-06-01 --to 2026-06-30")
    start, end = _date("--from", start), _date("--to", end)
    SS.step_starts(start, end, step)            # refuses a reversed or too long period first
    scn = scenario_obj if scenario_obj is not None else load_scenario(p, overrides)
    if (scn.get("trees") or scn.get("stand")) and segments is None:
        # the scene file's shapes alone would leave the trees out
        raise ParameterError("trees", f"{len(scn.get('trees') or [])} [[trees]] entries"
                             + (" and a [stand]" if scn.get("stand") else ""),
                             "a scenario without [[trees]] here, or the world's scenes of the "
                             "period (segments)", "use `mitsuba-veg light-study` (it runs the "
                             "world's trees to their leaf state on each date) or "
                             "mitsuba_veg.canopy_photo.run_world_sensor_study", str(p))
    scene = scn.load_scene(daylight=False)
    sensors = S.from_scenario(scn, scene)
    if sensors is None:
        raise ParameterError("sensors", None, "at least one [[sensors]] entry in the scenario",
                             "add e.g. [[sensors]] name = \"open\" position = [0, 0.5, 0] "
                             "(docs/sensors.md)", str(p))
    light = scn.get("light")
    seed = int(light["seed"] if seed is None else seed)
    max_depth = int(light["max_depth"] if max_depth is None else max_depth)
    indirect = bool(light["indirect"] if indirect is None else indirect)
    lat, lon = float(scn.get("site.latitude")), float(scn.get("site.longitude"))
    tz = scn.get("site.timezone")
    focus = _focus_sensor(sensors, sensor)

    folder = OutputFolder(out_dir, "light-study")
    out = folder.path
    folder.clear(FILES)
    kw = dict(latitude=lat, longitude=lon, timezone=tz, photons=int(photons),
              sky_photons=sky_photons, seed=seed, max_depth=max_depth, indirect=indirect,
              progress=progress)
    segs = [(start, end, scene)] if segments is None else list(segments(start, end))
    series, cache = _trace_segments(segs, sensors, step, kw)
    hourly = None
    if step == "hourly":
        hourly = series
    elif heatmap_every > 0:
        hourly = _hourly_days(segs, cache, sensors, start, end, heatmap_every, kw)
    files = {}
    files["sensors"] = _write_table(series, out / "sensors")
    if hourly is not None and hourly is not series:
        # point sensors (and the plotted one): grids' hourly rows would be most of the data
        keep = sensors.ij[:, 0] < 0
        keep[focus] = True
        files["sensors_hourly"] = _write_table(hourly, out / "sensors_hourly", keep)
    days, dli, odli = SS.daily_light_integral(series)
    hdays, hrs = (SS.hours_above(hourly, par_threshold) if hourly is not None
                  else (np.array([], "datetime64[D]"), np.zeros((0, len(sensors)))))
    files["dli"] = _write_dli(out / "dli.csv", days, dli, odli, sensors, hdays, hrs)
    # figures
    files["sensor_year"] = year_figure(series, days, dli, odli, focus, out / "sensor_year.png")
    if hourly is not None:
        files["heatmap"] = heatmap_figure(hourly, focus, out / "heatmap.png")
    grid = next((g for g in sensors.groups
                 if (sensors.ij[sensors.group == g] >= 0).all()), None)
    mean_dli = dli[..., 2].mean(axis=0)
    red, fr = (series.values[:, :, S.QUANTITIES.index(q), 2].sum(axis=0)
               for q in ("red", "far_red"))
    with np.errstate(divide="ignore", invalid="ignore"):
        mean_rfr = np.where(fr > 0, red / fr, np.nan)
    if grid is not None:
        m = sensors.group == grid
        files["dli_map"] = grid_map_figure(
            sensors, m, mean_dli, out / "dli_map.png", f"mean daily light integral, grid "
            f"'{grid}' ({start} to {end})", "DLI [mol m$^{-2}$ d$^{-1}$]", "viridis", vmin=0.0)
        fin = mean_rfr[m][np.isfinite(mean_rfr[m])]
        rng = f", {fin.min():.3f}-{fin.max():.3f}" if fin.size else ""
        files["rfr_map"] = grid_map_figure(
            sensors, m, mean_rfr, out / "rfr_map.png", f"red : far-red photon ratio, grid "
            f"'{grid}' ({start} to {end}{rng})", "R:FR [-]", "RdYlGn", vmin=0.0,
            vmax=max(1.3, float(np.nanmax(mean_rfr[m])) if np.isfinite(mean_rfr[m]).any()
                     else 1.3))
    per = {}
    hours_mean = hrs.mean(axis=0) if len(hrs) else np.full(len(sensors), np.nan)
    for i, name in enumerate(sensors.names[:1000]):   # summary of at most 1000 sensors
        per[str(name)] = {"kind": S.KINDS[sensors.kind[i]],
                          "dli_mean": float(mean_dli[i]), "dli_min": float(dli[:, i, 2].min()),
                          "dli_max": float(dli[:, i, 2].max()),
                          "dli_direct_mean": float(dli[:, i, 0].mean()),
                          "dli_diffuse_mean": float(dli[:, i, 1].mean()),
                          "par_mol_m2_total": float(dli[:, i, 2].sum()),
                          "rfr": None if not np.isfinite(mean_rfr[i]) else float(mean_rfr[i]),
                          "hours_above_threshold_per_day": None if not len(hrs)
                          else float(hours_mean[i])}
    summary = {
        "command": "light-study", "mode": "sensor time series", "scenario": str(p),
        "site": {"latitude": lat, "longitude": lon, "timezone_h": series.timezone},
        "period": {"from": start.isoformat(), "to": end.isoformat(), "days": int(len(days)),
                   "step": step, "steps": int(len(series.times)),
                   "heatmap_days": int(len(hdays)) if hourly is not series else int(len(days))},
        "settings": {k: v for k, v in series.settings.items()
                     if k not in ("sky_readings", "light_scene")},
        "sky_passes": len(segs),
        "par_threshold_umol_m2_s": float(par_threshold),
        "sensors": {"count": int(len(sensors)), "groups": sensors.groups,
                    "focus": str(sensors.names[focus])},
        "open_sky": {"dli_mean": float(odli[:, 2].mean()), "dli_min": float(odli[:, 2].min()),
                     "dli_max": float(odli[:, 2].max())},
        "per_sensor": per,
        "passes": {"sun": int(series.sun_passes + (hourly.sun_passes if hourly is not None
                                                   and hourly is not series else 0)),
                   "sky": len(segs)},
        "world": None if segments is None else {
            "segments": [{"from": a.isoformat(), "to": b.isoformat()} for a, b, _ in segs]},
        "timings_s": {"series": series.seconds,
                      "hourly": hourly.seconds if hourly is not None and hourly is not series
                      else 0.0, "total": time.perf_counter() - t0},
        "units": {"value": "mean over the step; see the unit column", "dli": "mol m-2 d-1"},
        "files": files, "versions": versions()}
    write_json(out / "summary.json", summary)
    folder.release()
    return summary


def _focus_sensor(sensors, name) -> int:
    if name is not None:
        return sensors.index(name)
    pts = np.flatnonzero(sensors.ij[:, 0] < 0)
    return int(pts[0]) if len(pts) else 0


def _join(parts):
    """One series of consecutive parts (same sensors)."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    return SS.SensorSeries(first.sensors, np.concatenate([x.times for x in parts]),
                           first.step_hours, first.timezone,
                           np.concatenate([x.values for x in parts]),
                           np.concatenate([x.open_values for x in parts]),
                           sum(x.sun_passes for x in parts), first.photons,
                           sum(x.seconds for x in parts), first.settings)


def _trace_segments(segs, sensors, step, kw):
    """Each segment's days with its own scene (one sky pass each), joined; and per segment
    the light scene and sky readings that later passes of its days reuse."""
    parts, cache = [], []
    for a, b, scene in segs:
        part = SS.run_series(scene, sensors, start=a, end=b, step=step, **kw)
        parts.append(part)
        cache.append(dict(sky_readings=part.settings["sky_readings"],
                          light_scene=part.settings["light_scene"]))
    return _join(parts), cache


def _hourly_days(segs, cache, sensors, start, end, every, kw):
    """Hourly passes on every ``every``-th day of the period (one series per day, joined),
    each in the scene of its segment."""
    days = [start + _dt.timedelta(days=k) for k in range(0, (end - start).days + 1, every)]
    parts = []
    kw = dict(kw)
    progress = kw.pop("progress")
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=len(days), unit="day", desc="hourly heat-map days")
    for d in days:
        k = next(i for i, (a, b, _) in enumerate(segs) if a <= d <= b)
        parts.append(SS.run_series(segs[k][2], sensors, start=d, end=d, step="hourly",
                                   progress=False, **kw, **cache[k]))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return _join(parts)


def _write_dli(path, days, dli, odli, sensors, hdays, hrs) -> str:
    import pandas as pd
    nd, ns = dli.shape[:2]
    hours = np.full((nd, ns), np.nan)
    if len(hdays):
        pos = np.searchsorted(days, hdays)
        ok = (pos < nd) & (days[np.minimum(pos, nd - 1)] == hdays)
        hours[pos[ok]] = hrs[ok]
    df = pd.DataFrame({
        "date": np.repeat(days.astype(str), ns),
        "sensor": np.tile(sensors.names, nd),
        "dli_mol_m2_d": dli[..., 2].ravel(), "dli_direct_mol_m2_d": dli[..., 0].ravel(),
        "dli_diffuse_mol_m2_d": dli[..., 1].ravel(),
        "open_dli_mol_m2_d": np.repeat(odli[:, 2], ns),
        "hours_above_threshold": hours.ravel()})
    with atomic_write(path, str(path) + ".tmp") as tmp:
        df.to_csv(tmp, index=False, float_format="%.6g")
    return str(path)


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
def _save(fig, path):
    with atomic_write(path, f"{path}.tmp.png") as tmp:
        fig.savefig(tmp, dpi=90)
    _mpl().close(fig)
    return str(path)


def year_figure(series, days, dli, odli, i, path) -> str:
    """Daily DLI (total, direct, diffuse, open sky) and daily R:FR of sensor ``i``.

    Parameters
    ----------
    series : SensorSeries
        The time series (:func:`mitsuba_veg.light.sensor_study.run_series`).
    days : numpy.ndarray
        (days,) local days (datetime64[D]).
    dli : numpy.ndarray
        (days, sensors, 3) daily light integral of PAR [mol m-2 d-1]: direct, diffuse, total.
    odli : numpy.ndarray
        (days, 3) open-sky (horizontal) DLI [mol m-2 d-1], same components.
    i : int
        Index of the sensor plotted.
    path : pathlib.Path
        PNG file to write (atomically).

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    x = days.astype("datetime64[D]").astype(object)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, constrained_layout=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    a1.plot(x, odli[:, 2], color="0.6", lw=1.2, ls="--", label="open sky (horizontal)")
    a1.plot(x, dli[:, i, 2], color="tab:green", lw=1.5, label="total")
    a1.plot(x, dli[:, i, 0], color="tab:orange", lw=1.0, label="direct (sun beam)")
    a1.plot(x, dli[:, i, 1], color="tab:blue", lw=1.0, label="diffuse (sky + scattered)")
    a1.set_ylabel("DLI [mol m$^{-2}$ d$^{-1}$]")
    a1.set_ylim(bottom=0)
    a1.legend(fontsize=8, loc="upper right")
    name = series.sensors.names[i]
    a1.set_title(f"sensor '{name}' ({S.KINDS[series.sensors.kind[i]]}): daily light integral "
                 f"of PAR, clear sky", fontsize=10)
    day = series.times.astype("datetime64[D]")
    red = series.values[:, i, S.QUANTITIES.index("red"), 2]
    fr = series.values[:, i, S.QUANTITIES.index("far_red"), 2]
    _, inv = np.unique(day, return_inverse=True)
    rs, fs = np.zeros(len(days)), np.zeros(len(days))
    np.add.at(rs, inv, red)
    np.add.at(fs, inv, fr)
    with np.errstate(divide="ignore", invalid="ignore"):
        a2.plot(x, np.where(fs > 0, rs / fs, np.nan), color="tab:red", lw=1.2)
    a2.set_ylabel("R:FR [-] (daily)")
    a2.set_xlabel("date (local)")
    return _save(fig, path)


def heatmap_figure(hourly, i, path) -> str:
    """PPFD of sensor ``i``: hour of the day × day.

    Parameters
    ----------
    hourly : SensorSeries
        An hourly series (hour means of the PPFD [µmol m-2 s-1]).
    i : int
        Index of the sensor plotted.
    path : pathlib.Path
        PNG file to write (atomically).

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    day = hourly.times.astype("datetime64[D]")
    days, inv = np.unique(day, return_inverse=True)
    hour = ((hourly.times - day).astype("timedelta64[h]").astype(int))
    grid = np.full((24, len(days)), np.nan)
    grid[hour, inv] = hourly.values[:, i, S.QUANTITIES.index("par"), 2]
    fig, ax = plt.subplots(figsize=(10, 4.2), constrained_layout=True)
    import matplotlib.dates as mdates
    x = mdates.date2num(days.astype(object))
    if len(x) > 1:
        w = np.diff(x).min()
        edges = np.concatenate([x - w / 2, [x[-1] + w / 2]]) if np.allclose(np.diff(x), w) \
            else np.concatenate([[x[0] - 0.5], (x[1:] + x[:-1]) / 2, [x[-1] + 0.5]])
    else:
        edges = np.array([x[0] - 0.5, x[0] + 0.5])
    pc = ax.pcolormesh(edges, np.arange(25), grid, cmap="magma", vmin=0.0, shading="flat")
    ax.xaxis_date()
    ax.set_ylabel(f"hour (local, UTC{hourly.timezone:+g})")
    ax.set_yticks(range(0, 25, 3))
    ax.set_xlabel("date")
    cb = fig.colorbar(pc, ax=ax)
    cb.set_label("PPFD [µmol m$^{-2}$ s$^{-1}$] (hour mean)")
    ax.set_title(f"sensor '{hourly.sensors.names[i]}': PAR by hour and day "
                 f"({len(days)} days with hourly passes)", fontsize=10)
    return _save(fig, path)


def grid_map_figure(sensors, mask, values, path, title, label, cmap, vmin=None,
                    vmax=None) -> str:
    """One grid's values as a map.

    Plan view (x east, north up) for grids facing up or down, else an elevation view along the
    grid.

    Parameters
    ----------
    sensors : Sensors
        The scenario's sensors (grid cells carry their (i, j) in ``ij``).
    mask : numpy.ndarray
        (n_sensors,) bool: the cells of the grid to draw.
    values : array_like
        (n_sensors,) value per sensor (e.g. DLI [mol m-2 d-1] or R:FR [-]).
    path : pathlib.Path
        PNG file to write (atomically).
    title : str
        Figure title.
    label : str
        Colour-bar label (with the unit).
    cmap : str
        Matplotlib colour map.
    vmin, vmax : float, optional
        Colour-scale limits (in the unit of ``values``; default: the data's range).

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    idx = np.flatnonzero(mask)
    ij, pos, v = sensors.ij[idx], sensors.position[idx], np.asarray(values, float)[idx]
    ni, nj = ij[:, 0].max() + 1, ij[:, 1].max() + 1
    img = np.full((nj, ni), np.nan)
    img[ij[:, 1], ij[:, 0]] = v
    up = abs(float(np.mean(sensors.normal[idx, 1]))) > 0.7
    if up:     # plan view: i along x (east), j along z (south), north up
        ca, cb = pos[:, 0], -pos[:, 2]
        labels = ("x (east) [m]", "-z (north) [m]")
    else:      # elevation view: distance along the grid's first axis, height
        e = pos - pos[np.argmin(ij[:, 0] + ij[:, 1])]
        ca, cb = np.hypot(e[:, 0], e[:, 2]), pos[:, 1]
        labels = ("distance along the grid [m]", "y (up) [m]")
    # cell edges from each column's / row's mean coordinate (ground grids may be ragged)
    def edges(c, k, n):
        m = np.bincount(k, c, n) / np.maximum(np.bincount(k, None, n), 1)
        d = np.diff(m)
        step = float(np.median(d)) if len(d) else float(sensors.size[idx].max())
        return np.concatenate([[m[0] - step / 2], m[:-1] + d / 2, [m[-1] + step / 2]])
    ea, eb = edges(ca, ij[:, 0], ni), edges(cb, ij[:, 1], nj)
    fig, ax = plt.subplots(figsize=(7.5, 6.2), constrained_layout=True)
    pc = ax.pcolormesh(ea, eb, np.ma.masked_invalid(img), cmap=cmap, vmin=vmin, vmax=vmax,
                       shading="flat")
    ax.set_aspect("equal")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title(title, fontsize=10)
    cbar = fig.colorbar(pc, ax=ax, shrink=0.85)
    cbar.set_label(label)
    return _save(fig, path)
