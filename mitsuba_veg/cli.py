"""The ``mitsuba-veg`` command.

    mitsuba-veg demo [--out DIR]                       the default scenario end to end
    mitsuba-veg irradiance SCENE [--photons N] [--out DIR] [--when ISO] [--no-indirect] ...
    mitsuba-veg run SCENARIO [--out DIR] [--days N] [--set KEY=VALUE ...] [--fresh]
    mitsuba-veg light-study SCENE [--out DIR] ...
    mitsuba-veg grow TREE.toml [--out DIR] [--set KEY=VALUE] [--seed S] [--generations G]
    mitsuba-veg sweep SWEEP.toml [--scheduler ADDRESS] [--workers N] [--out DIR]

SCENE is a Mitsuba XML file or a scenario TOML (which names the XML and the light settings).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

def _default_scenario() -> Path:
    """The shipped moss garden: from the source tree, else from the installed package data."""
    here = Path(__file__).resolve().parent
    for p in (here.parent / "scenes", here / "scenes"):
        if (p / "moss_garden" / "scenario.toml").exists():
            return p / "moss_garden" / "scenario.toml"
    raise SystemExit("mitsuba-veg: the shipped scenes are missing from this installation; "
                     "pass a scenario file explicitly")


DEFAULT_SCENARIO = None  # resolved lazily by _default_scenario()
#: a spring morning: the sun (~50 deg, south-east) leaves the back floor in the roof's shade
DEMO_WHEN = "2026-04-20T10:00:00+09:00"


from .outputs import write_json as _write_json  # noqa: E402


def versions() -> dict:
    import drjit
    import mitsuba
    import numpy
    import mitsuba_veg
    return {"mitsuba_veg": mitsuba_veg.__version__, "mitsuba": mitsuba.__version__,
            "drjit": drjit.__version__, "numpy": numpy.__version__, "variant": mitsuba.variant(),
            "python": sys.version.split()[0]}


def run_irradiance(scene_path, out, photons=None, seed=None, max_depth=None, indirect=None,
                   when=None, overrides=(), progress=True) -> dict:
    """Photon pass on a scene or scenario; writes irradiance.npz, PNG maps and summary.json."""
    import numpy as np
    import mitsuba as mi
    from .light import photon_irradiance
    from .plots import irradiance_figure
    from .scenario import load_scenario

    scene_path = Path(scene_path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    regions = {}
    ground = "ground"
    settings = {"photons": 1_000_000, "seed": 0, "max_depth": 8, "indirect": True}
    t0 = time.perf_counter()
    if scene_path.suffix.lower() == ".toml":
        ov = list(overrides)
        if when is not None:
            ov.append(f'light.when="{when}"')
        scn = load_scenario(scene_path, ov)
        scene = scn.load_scene()
        settings.update({k: scn.get(f"light.{k}") for k in settings})
        regions = scn.get("regions", {})
        ground = scn.get("terrain.ground", ground)
        when = scn.get("light.when")
    else:
        if not scene_path.exists():
            from .errors import ParameterError
            raise ParameterError("SCENE", str(scene_path), "an existing .xml or .toml file",
                                 "check the path")
        scene = mi.load_file(str(scene_path), optimize=False)
        if when is not None:
            raise SystemExit("--when needs a scenario (.toml) with a [site]: it replaces the "
                             "scene's emitters by daylight for that place")
    t_load = time.perf_counter() - t0
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
        if sid in res.index.geometry:
            pngs.append(irradiance_figure(res, sid, out / f"irradiance_{sid}.png"))
    shapes = {}
    for sid in res.index.shape_ids:
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
    _write_json(out / "summary.json", summary)
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
    from .simulation import run
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
    from .simulation import run
    out = Path(a.out)
    scen = _default_scenario()
    print(f"mitsuba-veg demo 1/3: light study of the moss garden (paper 000 test scene) under "
          f"daylight on {DEMO_WHEN} -> {out / 'light'}/")
    s = run_irradiance(scen, out / "light", photons=a.photons, when=DEMO_WHEN,
                       progress=not a.quiet)
    _report(s)
    print(f"\nmitsuba-veg demo 2/3: {a.days} days of moss in the garden (paper 000) -> "
          f"{out / 'moss'}/")
    m = run(scen, out=out / "moss", days=a.days, progress=not a.quiet)
    f = m["final"]
    print(f"{a.days} days: {f['moss_alive']} moss alive, covered {f['covered_area_m2']:.3f} m2"
          + "".join(f"; {k} {v['covered_area_m2']:.3f} m2" for k, v in f["regions"].items()))
    print("wrote:")
    for p in (out / "moss" / "summary.json", m.get("files", {}).get("animation"),
              out / "moss" / "maps"):
        if p:
            print(f"  {p}")
    from .render.cli import run_animate, run_render
    print(f"\nmitsuba-veg demo 3/3: spectral render and animation -> "
          f"{out / 'moss' / 'render'}/, {out / 'moss' / 'animation'}/")
    r = run_render(out / "moss", progress=not a.quiet)
    an = run_animate(out / "moss", progress=not a.quiet)
    print("wrote:")
    for cam in r["files"].values():
        for p in cam.values():
            print(f"  {p}")
    for k in ("mp4", "gif"):
        if an["files"].get(k):
            print(f"  {an['files'][k]}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="mitsuba-veg",
                                 description="Grow vegetation from light with Mitsuba 3.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("demo", help="run the default scenario end to end")
    d.add_argument("--out", default="out/demo")
    d.add_argument("--photons", type=int, default=4_000_000,
                   help="photons of the light study (the moss run uses the scenario's)")
    d.add_argument("--days", type=int, default=300, help="days of the moss run")
    d.add_argument("--quiet", action="store_true")
    d.set_defaults(func=_cmd_demo)
    r = sub.add_parser("run", help="run a moss scenario day by day (paper 000)")
    r.add_argument("scenario", help="scenario TOML, e.g. scenes/moss_garden/scenario.toml")
    r.add_argument("--out", default="out/run")
    r.add_argument("--days", type=int, help="simulated days (default: the scenario's)")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario field, e.g. --set light.indirect=false")
    r.add_argument("--fresh", action="store_true",
                   help="ignore a checkpoint in --out and start from day 1")
    r.add_argument("--quiet", action="store_true")
    r.set_defaults(func=_cmd_run)
    p = sub.add_parser("irradiance", help="photon pass: irradiance per triangle (npz + PNG)")
    p.add_argument("scene", help="Mitsuba XML scene or scenario TOML")
    p.add_argument("--photons", type=int)
    p.add_argument("--seed", type=int)
    p.add_argument("--max-depth", type=int)
    p.add_argument("--no-indirect", action="store_true", help="direct light only (paper fig 4.2)")
    p.add_argument("--when", help="ISO date-time: daylight for the scenario's site (TOML only)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario field, e.g. --set light.photons=2000000")
    p.add_argument("--out", default="out/irradiance")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_irradiance)
    from .foliage.light_study import add_parser as _add_light_study
    _add_light_study(sub)
    from .trees.grow_cli import add_parser as _add_grow
    _add_grow(sub)
    from .render.cli import add_parsers as _render_parsers
    _render_parsers(sub)
    from .tune.cli import add_parser as _add_tune
    _add_tune(sub)
    from .sweeps.cli import add_parser as _add_sweep
    _add_sweep(sub)
    return run_parsed(ap.parse_args(argv))


def run_parsed(a) -> int:
    """Run a parsed command: a library error becomes one line on stderr and exit code 2."""
    from .errors import MitsubaVegError
    import mitsuba_veg  # noqa: F401  (variant + plugins)
    try:
        return a.func(a)
    except MitsubaVegError as e:
        print(f"mitsuba-veg: error: {e}", file=sys.stderr)
        return 2


def standalone(command: str, add_parser, argv=None) -> int:
    """Entry of one sub-command run on its own (``python -m ...``): ``argv`` without the
    command's name."""
    ap = argparse.ArgumentParser(prog="mitsuba-veg")
    add_parser(ap.add_subparsers(dest="cmd", required=True))
    return run_parsed(ap.parse_args([command, *(sys.argv[1:] if argv is None else argv)]))


if __name__ == "__main__":
    sys.exit(main())
