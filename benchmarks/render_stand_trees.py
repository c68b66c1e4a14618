"""The cost of drawing leaves as leaves, wood as wood and the litter: a forest stand's day at
1920 x 1080 (scene build and render), and the trees of the hectare (memory).

    python benchmarks/render_stand_trees.py RUN_DIR [--day 1030] [--spp 4] [--width 1920]
                                            [--height 1080] [--camera overview]
    python benchmarks/render_stand_trees.py --hectare [--fraction 0.25] ...

RUN_DIR is a forest-stand run (``mitsuba-veg run scenes/forest_stand/scenario.toml --out RUN_DIR
--days 1095``: the third year has about 470,000 leaves). Prints, as JSON: the leaves drawn and
the litter, triangles per leaf, the scene build's parts [s] (trees and litter meshes, Mitsuba's
load with the BVH), the render [s] at --spp, the process's peak memory [GiB], and the largest
relative difference between a drawn leaf's area and the light pass's blade area
(``WorldTree.leaf_area``). With ``--hectare`` the stand is the hectare's 300 aspens as the world
builds them on day 1 (``scenes/forest_hectare``, 6.7 million leaves; ``--fraction`` of them,
spread over the plot), in late October: half the leaves on the trees in their autumn colour,
half on the ground as litter of all ages (the most geometry a day can hold).
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _peak_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def _area_check(trees, cache) -> float:
    """Largest relative difference of drawn leaf area to 0.6 size² (the light pass's blade)."""
    from mitsuba_veg.render.leaves import LEAF_AREA, triangle_areas
    worst = 0.0
    for t in trees:
        _, leaves = cache[id(t)][1:]
        if leaves is None:
            continue
        v, f, k = leaves
        m = len(t.leaves)
        a = triangle_areas(v[: 50 * k].astype(float), f[: 50 * (len(f) // m)].astype(np.int64))
        a = a.reshape(min(m, 50), -1).sum(1)
        ref = LEAF_AREA * t.leaves.size[: min(m, 50)] ** 2
        worst = max(worst, float(np.max(np.abs(a / ref - 1))))
    return worst


def stand(run_dir, day, opts):
    from mitsuba_veg.render.history import load_run
    from mitsuba_veg.render.world import trees_for_run
    run = load_run(run_dir)
    day = run.final_day if day is None else int(day)
    t0 = time.perf_counter()
    trees, seasons = trees_for_run(run, None, day)
    date = run.date(day)
    for s in seasons:
        s.apply(date)
    t1 = time.perf_counter()
    frame = run.frame(min(day, run.final_day))
    return run.scenario, trees, date, frame.moss, run.moss_size, {"trees_from_run": t1 - t0,
                                                                  "day": day}


def hectare(fraction):
    import mitsuba as mi  # noqa: F401
    from mitsuba_veg.scenario import load_scenario
    from mitsuba_veg.world.trees import scenario_trees
    from mitsuba_veg.render.litter import LIFE_DAYS
    scn = load_scenario(ROOT / "scenes" / "forest_hectare" / "scenario.toml")
    t0 = time.perf_counter()
    built = scenario_trees(scn, scn.load_scene(daylight=False))
    rng = np.random.default_rng(0)
    keep = rng.random(len(built)) < fraction
    trees = [wt.tree for wt, k in zip(built, keep) if k and wt.tree is not None]
    for t in trees:            # late October: half coloured on the tree, half litter
        n = len(t.leaves)
        fell = rng.random(n) < 0.5
        t.leaves.attrs["autumn_tau"] = rng.uniform(0.3, 1.0, n)
        t.leaves.attrs["fallen"] = fell
        t.leaves.attrs["litter_age"] = np.where(fell, rng.uniform(0, LIFE_DAYS[0], n), np.nan)
    return scn, trees, dt.date(2026, 10, 25), None, 0.01, {
        "trees_from_scenario": time.perf_counter() - t0, "trees": len(trees)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", nargs="?")
    ap.add_argument("--day", type=int)
    ap.add_argument("--hectare", action="store_true")
    ap.add_argument("--fraction", type=float, default=1.0)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--camera", default="overview")
    ap.add_argument("--no-litter", action="store_true")
    ap.add_argument("--png", help="write the image here")
    a = ap.parse_args(argv)
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    from mitsuba_veg.render import film
    from mitsuba_veg.render.scene import RenderOptions, Terrain, build_scene
    from mitsuba_veg.render.still import render
    if a.hectare:
        scn, trees, date, moss, msize, rec = hectare(a.fraction)
    else:
        scn, trees, date, moss, msize, rec = stand(a.run_dir, a.day, a)
    rec["peak_after_trees_GiB"] = _peak_gib()
    terrain = Terrain.from_scenario(scn)
    opts = RenderOptions(width=a.width, height=a.height, spp=a.spp, camera=a.camera,
                         litter=not a.no_litter)
    cache = {}
    t0 = time.perf_counter()
    rs = build_scene(scn, moss, moss_size=msize, trees=trees, date=date, options=opts,
                     terrain=terrain, tree_cache=cache)
    rec["build_s"] = time.perf_counter() - t0
    rec["build_parts_s"] = rs.info["seconds"]
    rec["peak_after_build_GiB"] = _peak_gib()
    img = render(rs)
    rec["render_s"] = img["seconds"]
    rec["spp"] = opts.samples
    rec["size"] = [a.width, a.height]
    rec["peak_GiB"] = _peak_gib()
    from mitsuba_veg.render.leaves import leaf_template, leaf_shape_of
    rec["triangles_per_leaf"] = sorted({len(leaf_template(leaf_shape_of(t))[1]) for t in trees})
    for k in ("leaves", "litter", "tree_triangles", "litter_triangles", "triangles", "tufts"):
        rec[k] = rs.info.get(k)
    rec["leaf_area_max_rel_diff"] = _area_check(trees, cache)
    rec["date"] = date.isoformat()
    if a.png:
        rgb8, _ = film.to_srgb8(img["rgb"], None)
        film.write_png(a.png, rgb8)
    print(json.dumps(rec, indent=1, default=str))


if __name__ == "__main__":
    main()
