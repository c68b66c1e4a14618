"""Does the render show the moss the run grew? Drawn against simulated cover per ground triangle.

A run's day rendered from straight above (the ``top`` preset); per ground triangle the share of
its pixels that show moss (red/far-red NDVI > 0.45, :mod:`mitsuba_veg.render.fidelity`) against
the run's cover ``min(n size² / area, 1)``. Printed: the drawn / simulated moss area (target
0.8-1.25) and the mean absolute difference over the mossy triangles (target <= 0.1), for the NDVI
pixels and for the geometric cover (pixels whose ray meets moss first: the same without the
render's noise).

    python benchmarks/render_moss_cover.py out/demo/world                  # the courtyard's year
    python benchmarks/render_moss_cover.py RUN_DIR --scenario TOML --no-litter   # a forest floor

The courtyard's run is ``make demo``'s (``out/demo/world``). Litter hides moss as it does in a
real forest: ``--no-litter`` switches it off for the comparison. ``--spp`` sets the samples per
pixel of the NDVI render (the bands get about a sixth of the wavelength samples each, so the
per-pixel NDVI needs a few dozen).

A forest floor's moss grows in scattered 5-cm cells: from straight above the whole 30-m stand
at 2560 px a cell spans 4 pixels, and its edge pixels mix moss with soil (a pixel reads as moss
by NDVI only above 55-80 % moss, by species and soil). ``--tiles N`` measures the floor where a
cell is resolved instead: N squares of ``--tile-m`` metres, each seen straight down from the
``top`` preset's height at ``--width`` pixels, centred on moss picked at random in proportion
to the simulated moss area (so that every square metre of moss is as likely to be looked at,
and the squares do not overlap); the pixel counts of the views are pooled per triangle.

    python benchmarks/render_moss_cover.py RUN_DIR --scenario TOML --no-litter --tiles 6
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def tile_views(scn, terrain, moss, trees, sim, area, v, f, n: int, side: float, seed: int):
    """``n`` squares of the ground, ``side`` metres, centred on triangles picked at random in
    proportion to their simulated moss area, none overlapping another (module docstring)."""
    w = sim * area
    if w.sum() <= 0:
        raise SystemExit("no simulated moss on the ground: nothing to look at")
    cen = np.asarray(v, float)[np.asarray(f, np.int64)].mean(1)
    from mitsuba_veg.render.cameras import presets
    rng = np.random.default_rng(seed)
    top = presets(scn, terrain, moss, trees)["top"]
    views = []
    for i in rng.choice(len(w), size=min(50 * n, int((w > 0).sum()) * 4), p=w / w.sum()):
        c = cen[i]
        if all(max(abs(c[0] - u["centre"][0]), abs(c[2] - u["centre"][2])) >= side
               for u in views):
            h = float(top["origin"][1]) - float(c[1])
            views.append({"centre": c, "origin": [float(c[0]), float(top["origin"][1]),
                                                  float(c[2]) + 1e-4],
                          "target": [float(c[0]), float(c[1]), float(c[2])],
                          "up": [0.0, 0.0, -1.0], "fov_axis": "x",
                          "fov": float(np.degrees(2 * np.arctan(0.5 * side / h)))})
            if len(views) == n:
                break
    return views


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir", nargs="?", default="out/demo/world")
    ap.add_argument("--scenario", help="the run's scenario file (default: the summary's)")
    ap.add_argument("--day", type=int, help="the day (default: the last)")
    ap.add_argument("--width", type=int, default=1024, help="image side [px] (default 1024)")
    ap.add_argument("--spp", type=int, default=64, help="samples per pixel (default 64)")
    ap.add_argument("--no-litter", action="store_true", help="no fallen leaves on the floor")
    ap.add_argument("--tiles", type=int, default=0,
                    help="views of N squares of the floor centred on moss, pooled (module "
                    "docstring); 0: one view of the whole terrain (default)")
    ap.add_argument("--tile-m", type=float, default=4.0, help="side of a square [m] (default 4)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the squares' choice")
    ap.add_argument("--png", help="write the render and the moss masks here (a PNG)")
    ap.add_argument("--json", help="write the figures here")
    ap.add_argument("--record", help="suffix of the results file (default: the scenario's "
                    "folder name: render_moss_cover_courtyard.json)")
    a = ap.parse_args(argv)
    if not (Path(a.run_dir) / "summary.json").is_file():
        raise SystemExit(f"{a.run_dir}: no run folder (make demo writes out/demo/world)")

    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.render import fidelity, film, history, scene as S, still
    from mitsuba_veg.render.world import trees_for_run

    run = history.load_run(a.run_dir, a.scenario)
    day = run.final_day if a.day is None else a.day
    fr = run.frame(day)
    trees, seasons = trees_for_run(run, None, day)
    for s in seasons:
        s.apply(fr.date)
    terrain = S.Terrain.from_scenario(run.scenario)
    kw = {"litter": False} if a.no_litter and "litter" in S.RenderOptions.__dataclass_fields__ \
        else {}
    opts = S.RenderOptions(width=a.width, height=a.width, spp=a.spp, camera="top",
                           denoise=False, **kw)
    v, f = terrain.meshes["ground"][:2]
    area = fidelity.triangle_areas(v, f)
    sim = fidelity.simulated_cover(terrain, fr.moss, run.moss_size)
    views = [None] if a.tiles <= 0 else tile_views(run.scenario, terrain, fr.moss, trees, sim,
                                                   area, v, f, a.tiles, a.tile_m, a.seed)
    counts, rows, seconds, build = None, [], 0.0, 0.0
    for k, view in enumerate(views):
        o = opts
        if view is not None:     # a camera of its own for the square (a scene built for it)
            run.scenario.data.setdefault("render", {}).setdefault("cameras", {})["square"] = {
                n: view[n] for n in ("origin", "target", "up", "fov", "fov_axis")}
            o = replace(opts, camera="square")
        t0 = time.perf_counter()
        rv = S.build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=trees,
                           date=fr.date, options=o, terrain=terrain)
        build += time.perf_counter() - t0
        im = still.render(rv)
        seconds += im["seconds"]
        c = fidelity.cover_counts(rv, im)
        counts = c if counts is None else {n: counts[n] + c[n] for n in counts}
        if view is not None:
            one = fidelity.cover_summary(c, sim, area)
            print(f"  view {k + 1}/{len(views)} at x {view['centre'][0]:.2f} z "
                  f"{view['centre'][2]:.2f}: NDVI {one['area_ratio']:.3f}, geometric "
                  f"{one['geometric_area_ratio']:.3f} over {one['compared']} triangles "
                  f"({im['seconds']:.0f} s)", flush=True)
        if a.png:
            on_moss = fidelity.pixel_triangles(rv)[2]
            img8, _ = film.to_srgb8(im["rgb"])
            masks = [np.stack([m.astype(np.uint8) * 255] * 3, -1)
                     for m in (fidelity.moss_pixels(im), on_moss)]
            rows.append(np.concatenate([img8, *masks], 1))
    c = fidelity.cover_summary(counts, sim, area)
    what = "whole terrain" if a.tiles <= 0 else \
        f"{len(views)} squares of {a.tile_m:g} m at {a.width} px"
    out = {"run": str(run.dir), "day": day, "date": fr.date.isoformat(), "moss": len(fr.moss),
           "moss_size_m": run.moss_size, "width": a.width, "spp": a.spp, "views": what,
           "litter": not a.no_litter, "build_s": build, "render_s": seconds,
           "simulated_m2": c["simulated_m2"], "rendered_m2": c["rendered_m2"],
           "area_ratio_ndvi": c["area_ratio"], "mad_mossy_ndvi": c["mad_mossy"],
           "area_ratio_geometric": c["geometric_area_ratio"],
           "mad_mossy_geometric": c["geometric_mad_mossy"],
           "mossy_triangles": c["mossy"], "compared_triangles": c["compared"]}
    print(f"{run.dir} day {day} ({fr.date}): {len(fr.moss):,d} moss, {what}, {a.width}x"
          f"{a.width} at {a.spp} spp (build {build:.1f} s, render {seconds:.1f} s)")
    print(f"  simulated moss on the ground {c['simulated_m2']:.3f} m2 over "
          f"{c['mossy']} mossy of {c['compared']} triangles compared")
    for name, r, m in (("NDVI > 0.45", c["area_ratio"], c["mad_mossy"]),
                       ("geometric", c["geometric_area_ratio"], c["geometric_mad_mossy"])):
        ok = "ok" if 0.8 <= r <= 1.25 and m <= 0.1 else "MISSED"
        print(f"  {name:12s} drawn / simulated area {r:5.3f} (target 0.8-1.25), mean |diff| "
              f"over mossy triangles {m:5.3f} (target <= 0.1)  {ok}")
    if a.png:
        film.write_png(a.png, np.concatenate(rows, 0))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    from _record import Recorder
    name = "render_moss_cover_" + (a.record or Path(run.scenario.path).parent.name)
    rec = Recorder(name, notes=f"{run.dir.name}, day {day} ({fr.date}), {len(fr.moss):,d} moss, "
                   f"top view{'s' if a.tiles > 0 else ''} ({what}) {a.width}x{a.width} at "
                   f"{a.spp} spp"
                   + (", litter off" if a.no_litter else ""))
    rec.add("area_ratio_ndvi", c["area_ratio"], "ratio",
            "drawn / simulated moss area on the ground, pixels with NDVI > 0.45 (target 0.8-1.25)")
    rec.add("mad_mossy_ndvi", c["mad_mossy"], "cover",
            "mean |drawn - simulated| cover over mossy triangles, NDVI (target <= 0.1)")
    rec.add("area_ratio_geometric", c["geometric_area_ratio"], "ratio",
            "drawn / simulated moss area, pixels whose ray meets moss first")
    rec.add("mad_mossy_geometric", c["geometric_mad_mossy"], "cover",
            "mean |drawn - simulated| cover over mossy triangles, geometric")
    rec.add("simulated_m2", c["simulated_m2"], "m2", "simulated moss area on the compared ground")
    rec.write()
    return out


if __name__ == "__main__":
    main()
