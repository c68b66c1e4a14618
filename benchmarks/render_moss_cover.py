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
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir", nargs="?", default="out/demo/world")
    ap.add_argument("--scenario", help="the run's scenario file (default: the summary's)")
    ap.add_argument("--day", type=int, help="the day (default: the last)")
    ap.add_argument("--width", type=int, default=1024, help="image side [px] (default 1024)")
    ap.add_argument("--spp", type=int, default=64, help="samples per pixel (default 64)")
    ap.add_argument("--no-litter", action="store_true", help="no fallen leaves on the floor")
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
    t0 = time.perf_counter()
    rs = S.build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=trees,
                       date=fr.date, options=opts, terrain=terrain)
    t1 = time.perf_counter()
    im = still.render(rs)
    c = fidelity.cover_comparison(rs, im, fr.moss, run.moss_size)
    out = {"run": str(run.dir), "day": day, "date": fr.date.isoformat(), "moss": len(fr.moss),
           "moss_size_m": run.moss_size, "width": a.width, "spp": a.spp,
           "litter": not a.no_litter, "build_s": t1 - t0, "render_s": im["seconds"],
           "simulated_m2": c["simulated_m2"], "rendered_m2": c["rendered_m2"],
           "area_ratio_ndvi": c["area_ratio"], "mad_mossy_ndvi": c["mad_mossy"],
           "area_ratio_geometric": c["geometric_area_ratio"],
           "mad_mossy_geometric": c["geometric_mad_mossy"],
           "mossy_triangles": c["mossy"], "compared_triangles": c["compared"]}
    print(f"{run.dir} day {day} ({fr.date}): {len(fr.moss):,d} moss, {a.width}x{a.width} at "
          f"{a.spp} spp (build {t1 - t0:.1f} s, render {im['seconds']:.1f} s)")
    print(f"  simulated moss on the ground {c['simulated_m2']:.3f} m2 over "
          f"{c['mossy']} mossy of {c['compared']} triangles compared")
    for name, r, m in (("NDVI > 0.45", c["area_ratio"], c["mad_mossy"]),
                       ("geometric", c["geometric_area_ratio"], c["geometric_mad_mossy"])):
        ok = "ok" if 0.8 <= r <= 1.25 and m <= 0.1 else "MISSED"
        print(f"  {name:12s} drawn / simulated area {r:5.3f} (target 0.8-1.25), mean |diff| "
              f"over mossy triangles {m:5.3f} (target <= 0.1)  {ok}")
    if a.png:
        tri, clear, on_moss = fidelity.pixel_triangles(rs)
        img8, _ = film.to_srgb8(im["rgb"])
        ndvi = fidelity.moss_pixels(im)
        masks = np.concatenate([np.stack([ndvi * 255] * 3, -1), np.stack([on_moss * 255] * 3,
                                                                          -1)], 1)
        film.write_png(a.png, np.concatenate([np.concatenate([img8, img8], 1),
                                              masks.astype(np.uint8)], 0))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    from _record import Recorder
    name = "render_moss_cover_" + (a.record or Path(run.scenario.path).parent.name)
    rec = Recorder(name, notes=f"{run.dir.name}, day {day} ({fr.date}), {len(fr.moss):,d} moss, "
                   f"top view {a.width}x{a.width} at {a.spp} spp"
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
