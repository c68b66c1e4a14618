"""A stand's year of ageing on one thread and on all the machine's cores (``map_on_cores``).

    python benchmarks/tree_ageing.py [--trees 300] [--reps 3]

The year's end of a world ages every Weber-Penn tree that has an ``age`` by one year
(:func:`mitsuba_veg.world.trees.age_tree`: the meshes scaled about the base, then the crown's
radius). ``--trees`` quaking aspens (three variants, 12 m, aged 20, wood as tubes like a
``[stand]``'s, the hectare's trees) are aged one year on one thread and with
:func:`~mitsuba_veg.parallel.map_on_cores` (a thread per core), interleaved per repetition;
printed: the median times and their ratio, the cores, and whether the results are identical
(wood, blades, leaf areas, crown radii; they must be).
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trees", type=int, default=300)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args(argv)
    import mitsuba as mi

    import mitsuba_veg  # noqa: F401  (sets the variant)
    from mitsuba_veg.parallel import map_on_cores
    from mitsuba_veg.world.trees import age_tree, build_trees

    scene = mi.load_dict({"type": "scene"})
    ents = [{"name": f"v{i}", "model": "weber_penn", "preset": "quaking_aspen", "seed": i,
             "height": 12.0, "age": 20, "position": [i * 3.0, 0.0, 0.0]} for i in range(3)]
    variants = build_trees(ents, scene, ROOT)
    for v in variants:
        v.info["bark"] = "tubes"
    trees = [variants[i % 3] for i in range(a.trees)]

    def one(wt):
        t = age_tree(wt, 1)
        return t, t.crown_radius()

    seq, par = [], []
    for _ in range(a.reps):
        t0 = time.perf_counter()
        r1 = [one(w) for w in trees]
        seq.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        r2 = map_on_cores(one, trees)
        par.append(time.perf_counter() - t0)
        same = all(np.array_equal(x[0].bark[0], y[0].bark[0])
                   and np.array_equal(x[0].leaf_vertices, y[0].leaf_vertices)
                   and np.array_equal(x[0].leaf_area, y[0].leaf_area) and x[1] == y[1]
                   for x, y in zip(r1, r2))
        if not same:
            print("map_on_cores gave other results than one thread")
            return 1
        del r1, r2
    leaves = sum(len(t.leaf_area) for t in trees)
    s, p = statistics.median(seq), statistics.median(par)
    print(f"{a.trees} aspens ({leaves:,d} leaves) aged one year, {os.cpu_count()} cores: one "
          f"thread {s:.2f} s, map_on_cores {p:.2f} s (median of {a.reps}): ratio {s / p:.2f}; "
          "the results identical")
    from _record import Recorder
    rec = Recorder("tree_ageing", notes=f"{a.trees} Weber-Penn aspens ({leaves:,d} leaves) aged "
                   f"one year; median of {a.reps}; results identical")
    rec.add("one_thread_s", s, "s", "one thread")
    rec.add("map_on_cores_s", p, "s", "map_on_cores (a thread per core)")
    rec.add("speedup", s / p, "ratio", "map_on_cores vs one thread")
    rec.write()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
