"""``mitsuba-veg light-study``: the command line of the spectral light study.

One time (:func:`mitsuba_veg.foliage.light_study.run_light_study`: ground maps, per-leaf values
and the scenario's sensors from one photon pass) or a sensor time series with ``--year`` /
``--from`` / ``--to`` (:func:`mitsuba_veg.foliage.light_series.run_sensor_study`).
"""
from __future__ import annotations

import datetime as _dt

from ..canopy_photo.world_light import is_world, run_world_sensor_study
from ..errors import ParameterError
from ..foliage.light_series import SERIES_PHOTONS, run_sensor_study
from ..foliage.light_study import run_light_study
from .args import add_out, add_photons, add_quiet, add_set, iso_datetime, light_type, ranged

__all__ = ["add_parser"]


def add_parser(subparsers):
    """Add ``light-study`` to an argparse subparsers object.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``mitsuba-veg`` command's subparsers.

    Returns
    -------
    argparse.ArgumentParser
        The ``light-study`` parser.
    """
    p = subparsers.add_parser(
        "light-study", help="spectral light study: PAR, red, far-red, R:FR maps under trees",
        description="Photon pass with PAR/red/far-red bands: ground maps (PNG + npz), per-leaf "
                    "values (CSV) and summary.json. SCENE: scenario .toml, scene .xml, or "
                    "'sphere-tree' (built-in test tree under daylight); for a time series also "
                    "a world scenario (its trees run to their leaf state on each date) or a run "
                    "folder (its trees and leaf states).")
    p.add_argument("scene", help="scenario .toml, Mitsuba .xml, 'sphere-tree', or (time series) "
                                 "a run folder")
    add_photons(p, None, "per light pass (default 2000000; time series: 500000 per sun "
                         "pass)")
    p.add_argument("--seed", type=light_type("seed"),
                   help="random seed (default 0; time series: the scenario's light.seed)")
    p.add_argument("--max-depth", type=light_type("max_depth"),
                   help="bounces per photon (default 8; time series: the scenario's "
                        "light.max_depth)")
    p.add_argument("--no-indirect", action="store_true", help="first hits only")
    p.add_argument("--when", metavar="ISO-DATETIME", type=iso_datetime,
                   help="daylight at this time, e.g. 2026-07-15T12:00:00+09:00 (scenario or "
                        "tree; default for trees: mid-July noon)")
    p.add_argument("--latitude", type=ranged(float, -90, 90, "deg"),
                   help="tree scenes: site latitude [deg] (default 35)")
    p.add_argument("--longitude", type=ranged(float, -180, 180, "deg"),
                   help="tree scenes: site longitude [deg] (default 139)")
    p.add_argument("--ground", help="shape id of the ground (default: scenario's or 'ground')")
    p.add_argument("--leaves", type=ranged(int, 1, 1_000_000, "leaves"), default=3000,
                   help="'sphere-tree': number of leaves")
    g = p.add_argument_group(
        "sensor time series (a scenario with [[sensors]], or a run folder; docs/sensors.md)",
        "--year or --from/--to: clear-sky daylight of the scenario's site over the days; writes "
        "sensors.csv/.parquet (time x sensor x band x component), dli.csv, summary.json and "
        "figures (DLI and R:FR maps of the first grid, one sensor's year, hour x day heat map); "
        "under a world's trees also hemispherical photographs at the point sensors "
        "(hemiphotos/, docs/hemiphoto.md)")
    g.add_argument("--year", type=ranged(int, 1, 9999, "year"), nargs="?", const=-1,
                   metavar="YYYY", help="a whole calendar year (default: this year)")
    g.add_argument("--from", dest="date_from", metavar="YYYY-MM-DD", help="first local day")
    g.add_argument("--to", dest="date_to", metavar="YYYY-MM-DD", help="last local day")
    g.add_argument("--step", choices=("daily", "hourly"), default="daily",
                   help="daily: one sun pass per day (the day's sun path); hourly: one per hour")
    g.add_argument("--heatmap-every", type=ranged(int, 0, 366, "days"), default=7,
                   metavar="DAYS", help="daily steps: hourly passes every DAYS days for the "
                                        "hour x day heat map and hours above the threshold "
                                        "(0: none)")
    g.add_argument("--par-threshold", type=ranged(float, 0, 5000, "umol m-2 s-1"),
                   default=200.0, help="PPFD threshold of the hours-above count")
    g.add_argument("--sensor", help="sensor of the year plot and heat map (default: the first "
                                    "point sensor)")
    g.add_argument("--sky-photons", type=light_type("photons"),
                   metavar="N", help="photons of the one sky pass (default 10 x --photons)")
    add_set(p, "scenario")
    add_out(p, "out/light_study", "maps, light_study.npz, leaves.csv and summary.json (time "
                                  "series: sensors.csv/.parquet, dli.csv, figures)")
    add_quiet(p)
    p.set_defaults(func=_cmd)
    return p


def _series_cmd(a) -> int:
    year = a.year
    if year == -1:
        year = _dt.date.today().year
    if a.when is not None:
        raise ParameterError("--when", a.when, "not with --year/--from/--to",
                             "a time series covers its own days")
    # a world (a run folder, or a scenario with trees): the trees in their leaf state on
    # each date (mitsuba_veg.canopy_photo.world_light)
    study = run_world_sensor_study if is_world(a.scene, a.set or ()) else run_sensor_study
    s = study(a.scene, a.out, start=a.date_from, end=a.date_to, year=year,
              step=a.step, photons=a.photons or SERIES_PHOTONS,
              sky_photons=a.sky_photons, seed=a.seed, max_depth=a.max_depth,
              indirect=False if a.no_indirect else None,
              heatmap_every=a.heatmap_every, par_threshold=a.par_threshold,
              sensor=a.sensor, overrides=a.set or (), progress=not a.quiet)
    per = s["per_sensor"]
    print(f"light study (sensors): {s['scenario']}: {s['period']['from']} to "
          f"{s['period']['to']}, {s['period']['steps']} {s['period']['step']} steps, "
          f"{s['passes']['sun']} sun passes x {s['settings']['photons']:,d} photons, "
          f"{s['timings_s']['total']:.1f} s")
    print(f"  open sky: mean DLI {s['open_sky']['dli_mean']:.2f} mol m-2 d-1")
    for name in list(per)[:8]:
        v = per[name]
        line = f"  {name} ({v['kind']}): mean DLI {v['dli_mean']:.2f} mol m-2 d-1"
        if v["rfr"] is not None:
            line += f", R:FR {v['rfr']:.3f}"
        if v["hours_above_threshold_per_day"] is not None:
            line += (f", {v['hours_above_threshold_per_day']:.1f} h/day above "
                     f"{s['par_threshold_umol_m2_s']:g}")
        print(line)
    if len(per) > 8:
        print(f"  ... {len(per) - 8} more sensors (summary.json, dli.csv)")
    if s.get("world"):
        n = len(s["world"]["segments"])
        print(f"  under the world's trees ({s['world']['source']}): {n} leaf "
              f"state{'s' if n != 1 else ''} over the period")
    for r in s.get("hemiphotos", [])[:8]:
        print(f"  hemiphoto {r['photo']} {r['date']}: openness {r['openness']:.3f}, "
              f"LAI-2000 Le {r['lai_lai2000']:.2f}, true LAI {r['lai_true']:.2f}, DSF "
              f"{r['site_factor_diffuse']:.3f}")
    print("wrote:")
    for v in s["files"].values():
        for f in (v.values() if isinstance(v, dict) else [v]):
            print(f"  {f}")
    return 0


def _cmd(a) -> int:
    series = a.year is not None or a.date_from is not None or a.date_to is not None
    if series:
        return _series_cmd(a)
    s = run_light_study(a.scene, a.out, photons=2_000_000 if a.photons is None else a.photons,
                        seed=0 if a.seed is None else a.seed,
                        max_depth=8 if a.max_depth is None else a.max_depth,
                        indirect=not a.no_indirect, when=a.when, latitude=a.latitude,
                        longitude=a.longitude, ground=a.ground, overrides=a.set or (),
                        tree_leaves=a.leaves, progress=not a.quiet)
    g = s["ground"]
    print(f"light study: {s['scene']}: photon pass {s['timings_s']['photon_pass']:.2f} s")
    line = f"  ground '{s['ground_id']}': mean PPFD {g['ppfd']:.1f} umol m-2 s-1"
    if g.get("rfr") is not None:
        line += f", R:FR {g['rfr']:.3f} (min {g['rfr_min']:.3f})"
    if "ppfd_fraction_of_open" in g:
        line += f", {100 * g['ppfd_fraction_of_open']:.1f} % of open PPFD"
    print(line)
    for name, v in list(s.get("sensors", {}).items())[:8]:
        print(f"  sensor {name}: PPFD {v['ppfd']:.1f} umol m-2 s-1 (direct {v['ppfd_direct']:.1f}),"
              f" R:FR {v['rfr']:.3f}")
    if s["leaves"]:
        lv = s["leaves"]
        print(f"  {lv['leaves']} leaves: PPFD mean {lv['ppfd_mean']:.1f} (p10 {lv['ppfd_p10']:.1f},"
              f" p90 {lv['ppfd_p90']:.1f}), R:FR mean {lv['rfr_mean']:.3f}")
    print("wrote:")
    for k, v in s["files"].items():
        print(f"  {v}")
    return 0
