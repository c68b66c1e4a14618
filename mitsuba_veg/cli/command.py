"""The ``mitsuba-veg`` command.

    mitsuba-veg demo [--out DIR]                       the default scenario end to end
    mitsuba-veg irradiance SCENE [--photons N] [--out DIR] [--when ISO] [--no-indirect] ...
    mitsuba-veg run SCENARIO [--out DIR] [--days N] [--set KEY=VALUE ...] [--fresh]
    mitsuba-veg light-study SCENE [--out DIR] ...
    mitsuba-veg hemiphoto RUN_DIR --at X,Z [--at ...] (--day N | --years) [--truth] ...
    mitsuba-veg grow TREE.toml [--out DIR] [--set KEY=VALUE] [--seed S] [--generations G]
    mitsuba-veg sweep SWEEP.toml [--scheduler ADDRESS] [--workers N] [--out DIR]

SCENE is a Mitsuba XML file or a scenario TOML (which names the XML and the light settings).
"""
from __future__ import annotations

import time
from pathlib import Path

import mitsuba as mi
import numpy as np

from ..daily.run import run
from ..defaults import LIGHT, check_light
from ..errors import ParameterError, SceneError
from ..light import photon_irradiance
from ..outputs import OutputFolder, write_json
from ..plots import irradiance_figure
from ..render.still import run_render
from ..scenario import light_overrides, load_scenario, load_scene_file
from ..sweeps.frames import run_animate
from ..backend import __version__, versions
from ..world.trees import scene_with_trees
from . import grow, hemiphoto, light_study, render, sweep, tune
from .args import (Parser, add_out, add_photons, add_quiet, add_set, iso_datetime, light_type,
                   ranged)
from .entry import run_parsed


__all__ = ["DEFAULT_SCENARIO", "DEMO_WHEN", "run_irradiance", "build_parser", "main"]

def _default_scenario(name: str = "courtyard") -> Path:
    """A shipped scenario (default: the courtyard world): from the source tree, else from the
    installed package data."""
    here = Path(__file__).resolve().parent.parent
    for p in (here.parent / "scenes", here / "scenes"):
        if (p / name / "scenario.toml").exists():
            return p / name / "scenario.toml"
    raise SceneError("the shipped scenes are missing from this installation; pass a scenario "
                     "file explicitly (mitsuba-veg run SCENARIO.toml)")


#: the demo's scenario file (None until ``_default_scenario()`` resolves it)
DEFAULT_SCENARIO = None
#: a summer morning in the courtyard: trees in full leaf, the house wall's shade on the bed
DEMO_WHEN = "2026-07-15T10:00:00+09:00"




def run_irradiance(scene_path, out, photons=None, seed=None, max_depth=None, indirect=None,
                   when=None, overrides=(), progress=True) -> dict:
    """The photon pass of ``mitsuba-veg irradiance`` on a scene or scenario.

    Parameters
    ----------
    scene_path : path-like
        A Mitsuba XML scene or a scenario TOML.
    out : path-like
        Output folder: ``irradiance.npz``, PNG maps per shape and ``summary.json``.
    photons, seed, max_depth : int, optional
        Photons of the pass in all (shared by the emitters in proportion to the power each
        sends towards the geometry, each at least 5 %), random seed, bounces per photon
        (default: the scenario's, else 1000000, 0, 8).
    indirect : bool, optional
        Follow bounces (default: the scenario's, else True).
    when : str, optional
        ISO date-time: daylight for the scenario's site instead of its emitters (TOML only).
    overrides : sequence of str
        ``KEY=VALUE`` scenario fields.
    progress : bool
        Show a progress bar.

    Returns
    -------
    dict
        The summary (irradiance means per shape and region [W m-2], R:FR, energy balance [W],
        timings [s], files, versions).
    """
    scene_path = Path(scene_path)
    out = Path(out)
    if scene_path.suffix.lower() not in (".toml", ".xml") or not scene_path.is_file():
        raise ParameterError("SCENE", str(scene_path), "an existing .xml scene or .toml "
                             "scenario file", "check the path")
    if when is not None and scene_path.suffix.lower() != ".toml":
        raise ParameterError("--when", when, "a scenario (.toml) with a [site] as SCENE",
                             "pass the scenario instead of the XML: --when replaces the "
                             "scene's emitters by daylight for the scenario's site")
    for k, v in (("photons", photons), ("seed", seed), ("max_depth", max_depth)):
        if v is not None:
            check_light(k, v, "--" + k.replace("_", "-"))
    regions = {}
    tree_shapes = []
    ground = "ground"
    settings = {k: LIGHT[k].default for k in ("photons", "seed", "max_depth", "indirect")}
    t0 = time.perf_counter()
    if scene_path.suffix.lower() == ".toml":
        ov = list(overrides)
        if when is not None:
            ov.append(f'light.when="{when}"')
        scn = load_scenario(scene_path, ov)
        scene = scn.load_scene()
        if scn.get("trees") or scn.get("stand"):   # a world: its trees in full green leaf
            scene, tree_shapes = scene_with_trees(scn, scene)
        settings.update({k: scn.get(f"light.{k}") for k in settings})
        regions = scn.get("regions", {})
        ground = scn.get("terrain.ground", ground)
        when = scn.get("light.when")
    else:
        # --set with an XML: the light settings only, every key checked (none ignored)
        settings.update(light_overrides(overrides, f"{scene_path} (--set)"))
        scene = load_scene_file(scene_path, "SCENE")
    t_load = time.perf_counter() - t0
    folder = OutputFolder(out, "irradiance", info={"scene": str(scene_path)})
    for k, v in {"photons": photons, "seed": seed, "max_depth": max_depth,
                 "indirect": indirect}.items():
        if v is not None:
            settings[k] = v
    res = photon_irradiance(scene, photons=int(settings["photons"]), seed=int(settings["seed"]),
                            max_depth=int(settings["max_depth"]),
                            indirect=bool(settings["indirect"]), progress=progress)
    res.to_npz(out / "irradiance.npz")
    pngs = []
    for sid in res.index.shape_ids:
        if sid in res.index.geometry and sid not in tree_shapes:
            pngs.append(irradiance_figure(res, sid, out / f"irradiance_{sid}.png"))
    shapes = {}
    for sid in res.index.shape_ids:
        if sid in tree_shapes:
            continue
        sl = res.index.shape_slice(sid)
        area = res.index.areas[sl]
        entry = {"triangles": int(sl.stop - sl.start), "area_m2": float(area.sum())}
        for b in res.bands:
            for c in ("direct", "indirect", "total"):
                e = res.irradiance(sid, b, c)
                entry[f"{b}.{c}.mean_W_m2"] = float((e * area).sum() / area.sum())
        if "red" in res.bands and "far_red" in res.bands:
            r = res.photon_flux_density(sid, "red") * area
            f = res.photon_flux_density(sid, "far_red") * area
            entry["red_far_red"] = float(r.sum() / f.sum()) if f.sum() > 0 else None
        shapes[sid] = entry
    reg_out = {}
    for name, reg in regions.items():
        acc = {}
        for sid in reg["shapes"]:
            sl = res.index.shape_slice(sid)
            c = res.index.centroids[sl]
            inside = np.all((c >= np.array(reg["min"])) & (c <= np.array(reg["max"])), axis=1)
            area = res.index.areas[sl][inside]
            for b in res.bands:
                e = res.irradiance(sid, b)[inside]
                acc.setdefault(b, [0.0, 0.0])
                acc[b][0] += float((e * area).sum())
                acc[b][1] += float(area.sum())
        reg_out[name] = {f"{b}.mean_W_m2": (v[0] / v[1] if v[1] > 0 else None)
                         for b, v in acc.items()}
        reg_out[name]["area_m2"] = next(iter(acc.values()))[1] if acc else 0.0
    summary = {
        "command": "irradiance", "scene": str(scene_path), "when": when, "settings": settings,
        "bands_nm": dict(zip(res.bands, res.band_ranges)), "emitters": list(res.emitters),
        "photons_per_emitter": res.photons.tolist(), "rays_traced": res.rays_traced,
        "timings_s": {"load": t_load, "photon_pass": res.seconds},
        "photons_per_s": float(res.photons.sum() / res.seconds),
        "energy_W": {"emitted": res.emitted.sum(0).tolist(), "absorbed": res.absorbed.sum(0).tolist(),
                     "escaped": res.escaped.sum(0).tolist(),
                     "truncated": res.truncated.sum(0).tolist()},
        "shapes": shapes, "regions": reg_out, "files": {
            "npz": str(out / "irradiance.npz"), "png": pngs}, "versions": versions()}
    write_json(out / "summary.json", summary)
    folder.release()
    return summary


def _cmd_irradiance(a) -> int:
    s = run_irradiance(a.scene, a.out, photons=a.photons, seed=a.seed, max_depth=a.max_depth,
                       indirect=False if a.no_indirect else None, when=a.when,
                       overrides=a.set or (), progress=not a.quiet)
    _report(s)
    return 0


def _report(s: dict) -> None:
    print(f"photon pass: {sum(s['photons_per_emitter']):,d} photons, {s['rays_traced']:,d} ray "
          f"casts in {s['timings_s']['photon_pass']:.2f} s ({s['photons_per_s'] / 1e6:.2f} M "
          f"photons/s)")
    for sid, e in s["shapes"].items():
        line = f"  {sid:>10s}: mean total {e.get('total.total.mean_W_m2', float('nan')):8.2f} W/m2"
        if e.get("red_far_red") is not None:
            line += f", R:FR {e['red_far_red']:.3f}"
        print(line)
    for name, r in s["regions"].items():
        print(f"  region {name}: mean total {r.get('total.mean_W_m2') or 0:.2f} W/m2 over "
              f"{r['area_m2']:.2f} m2")
    print("wrote:")
    print(f"  {s['files']['npz']}")
    for p in s["files"]["png"]:
        print(f"  {p}")
    print(f"  {Path(s['files']['npz']).parent / 'summary.json'}")


def _cmd_run(a) -> int:
    out = Path(a.out)
    s = run(a.scenario, out=out, days=a.days, overrides=a.set or (), resume=not a.fresh,
            progress=not a.quiet)
    f = s["final"]
    print(f"{s['days']} days: {f['moss_alive']} moss alive, covered {f['covered_area_m2']:.4f} m2"
          + "".join(f"; {k} {v['covered_area_m2']:.4f} m2" for k, v in f["regions"].items()))
    t = s["timings_s"]["per_day"]
    print(f"per day: light {t['light']:.3f} s, soil {t['soil']:.4f} s, moss {t['moss']:.4f} s")
    print("wrote:")
    print(f"  {out / 'summary.json'}")
    for k in ("animation",):
        if k in s.get("files", {}):
            print(f"  {s['files'][k]}")
    print(f"  {out / 'maps'}/day_*.png")
    print(f"  {out / 'checkpoint.npz'}")
    return 0


def _cmd_demo(a) -> int:
    out = Path(a.out)
    scen = _default_scenario()
    print(f"mitsuba-veg demo 1/4: light study of the courtyard (trees in full leaf) under "
          f"daylight on {DEMO_WHEN} -> {out / 'light'}/")
    s = run_irradiance(scen, out / "light", photons=a.photons, when=DEMO_WHEN,
                       progress=not a.quiet)
    _report(s)
    print(f"\nmitsuba-veg demo 2/4: {a.days} days of the courtyard world (trees, leaves, soil "
          f"and moss in one daily light loop) -> {out / 'world'}/")
    m = run(scen, out=out / "world", days=a.days,
            overrides=[f"light.photons={a.world_photons}"], progress=not a.quiet)
    f = m["final"]
    print(f"{a.days} days: {f['moss_alive']} moss alive, covered {f['covered_area_m2']:.3f} m2"
          + "".join(f"; {k} {v['covered_area_m2']:.3f} m2" for k, v in f["regions"].items()))
    # the day the leaves absorbed the most PAR: full leaf, high sun
    summer = max(m["days_record"], key=lambda r: sum(t["absorbed_par_W"]
                                                     for t in r["trees"].values()))
    for name, t in summer["trees"].items():
        u = t["ground_under_crown"]
        print(f"  {name}: {t['leaves_on_tree']:,d} leaves on {summer['date']}, ground under "
              f"the crown PAR {u['par_W_m2']:.1f} W/m2, R:FR {u['red_far_red']:.3f}")
    o = summer["ground_open"]
    print(f"  open ground: PAR {o['par_W_m2']:.1f} W/m2, R:FR {o['red_far_red']:.3f}")
    print("wrote:")
    for p in (out / "world" / "summary.json", m.get("files", {}).get("animation"),
              out / "world" / "maps"):
        if p:
            print(f"  {p}")
    print(f"\nmitsuba-veg demo 3/4: spectral render of the last day and of midsummer -> "
          f"{out / 'world' / 'render'}/")
    # the last day from the overview and from the floor across the moss; midsummer's overview
    r = run_render(out / "world", camera="overview,floor", progress=not a.quiet)
    r2 = run_render(out / "world", out / "world" / "render_summer", camera="overview",
                    day=summer["day"], progress=not a.quiet)
    print(f"\nmitsuba-veg demo 4/4: animation of the year -> {out / 'world' / 'animation'}/")
    # one daylight (the midsummer morning) for every frame: the scene is built and its kernel
    # compiled once; the frames' leaves and moss follow their days
    an = run_animate(out / "world", light="fixed", when=f"{summer['date']}T10:00:00+09:00",
                     progress=not a.quiet)
    print("wrote:")
    for rr in (r, r2):
        for cam in rr["files"].values():
            for p in cam.values():
                print(f"  {p}")
    for k in ("mp4", "gif"):
        if an["files"].get(k):
            print(f"  {an['files'][k]}")
    return 0


def build_parser():
    """The ``mitsuba-veg`` argument parser with every sub-command.

    Returns
    -------
    cli.args.Parser
    """
    ap = Parser(prog="mitsuba-veg", description="Grow vegetation from light with Mitsuba 3.")
    ap.add_argument("--version", action="version",
                    version=f"mitsuba-veg {__version__}")
    ap.add_argument("-v", "--verbose", action="store_true",
                    help="log more (level info) and show tracebacks of internal errors")
    ap.add_argument("--log-level", choices=("debug", "info", "warning", "error"),
                    help="logging level (default: warning; info with --verbose)")
    sub = ap.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    d = sub.add_parser("demo", help="run the default scenario end to end")
    add_out(d, "out/demo", "the light study, the world run, render and animation")
    add_photons(d, 4_000_000, "of the light study")
    d.add_argument("--world-photons", type=light_type("photons"), default=500_000,
                   help="photons per day of the world run")
    d.add_argument("--days", type=ranged(int, 1, 100_000, "days"), default=365,
                   help="days of the world run (from 1 March)")
    add_quiet(d)
    d.set_defaults(func=_cmd_demo)
    r = sub.add_parser("run", help="run a moss scenario day by day (paper 000)")
    r.add_argument("scenario", help="scenario TOML, e.g. scenes/moss_garden/scenario.toml")
    add_out(r, "out/run", "the run (summary.json, maps, checkpoint)")
    r.add_argument("--days", type=ranged(int, 1, 100_000, "days"),
                   help="simulated days (default: the scenario's simulation.days)")
    add_set(r, "scenario", "light.indirect=false")
    r.add_argument("--fresh", action="store_true",
                   help="discard the checkpoint and every output of an earlier run in --out "
                        "and start from day 1 (default: resume from the checkpoint)")
    add_quiet(r)
    r.set_defaults(func=_cmd_run)
    p = sub.add_parser("irradiance", help="photon pass: irradiance per triangle (npz + PNG)")
    p.add_argument("scene", help="Mitsuba XML scene or scenario TOML")
    add_photons(p, None, "(default: the scenario's light.photons, else "
                         f"{LIGHT['photons'].default})")
    p.add_argument("--seed", type=light_type("seed"),
                   help=f"random seed (default: the scenario's, else {LIGHT['seed'].default})")
    p.add_argument("--max-depth", type=light_type("max_depth"),
                   help="bounces per photon (default: the scenario's, else "
                        f"{LIGHT['max_depth'].default})")
    p.add_argument("--no-indirect", action="store_true", help="direct light only (paper fig 4.2)")
    p.add_argument("--when", metavar="ISO-DATETIME", type=iso_datetime,
                   help="daylight for the scenario's site at this time, e.g. "
                        "2026-04-20T10:00:00+09:00 (scenario .toml only)")
    add_set(p, "scenario")
    add_out(p, "out/irradiance", "irradiance.npz, PNG maps and summary.json")
    add_quiet(p)
    p.set_defaults(func=_cmd_irradiance)
    light_study.add_parser(sub)
    hemiphoto.add_parser(sub)
    grow.add_parser(sub)
    render.add_parsers(sub)
    tune.add_parser(sub)
    sweep.add_parser(sub)
    return ap


def main(argv=None) -> int:
    """Run the ``mitsuba-veg`` command.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code (0 done, 1 internal error, 2 bad input, 130 interrupted).
    """
    return run_parsed(build_parser().parse_args(argv))
