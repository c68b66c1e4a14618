"""Sensor time series under a world's trees: ``mitsuba-veg light-study SCENARIO|RUN_DIR --from
... --to ... --step hourly|daily`` for a scenario with ``[[trees]]`` or a ``[stand]``, or for a
run folder.

The trees stand on each date with their leaves in that day's state:

- **a run folder**: the run's trees and the leaf state of its snapshot on or before each date
  (:class:`~mitsuba_veg.canopy_photo.run_day.RunWorld`: the trees as they stood after each
  year's growth, the leaves as the run's daily loop had them, every
  ``simulation.frame_every`` days);
- **a world scenario**: its daily loop (:class:`mitsuba_veg.daily.pipeline.Simulation`) is run
  from the scenario's ``start_date`` to the last date of the study (in a temporary folder),
  and the trees and every leaf's state are taken on each date of the study: leaf-out,
  paper 003's autumn clock (which needs the leaves' own light, day by day) and leaf fall as the
  world has them. ``--set light.photons=...`` makes that run cheaper.

Days with the same trees and leaves form a segment, traced in one light scene (the scenario's
shapes, the wood and the shown leaves with their stage's optics,
:class:`~mitsuba_veg.world.visible_canopy.VisibleCanopy`) by
:func:`mitsuba_veg.foliage.light_series.run_sensor_study` (one sky pass per segment, one sun
pass per step). The outputs are those of a light study (``sensors.csv``, ``dli.csv``,
figures, ``summary.json``) and, in ``hemiphotos/``, hemispherical photographs at every point
sensor and at the scenario's ``[[hemiphotos]]`` points, on the study's first day and on the
``on`` days of the ``[[hemiphotos]]`` inside the period (PNG, tidy CSV, ``series.csv``).
"""
from __future__ import annotations

import datetime as _dt
import tempfile
from pathlib import Path

import numpy as np

from ..daily.hemiphotos import (FOLDER, PhotoPoint, ground_points, points_from_scenario,
                                series_row, take_photos, write_photo, write_series)
from ..daily.config import MossConfig
from ..daily.pipeline import Simulation
from ..errors import ParameterError
from ..foliage.light_series import SERIES_PHOTONS, run_sensor_study
from ..light import sensors as S
from ..light.fisheye import Lens
from ..light.sensor_study import step_starts
from ..outputs import OutputFolder
from ..scenario import load_scenario
from ..world.visible_canopy import LeafState, VisibleCanopy
from .run_day import RunWorld

__all__ = ["run_world_sensor_study", "world_days", "run_days", "is_world"]


def is_world(source, overrides=()) -> bool:
    """Whether a light study's SCENE is a world: a run folder, or a scenario with trees.

    Parameters
    ----------
    source : str or pathlib.Path
        The SCENE argument.
    overrides : sequence of str
        ``--set`` overrides.

    Returns
    -------
    bool
        True for a folder or a ``.toml`` with ``[[trees]]`` or a ``[stand]``.
    """
    p = Path(source)
    if p.is_dir():
        return True
    if p.suffix.lower() != ".toml" or not p.is_file():
        return False
    scn = load_scenario(p, overrides)
    return bool(scn.get("trees") or scn.get("stand"))


def world_days(scn, dates, progress: bool = False):
    """The world's trees and leaf states on dates, from its daily loop.

    Runs the scenario from its ``simulation.start_date`` to the last date (in a temporary
    folder) and keeps, on each of ``dates``, the trees (a list, the same object while the
    trees do not grow) and the leaves' state (stored as a snapshot stores it).

    Parameters
    ----------
    scn : Scenario
        The world scenario.
    dates : sequence of datetime.date
        The dates (on or after the start date).
    progress : bool
        A progress bar over the days.

    Returns
    -------
    dict
        ``{date: (trees, LeafState)}``.
    """
    start = MossConfig(scn, 1).start
    want = sorted(set(dates))
    if want[0] < start:
        raise ParameterError("--from", want[0].isoformat(), f"on or after the world's start "
                             f"date, simulation.start_date = {start.isoformat()}",
                             f"--set simulation.start_date=\"{want[0].isoformat()}\" (the "
                             "trees are bare before their first leaf-out)", str(scn.path))
    days = (want[-1] - start).days + 1
    keep = set(want)
    out: dict = {}
    last: list = [None]
    with tempfile.TemporaryDirectory(prefix="mitsuba-veg-world-") as tmp:
        sim = Simulation(scn, tmp, days=days, progress=progress)

        def on_day(s, rec):
            d = _dt.date.fromisoformat(str(rec["date"])[:10])
            if d in keep:
                st = LeafState.from_phenology(s.phen) if s.phen is not None else \
                    LeafState.green(0)
                trees = list(s.trees or [])
                prev = last[0]
                if prev is not None and len(prev[0]) == len(trees) and \
                        all(a is b for a, b in zip(prev[0], trees)) and _same(prev[1], st):
                    out[d] = prev            # the same trees and leaves: one copy
                else:
                    out[d] = last[0] = (trees, st)

        sim.run(resume=False, on_day=on_day)
    return out


def _same(a: LeafState, b: LeafState) -> bool:
    return len(a) == len(b) and np.array_equal(a.tau, b.tau) and \
        np.array_equal(a.grown, b.grown) and np.array_equal(a.on, b.on)


def run_days(world: RunWorld, dates):
    """A run's trees and leaf states on dates (its snapshots).

    Parameters
    ----------
    world : RunWorld
        The run.
    dates : sequence of datetime.date
        Dates inside the run.

    Returns
    -------
    dict
        ``{date: (VisibleCanopy, LeafState)}``.
    """
    out = {}
    for d in sorted(set(dates)):
        k = world.day_of(d)
        world.check_day(k, "--from/--to")
        c = world.canopy(k)
        out[d] = (c, world.leaf_state(k, c)[0])
    return out


def run_world_sensor_study(source, out_dir, *, start=None, end=None, year=None,
                           step: str = "daily", photons: int = SERIES_PHOTONS,
                           sky_photons=None, seed=None, max_depth=None, indirect=None,
                           heatmap_every: int = 7, par_threshold: float = 200.0,
                           sensor=None, overrides=(), progress: bool = False,
                           photo_size: int = 1024) -> dict:
    """A light study's sensor time series under a world's trees (module docstring).

    Parameters
    ----------
    source : str or pathlib.Path
        A world scenario TOML or a run folder.
    out_dir : str or pathlib.Path
        The light study's folder.
    start, end : date or str, optional
        First and last local day (ISO ``YYYY-MM-DD``); or
    year : int, optional
        A whole calendar year.
    step : str
        ``"daily"`` or ``"hourly"``.
    photons : int
        Photons per sun pass.
    sky_photons : int, optional
        Photons of each segment's sky pass (default 10 x photons).
    seed, max_depth, indirect : optional
        Random seed (int), bounces per photon (int), scattered light traced (bool); default
        the scenario's ``[light]``.
    heatmap_every : int
        Daily steps: hourly passes every this many days for the heat map (0: none).
    par_threshold : float
        PPFD threshold [µmol m-2 s-1] of the hours-above count.
    sensor : str, optional
        Sensor of the year plot and heat map.
    overrides : sequence of str
        ``--set`` overrides of a scenario (none for a run folder).
    progress : bool
        Progress bars.
    photo_size : int
        Side of the hemispherical photographs [px].

    Returns
    -------
    dict
        The light study's summary, with ``hemiphotos`` (the photographs' rows) and the world's
        ``source`` (``run`` or ``scenario``).
    """
    p = Path(source)
    run = None
    if p.is_dir():
        run = RunWorld(p)
        scn = run.scenario
        if overrides:
            raise ParameterError("--set", list(overrides), "no overrides for a run folder (its "
                                 "scenario is the run's)", "leave --set out")
    else:
        scn = load_scenario(p, overrides)
    base = scn.load_scene(daylight=False)
    base_shapes = list(base.shapes())
    bins = int((scn.get("phenology") or {}).get("stage_bins", 4))
    cache: dict = {}

    def states(a, b):
        days = [a + _dt.timedelta(days=k) for k in range((b - a).days + 1)]
        if run is not None:
            got = run_days(run, days)
        else:
            raw = world_days(scn, days, progress)
            canopies, got = {}, {}
            for d in days:
                trees, st = raw[d]
                key = tuple(id(t) for t in trees)
                if key not in canopies:
                    canopies[key] = VisibleCanopy(trees, bins)
                got[d] = (canopies[key], st)
        cache.update(got)
        return got

    def segments(a, b):
        step_starts(a, b, "daily")                  # a reversed or too long period first
        got = states(a, b)
        segs, cur = [], None
        for d in sorted(got):
            c, st = got[d]
            if cur is not None and cur[2] is c and _same(cur[3], st):
                cur[1] = d
            else:
                if cur is not None:
                    segs.append(cur)
                cur = [d, d, c, st]
        segs.append(cur)
        return [(a_, b_, c.scene(base_shapes, st, optics=True)) for a_, b_, c, st in segs]

    folder = OutputFolder(out_dir, "light-study")
    folder.clear([FOLDER])
    try:
        summary = run_sensor_study(p if run is None else scn.path, out_dir, start=start,
                                   end=end, year=year, step=step, photons=photons,
                                   sky_photons=sky_photons, seed=seed, max_depth=max_depth,
                                   indirect=indirect, heatmap_every=heatmap_every,
                                   par_threshold=par_threshold, sensor=sensor,
                                   overrides=() if run is not None else overrides,
                                   progress=progress, segments=segments, scenario_obj=scn)
        summary["world"] = {**(summary.get("world") or {}),
                            "source": "run" if run is not None else "scenario",
                            "path": str(p)}
        summary["hemiphotos"] = _photos(scn, base, base_shapes, cache, Path(out_dir),
                                        photo_size)
        summary["files"]["hemiphotos"] = str(Path(out_dir) / FOLDER)
    finally:
        folder.release()
    return summary


def _photos(scn, base, base_shapes, cache: dict, out: Path, size: int) -> list:
    """Photographs at the point sensors and the ``[[hemiphotos]]`` points (module docstring)."""
    sensors = S.from_scenario(scn, base)
    ground = {s.id(): s for s in base.shapes()}.get(scn.get("terrain.ground", "ground"))
    points = []
    if sensors is not None and ground is not None:
        for i in np.flatnonzero(sensors.ij[:, 0] < 0):
            pos = sensors.position[i]
            try:
                g = ground_points(ground, [[pos[0], pos[2]]], 0.01)[0][1] - 0.01
            except ParameterError:
                continue                       # not over the ground (on a wall)
            points.append((PhotoPoint(str(sensors.names[i]), float(pos[0]), float(pos[2]),
                                      float(pos[1] - g), np.asarray(pos, float)), None))
    if scn.get("hemiphotos"):
        # a [[hemiphotos]] entry named like a point sensor takes its place (its own height)
        own = points_from_scenario(scn, base)
        names = {pt.name for pt, _ in own}
        points = [x for x in points if x[0].name not in names] + own
    if not points or not cache:
        return []
    dates = sorted(cache)
    lat, lon = float(scn.get("site.latitude")), float(scn.get("site.longitude"))
    rows = []
    for d in dates:
        due = [pt for pt, s in points if d == dates[0] or
               (s is not None and (d.month, d.day) in s["on"])]
        if not due:
            continue
        c, st = cache[d]
        scene = c.scene(base_shapes, st, optics=False)
        for ph in take_photos(scene, due, d, c, st, lat, lon, Lens(int(size))):
            write_photo(ph, out / FOLDER)
            rows.append(series_row(ph))
    write_series(rows, out / FOLDER / "series.csv")
    return rows
