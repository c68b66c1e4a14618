"""``mitsuba-veg hemiphoto RUN_DIR``: hemispherical photographs of a world run's floor and what
field instruments would read there, against the truth the simulation knows.

For each day (``day``, or with ``years`` the same day of the year, ``on``, in every year of the
run) the run's world of that day (:class:`~mitsuba_veg.canopy_photo.run_day.RunWorld`) is
photographed at the points (:func:`mitsuba_veg.daily.hemiphotos.take_photos`: the binary
ray-cast photograph, its gap fractions, openness, effective LAI by the LAI-2000 formula and
Miller's integral, Lang & Xiang's clumping-corrected LAI, the site factors of the year's sun
paths) beside the true LAI, WAI and PAI in the LAI-2000's view cone and, for a ``[stand]``,
the stand's LAI (``lai_plot``: the one-sided area of every shown leaf over the plot's map
area). With ``truth`` a photon
pass of the day's scene (:func:`~mitsuba_veg.canopy_photo.light_truth.light_truth`) gives the
direct and scattered shares of the open's sky and sun light at the points; beside them the
photograph's diffuse site factor for the uniform sky of the pass, the direct site factor over
the day's own sun path (``site_factor_direct_day``, the weights of the pass's
``veg_sun_path``), and the means of both over photographs spread over the pass's sensor
(``site_factor_diffuse_footprint``, ``site_factor_direct_day_footprint``: a 3 x 3 grid over
the square; a sunfleck's edge moves across a sensor of half a metre). With ``colour`` a
spectral render through the same lens is drawn beside each binary photograph.

Files in the output folder (default ``RUN_DIR/hemiphoto``): per photograph
``<point>_<date>.png`` and ``<point>_<date>.csv`` (tidy table); ``series.csv`` (one row per
photograph); ``comparison.csv`` (per day and method: the mean over the points of the field
method and of its truth, their difference and ratio) and ``comparison.png`` (the methods
against the truth as the canopy closes); ``summary.json``.
"""
from __future__ import annotations

import csv
import datetime as _dt
import io
import math
import time
from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from ..backend import versions
from ..daily.hemiphotos import (CONE_DEG, parse_on, points_at, series_row, take_photos,
                                write_photo, write_series)
from ..errors import ParameterError, check_range
from ..light.fisheye import Lens, gap_image
from ..light.gap_fraction import diffuse_site_factor, direct_site_factor
from ..light.sunpath import day_sun_path
from ..outputs import OutputFolder, write_json
from ..plots import _mpl, save_figure
from .colour import colour_photo
from .light_truth import DEFAULT_PHOTONS, DEFAULT_SIZE, light_truth
from .run_day import RunWorld

__all__ = ["run_hemiphoto", "parse_at", "plot_area", "COMPARISONS", "comparison_rows", "comparison_figure"]

#: (field method, its truth, label) of the comparison table
COMPARISONS = [("lai_lai2000", "lai_true", "LAI-2000 effective LAI vs true LAI"),
               ("lai_miller", "lai_true", "Miller effective LAI vs true LAI"),
               ("lai_lang_xiang", "lai_true", "Lang & Xiang LAI vs true LAI"),
               ("lai_lai2000", "pai_true", "LAI-2000 effective LAI vs true PAI"),
               ("lai_lai2000", "lai_plot", "LAI-2000 effective LAI vs the stand's LAI"),
               ("lai_lang_xiang", "lai_plot", "Lang & Xiang LAI vs the stand's LAI"),
               ("site_factor_diffuse", "sky_direct_share",
                "diffuse site factor vs the pass's direct sky share"),
               ("site_factor_diffuse_footprint", "sky_direct_share",
                "diffuse site factor over the sensor vs the pass's direct sky share"),
               ("site_factor_direct_day", "sun_direct_share",
                "the day's direct site factor vs the pass's direct sun share"),
               ("site_factor_direct_day_footprint", "sun_direct_share",
                "the day's direct site factor over the sensor vs the pass's direct sun share")]


def plot_area(scenario) -> float:
    """The map area of a scenario's ``[stand]`` plot [m2] (NaN without a stand).

    Parameters
    ----------
    scenario : Scenario
        The scenario.

    Returns
    -------
    float
        ``(x1 - x0)(z1 - z0)`` of ``[x0, z0, x1, z1]``, or the shoelace area of a polygon.
    """
    stand = scenario.get("stand") or {}
    plot = stand.get("plot")
    if plot is None:
        return math.nan
    a = np.asarray(plot, float)
    if a.shape == (4,):
        return float(abs((a[2] - a[0]) * (a[3] - a[1])))
    x, z = a[:, 0], a[:, 1]
    return float(abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1))) / 2)


def parse_at(text: str) -> tuple[float, float]:
    """A floor position from ``"X,Z"``.

    Parameters
    ----------
    text : str
        Two numbers [m], comma-separated.

    Returns
    -------
    tuple of float
        (x, z) [m].
    """
    try:
        parts = [float(v) for v in str(text).split(",")]
        if len(parts) != 2 or not all(math.isfinite(v) for v in parts):
            raise ValueError
        return parts[0], parts[1]
    except ValueError:
        raise ParameterError("--at", text, "X,Z: two finite numbers [m] (a floor position)",
                             "e.g. --at 3.5,-2") from None


def _days(world: RunWorld, day, years: bool, on) -> list[int]:
    if (day is None) == (not years):
        raise ParameterError("--day/--years", day if day is not None else "neither",
                             "either --day N or --years", "give one of them")
    if day is not None:
        return [world.check_day(day)]
    m, d = parse_on(on, "--on")
    out = []
    first = world.date(1).year
    for y in range(first, world.date(world.last_day).year + 1):
        try:
            date = _dt.date(y, m, d)
        except ValueError:            # 29 February of a common year
            continue
        k = world.day_of(date)
        if 1 <= k <= world.last_day:
            out.append(k)
    if not out:
        raise ParameterError("--on", on, f"a day of the year inside the run "
                             f"({world.date(1)} to {world.date(world.last_day)})",
                             "pick another --on, or --day N")
    return out


def _footprint(scene, position, size: float, lens: Lens, sun) -> tuple[float, float]:
    """Mean diffuse site factor and mean direct site factor of the day's sun path of
    photographs on a 3 x 3 grid over a square of side ``size`` around ``position`` (the
    pass's sensor)."""
    dsf, dir_ = [], []
    for dx in (-size / 3, 0.0, size / 3):
        for dz in (-size / 3, 0.0, size / 3):
            img = gap_image(scene, np.asarray(position, float) + [dx, 0.0, dz], lens)
            m = img.pixel_map()
            dsf.append(diffuse_site_factor(img.gap, m["theta"], m["solid_angle"], "uniform"))
            if len(sun[2]):
                dir_.append(direct_site_factor(img.gap, lens, *sun))
    return float(np.mean(dsf)), float(np.mean(dir_)) if dir_ else math.nan


def run_hemiphoto(run_dir, out=None, at=(), day: int | None = None, years: bool = False,
                  on: str = "07-15", height: float = 1.0, size: int = 1024,
                  projection: str = "equidistant", ring_width: float = 5.0,
                  truth: bool = False, photons: int = DEFAULT_PHOTONS,
                  sensor_size: float = DEFAULT_SIZE, colour: bool = False, colour_size: int = 512,
                  spp: int = 32, hour: float = 12.0, scenario=None,
                  progress: bool = False) -> dict:
    """Hemispherical photographs of a run's floor and their comparison with the truth (module
    docstring).

    Parameters
    ----------
    run_dir : str or pathlib.Path
        A run folder (``mitsuba-veg run``; a world with ``[[trees]]`` or a ``[stand]`` shows
        trees, any other shows its buildings).
    out : str or pathlib.Path, optional
        Output folder (default ``RUN_DIR/hemiphoto``).
    at : sequence of (float, float) or str
        Floor positions (x, z) [m] (``"X,Z"`` strings too).
    day : int, optional
        A day of the run (1-based); or
    years : bool
        The day ``on`` of every year of the run.
    on : str
        ``"MM-DD"`` of ``years`` (default 15 July).
    height : float
        Lens height above the ground [m].
    size : int
        Photograph side [px].
    projection : str
        ``"equidistant"`` or ``"equisolid"``.
    ring_width : float
        Width of the extra rings [deg].
    truth : bool
        Run the photon pass of each day (the light's truth).
    photons : int
        Photons of the sky pass (the sun pass gets half).
    sensor_size : float
        Side of the pass's sensor at each point [m].
    colour : bool
        Also render each photograph in colour.
    colour_size : int
        Side of the colour photograph [px].
    spp : int
        Samples per pixel of the colour photograph.
    hour : float
        Local hour of the colour photograph's daylight [h].
    scenario : str, optional
        The run's scenario, instead of the one its summary names.
    progress : bool
        Print a line per day.

    Returns
    -------
    dict
        The summary (settings, days, per photograph its values, timings [s], files).
    """
    t0 = time.perf_counter()
    pts_xz = [parse_at(a) if isinstance(a, str) else (float(a[0]), float(a[1])) for a in at]
    if not pts_xz:
        raise ParameterError("--at", None, "at least one floor position X,Z", "e.g. --at 0,0")
    check_range("--height", height, 0.01, 100.0, fix="lens height above the ground [m]")
    check_range("--photons", photons, 1000, 2_000_000_000, fix="e.g. 40000000")
    check_range("--sensor-size", sensor_size, 0.01, 10.0, fix="sensor side [m], e.g. 0.5")
    check_range("--spp", spp, 1, 65536)
    check_range("--hour", hour, 0.0, 24.0)
    lens = Lens(int(size), projection)
    clens = Lens(int(colour_size), projection)
    world = RunWorld(run_dir, scenario)
    days = _days(world, day, years, on)
    points = points_at(world.base_scene, world.ground_id, pts_xz, height)
    out = Path(out) if out is not None else Path(world.run.dir) / "hemiphoto"
    t_load = time.perf_counter() - t0
    folder = OutputFolder(out, "hemiphoto", reads=world.run.dir,
                          info={"run": str(world.run.dir)})
    try:
        rows, files, timings = [], {}, {"load": t_load, "scene": 0.0, "photos": 0.0,
                                        "truth": 0.0, "colour": 0.0}
        for k in days:
            t1 = time.perf_counter()
            date = world.date(k)
            canopy = world.canopy(k)
            state, snap = world.leaf_state(k, canopy)
            scene = canopy.scene(world.base_shapes, state, optics=False)
            t2 = time.perf_counter()
            photos = take_photos(scene, points, date, canopy, state, world.latitude,
                                 world.longitude, lens, ring_width)
            dirs, w, el = day_sun_path(world.latitude, world.longitude, date)
            az = np.degrees(np.arctan2(dirs[:, 0], -dirs[:, 2])) if len(w) else np.zeros(0)
            shown, scale, _ = canopy.blades(state)
            lai_plot = float(np.sum(canopy.area * scale * scale * shown)) / plot_area(
                world.scenario) if canopy.n_leaves else math.nan
            for ph in photos:
                ph.truth["snapshot_day"] = float(snap)
                ph.truth["lai_plot"] = lai_plot
                ph.analysis.values["site_factor_direct_day"] = direct_site_factor(
                    ph.image.gap, lens, az, el, w) if len(w) else math.nan
            t3 = time.perf_counter()
            if truth:
                tr = light_truth(canopy, world.base_shapes, state,
                                 [p.position for p in points], date, world.latitude,
                                 world.longitude, photons=photons, size=sensor_size)
                for ph, t in zip(photos, tr):
                    ph.truth.update({q: t[q] for q in (
                        "sky_direct_share", "sky_scattered_share", "sky_direct_share_se",
                        "sun_direct_share", "sun_scattered_share", "sun_direct_share_se",
                        "open_sky_share", "open_sun_share", "sensor_size_m")})
                    fd, fs = _footprint(scene, ph.point.position, sensor_size,
                                        Lens(512, projection), (az, el, w))
                    ph.analysis.values["site_factor_diffuse_footprint"] = fd
                    ph.analysis.values["site_factor_direct_day_footprint"] = fs
            t4 = time.perf_counter()
            for ph in photos:
                img = None
                if colour:
                    img, _ = colour_photo(canopy, world.base_shapes, state, ph.point.position,
                                          date, world.scenario, clens, spp, hour)
                files[ph.stem] = write_photo(ph, out, img)
                rows.append(series_row(ph))
            t5 = time.perf_counter()
            timings["scene"] += t2 - t1
            timings["photos"] += t3 - t2 + (t5 - t4 if not colour else 0.0)
            timings["truth"] += t4 - t3
            timings["colour"] += t5 - t4 if colour else 0.0
            if progress:
                print(f"day {k} ({date}): {len(photos)} photographs, {canopy.n_leaves:,d} "
                      f"leaves, {t5 - t1:.1f} s", flush=True)
        files["series"] = write_series(rows, out / "series.csv")
        comp = comparison_rows(rows)
        files["comparison"] = _write_comparison(comp, out / "comparison.csv")
        if len(days) > 0:
            files["comparison_figure"] = comparison_figure(rows, out / "comparison.png",
                                                           str(world.run.dir))
        summary = {"command": "hemiphoto", "run": str(world.run.dir),
                   "scenario": str(world.scenario.path),
                   "settings": {"height_m": height, "size_px": int(size),
                                "projection": projection, "ring_width_deg": ring_width,
                                "cone_deg": CONE_DEG, "truth": bool(truth),
                                "photons": int(photons) if truth else 0,
                                "sensor_size_m": sensor_size, "colour": bool(colour),
                                "spp": int(spp), "hour": hour},
                   "days": [{"day": k, "date": world.date(k).isoformat()} for k in days],
                   "points": [{"name": p.name, "x_m": p.x, "z_m": p.z,
                               "position_m": [float(v) for v in p.position]} for p in points],
                   "photographs": rows, "comparison": comp,
                   "timings_s": {**timings, "total": time.perf_counter() - t0},
                   "files": files, "versions": versions()}
        write_json(out / "summary.json", summary)
    finally:
        folder.release()
    return summary


def comparison_rows(rows: list) -> list:
    """Each field method against its truth, per day: the means over the points.

    Parameters
    ----------
    rows : list of dict
        Series rows (:func:`mitsuba_veg.daily.hemiphotos.series_row`, with the truth).

    Returns
    -------
    list of dict
        ``date``, ``method``, ``truth``, ``label``, ``points``, ``method_mean``,
        ``truth_mean``, ``difference`` (method − truth), ``mean_abs_difference`` (over the
        points), ``ratio`` (method / truth of the means); methods without their truth are
        left out.
    """
    out = []
    for date in sorted({r["date"] for r in rows}):
        rs = [r for r in rows if r["date"] == date]
        for m, t, label in COMPARISONS:
            a = np.array([r.get(m, math.nan) for r in rs], float)
            b = np.array([r.get(t, math.nan) for r in rs], float)
            ok = np.isfinite(a) & np.isfinite(b)
            if not ok.any():
                continue
            am, bm = float(a[ok].mean()), float(b[ok].mean())
            out.append({"date": date, "method": m, "truth": t, "label": label,
                        "points": int(ok.sum()), "method_mean": am, "truth_mean": bm,
                        "difference": am - bm,
                        "mean_abs_difference": float(np.abs(a[ok] - b[ok]).mean()),
                        "ratio": am / bm if bm else math.nan})
    return out


def _write_comparison(comp: list, path: Path) -> str:
    cols = ["date", "method", "truth", "points", "method_mean", "truth_mean", "difference",
            "mean_abs_difference", "ratio", "label"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in comp:
        w.writerow([f"{r[c]:.6g}" if isinstance(r[c], float) else r[c] for c in cols])
    with atomic_write(path, path.with_name(f".{path.stem}.tmp.csv")) as tmp:
        Path(tmp).write_text(buf.getvalue())
    return str(path)


def comparison_figure(rows: list, path, title: str = "") -> str:
    """The field methods against the truth over the days (the years of a stand).

    Left: LAI by the LAI-2000 formula, Miller's integral and Lang & Xiang against the true LAI
    and PAI in the view cone (means over the points, the points' range shaded); middle: the
    ratio of each method to the true LAI; right: the photograph's diffuse site factor against
    the photon pass's direct share of the sky, with the scattered share beside it.

    Parameters
    ----------
    rows : list of dict
        Series rows with the truth.
    path : str or pathlib.Path
        The PNG.
    title : str
        A title (the run).

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    dates = sorted({r["date"] for r in rows})
    x = np.arange(len(dates))

    def series(key):
        v = [np.array([r.get(key, math.nan) for r in rows if r["date"] == d], float)
             for d in dates]
        return (np.array([np.nanmean(a) if np.isfinite(a).any() else math.nan for a in v]),
                np.array([np.nanmin(a) if np.isfinite(a).any() else math.nan for a in v]),
                np.array([np.nanmax(a) if np.isfinite(a).any() else math.nan for a in v]))

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    style = {"lai_true": ("k", "-", "true LAI (cone)"), "pai_true": ("0.5", "--", "true PAI"),
             "lai_plot": ("tab:purple", ":", "stand LAI (plot)"),
             "lai_lai2000": ("tab:blue", "-", "LAI-2000 Le"),
             "lai_miller": ("tab:orange", "-", "Miller Le"),
             "lai_lang_xiang": ("tab:green", "-", "Lang & Xiang")}
    for k, (c, ls, lab) in style.items():
        m, lo, hi = series(k)
        ax[0].plot(x, m, color=c, ls=ls, marker="o", label=lab)
        if k in ("lai_true", "lai_lai2000"):
            ax[0].fill_between(x, lo, hi, color=c, alpha=0.12)
    ax[0].set_ylabel("leaf area index [m$^2$ m$^{-2}$] (mean of the points)")
    ax[0].set_ylim(bottom=0)
    ax[0].legend(fontsize=8)
    true, _, _ = series("lai_true")
    for k in ("lai_lai2000", "lai_miller", "lai_lang_xiang"):
        m, _, _ = series(k)
        c, ls, lab = style[k]
        ax[1].plot(x, m / true, color=c, marker="o", label=lab)
    ax[1].axhline(1.0, color="k", lw=0.8)
    ax[1].set_ylabel("method / true LAI [-]")
    ax[1].legend(fontsize=8)
    for k, c, lab in (("sky_direct_share", "k", "photon pass: direct sky share"),
                      ("site_factor_diffuse", "tab:blue", "photo: diffuse site factor"),
                      ("sky_scattered_share", "tab:red", "photon pass: scattered sky share")):
        m, lo, hi = series(k)
        if np.isfinite(m).any():
            ax[2].plot(x, m, color=c, marker="o", label=lab)
            ax[2].fill_between(x, lo, hi, color=c, alpha=0.1)
    ax[2].set_ylabel("share of the open's sky light [-]")
    ax[2].set_ylim(0, 1)
    ax[2].legend(fontsize=8)
    for a in ax:
        a.set_xticks(x)
        a.set_xticklabels(dates, fontsize=8)
        a.set_xlabel("date of the photographs")
        a.grid(alpha=0.3)
    fig.suptitle(f"hemispherical photographs against the truth {title}".strip(), fontsize=10)
    return save_figure(fig, path, dpi=90)
