"""The render page's and README's lead image: a forest-stand run in its tenth autumn on an
afternoon, seen from the plot's north-east corner into the stand, under the crowns.

    mitsuba-veg run scenes/forest_stand/scenario.toml --out out/stand --days 3650   # ~40 min
    python experiments/render_hero.py out/stand --day 3570 --out docs/images/render_hero_stand.jpg

The view is added to the loaded scenario as ``[render.cameras.edge]`` (the same table in a
scenario file gives ``mitsuba-veg render --camera edge``); ``--origin``/``--target`` move it
(heights above the ground there), ``--ev`` sets the exposure in stops about the automatic one.
"""
from __future__ import annotations

import argparse
from pathlib import Path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir")
    ap.add_argument("--day", type=int, help="default: the last")
    ap.add_argument("--hour", type=float, default=15.0, help="local hour of the light (15)")
    ap.add_argument("--origin", default="12.0,-0.6,-19.0", help="x,dy,z: dy above the ground [m]")
    ap.add_argument("--target", default="9.0,0.0,-7.0", help="x,dy,z: dy above the ground [m]")
    ap.add_argument("--eye", type=float, default=1.7, help="eye height [m] (1.7)")
    ap.add_argument("--fov", type=float, default=58.0)
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--scenario", default="scenes/forest_stand/scenario.toml")
    ap.add_argument("--ev", type=float, default=-0.6,
                    help="exposure in stops about the automatic one (-0.6)")
    ap.add_argument("--out", default="docs/images/render_hero_stand.jpg")
    a = ap.parse_args(argv)
    import numpy as np
    import mitsuba_veg  # noqa: F401
    from PIL import Image
    from mitsuba_veg.render import cameras, film, history, scene as S, still
    from mitsuba_veg.render.world import trees_for_run

    run = history.load_run(a.run_dir, a.scenario)
    day = run.final_day if a.day is None else a.day
    fr = run.frame(day)
    terrain = S.Terrain.from_scenario(run.scenario)
    ox, oy, oz = (float(v) for v in a.origin.split(","))
    tx, ty, tz = (float(v) for v in a.target.split(","))
    lo, hi = terrain.ground_bbox()

    def gy(x, z):       # the ground's height there (at the nearest point of the plot outside it)
        return cameras._ground_y(terrain, min(max(x, lo[0]), hi[0]), min(max(z, lo[2]), hi[2]),
                                 0.0)
    origin = [ox, gy(ox, oz) + a.eye + oy, oz]
    target = [tx, gy(tx, tz) + a.eye * 0.6 + ty, tz]
    run.scenario.data.setdefault("render", {}).setdefault("cameras", {})["edge"] = {
        "origin": origin, "target": target, "fov": a.fov}
    trees, seasons = trees_for_run(run, None, day)
    for s in seasons:
        s.apply(fr.date)
    o = S.RenderOptions(width=a.width, height=a.height, spp=a.spp, camera="edge", hour=a.hour)
    rs = S.build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=trees,
                       date=fr.date, options=o, terrain=terrain)
    im = still.render(rs)
    img8, _ = film.to_srgb8(im["display"],
                            film.auto_exposure(np.asarray(im["display"])) * 2.0 ** a.ev)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.asarray(img8)).save(a.out, quality=90)
    print(f"{a.out}: day {day} ({fr.date}) {rs.info['when']}, camera {origin} -> {target}; "
          f"{rs.info['leaves']:,} leaves, {len(fr.moss):,} moss, render {im['seconds']:.0f} s")


if __name__ == "__main__":
    main()
