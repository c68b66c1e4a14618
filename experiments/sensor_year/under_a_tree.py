"""June under a tree, read by virtual sensors: maps of the daily light integral and of the
red:far-red ratio a shade-avoiding plant 0.3 m above the ground would sense (docs/sensors.md).

A built-in test tree (sphere crown of radius 1.5 m centred 3 m up, 20,000 green PROSPECT-D
leaves by default, :func:`mitsuba_veg.foliage.canopy.sphere_crown_tree`) over a 12 m x 12 m ground; a
0.5 m grid of 0.3 m cosine sensors 0.3 m above the ground and one spherical sensor in the
crown's shade; clear-sky SPCTRAL2 daylight of June 2026 at 35° N, one sun pass per day
(:func:`mitsuba_veg.light.sensor_study.run_series`).

Usage::

    .venv/bin/python experiments/sensor_year/under_a_tree.py [--out out/sensor_tree]
        [--photons 1000000] [--leaves 20000]

Writes ``dli_map.png``, ``rfr_map.png`` (June means), ``rfr_noon_map.png`` (21 June, 12-13 h
local, from an hourly series of that day) and prints the numbers.
"""
from __future__ import annotations

import argparse
import datetime as dt
import time
from pathlib import Path

import numpy as np

import mitsuba_veg  # noqa: F401  (variant, plugins)
from mitsuba_veg.foliage.canopy import sphere_crown_tree
from mitsuba_veg.foliage.light_series import grid_map_figure
from mitsuba_veg.foliage.light_study import tree_scene
from mitsuba_veg.light import sensor_study as SS
from mitsuba_veg.light import sensors as S
from mitsuba_veg.light.clear_sky import daylight_from_angles


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="out/sensor_tree")
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--leaves", type=int, default=20_000)
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    tree = sphere_crown_tree(a.leaves, seed=0)
    # the emitters given here are replaced by the series' sun and sky
    scene, _ = tree_scene(tree, emitters=daylight_from_angles(180.0, 60.0), ground_extent=12.0,
                          ground_resolution=24)
    grid = S.ground_grid(scene, "ground", spacing=0.5, height=0.3, size=0.3)
    shade = S.point("shade_sphere", (0.0, 0.3, 1.0), kind="spherical", size=0.3)
    sensors = grid + shade
    series = SS.run_series(scene, sensors, latitude=35.0, longitude=139.0, timezone=9.0,
                           start=dt.date(2026, 6, 1), end=dt.date(2026, 6, 30), step="daily",
                           photons=a.photons, progress=True)
    days, dli, odli = SS.daily_light_integral(series)
    mean_dli = dli[..., 2].mean(axis=0)
    q = S.QUANTITIES
    red = series.values[:, :, q.index("red"), 2].sum(axis=0)
    fr = series.values[:, :, q.index("far_red"), 2].sum(axis=0)
    rfr = red / fr
    m = sensors.group == "ground"
    grid_map_figure(sensors, m, mean_dli, out / "dli_map.png",
                    "June 2026, 35° N: mean DLI 0.3 m above the ground under a tree",
                    "DLI [mol m$^{-2}$ d$^{-1}$]", "viridis", vmin=0.0)
    grid_map_figure(sensors, m, rfr, out / "rfr_map.png",
                    f"June 2026: red : far-red 0.3 m above the ground under a tree "
                    f"({rfr[m].min():.2f}-{rfr[m].max():.2f})", "R:FR [-]", "RdYlGn",
                    vmin=0.0, vmax=1.3)
    noon = SS.run_series(scene, sensors, latitude=35.0, longitude=139.0, timezone=9.0,
                         start=dt.date(2026, 6, 21), end=dt.date(2026, 6, 21), step="hourly",
                         photons=a.photons, sky_readings=series.settings["sky_readings"],
                         light_scene=series.settings["light_scene"])
    h = 12
    rfr_noon = noon.values[h, :, q.index("rfr"), 2]
    ppfd_noon = noon.values[h, :, q.index("par"), 2]
    grid_map_figure(sensors, m, rfr_noon, out / "rfr_noon_map.png",
                    f"21 June 2026, 12-13 h: red : far-red 0.3 m above the ground under a tree "
                    f"({rfr_noon[m].min():.2f}-{rfr_noon[m].max():.2f})", "R:FR [-]", "RdYlGn",
                    vmin=0.0, vmax=1.3)
    i = sensors.index("shade_sphere")
    print(f"{a.leaves:,d} leaves, {len(sensors)} sensors, {series.sun_passes} sun passes x {a.photons:,d} photons, "
          f"{time.perf_counter() - t0:.1f} s")
    print(f"open sky: mean DLI {odli[:, 2].mean():.2f} mol m-2 d-1")
    print(f"ground grid: mean DLI {mean_dli[m].min():.2f}-{mean_dli[m].max():.2f}, "
          f"R:FR {rfr[m].min():.3f}-{rfr[m].max():.3f}")
    print(f"shade_sphere (spherical, 1 m south of the trunk): mean DLI {mean_dli[i]:.2f}, "
          f"R:FR {rfr[i]:.3f}")
    print(f"21 June 12-13 h: ground grid PPFD {ppfd_noon[m].min():.0f}-{ppfd_noon[m].max():.0f} "
          f"umol m-2 s-1, R:FR {rfr_noon[m].min():.3f}-{rfr_noon[m].max():.3f}")
    print(f"wrote {out / 'dli_map.png'}, {out / 'rfr_map.png'}, {out / 'rfr_noon_map.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
