"""Weber-Penn generation and meshing time and triangle counts per preset.

    .venv/bin/python benchmarks/weber_penn_generation.py [--repeat 3] [--seed 1]

For each preset: the median time to grow the tree (``generate``, knots on), to build the bark
mesh with smoothed junctions (paper 004 §4) and the leaf mesh, and the counts (stems, segments,
knots, leaves, bark and leaf triangles). The peer figures are the ones Blender's Sapling Tree
Gen (the maintained 0.4.0 fork, README "Performance": Blender 5.2.2, Windows, 24 logical cores)
reports for its own presets; its weeping_willow / douglas_fir / japanese_maple are Sapling
parameter sets, not the 1995 ones, so compare time per leaf rather than per preset name.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mitsuba_veg.trees import weber_penn as wp  # noqa: E402

PEER = [  # (preset, leaves, seconds) from the Sapling 0.4.0 README table (median of runs)
    ("callistemon", 9588, 0.086), ("douglas_fir", 52454, 0.727),
    ("japanese_maple", 106800, 1.934), ("quaking_aspen", 882, 0.012),
    ("small_maple", 36290, 0.516), ("small_pine", 48607, 0.600),
    ("weeping_willow", 62340, 0.592), ("white_birch", 18918, 0.310), ("willow", 1328, 0.048),
]


def timed(fn, repeat):
    ts, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", default=None, help="also write the results as JSON")
    args = ap.parse_args(argv)
    wp.mesh(wp.generate({"preset": "quaking_aspen", "Levels": 2}, seed=0))   # warm imports
    rows = []
    print(f"Weber-Penn generation on {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} logical cores, Python {platform.python_version()}, "
          f"median of {args.repeat}")
    hdr = (f"{'preset':15s} {'grow s':>7s} {'mesh s':>7s} {'stems':>7s} {'segments':>8s} "
           f"{'knots':>6s} {'leaves':>8s} {'bark tris':>10s} {'leaf tris':>10s} "
           f"{'us/leaf':>8s}")
    print(hdr)
    for name in wp.PRESETS:
        tg, tree = timed(lambda: wp.generate(name, seed=args.seed), args.repeat)
        tm, (bark, leaves) = timed(lambda: wp.mesh(tree, smooth=True), args.repeat)
        st = tree.weber_penn.stats
        r = {"preset": name, "generate_s": tg, "mesh_s": tm, "stems": st["stems"],
             "segments": len(tree), "knots": st["knots"], "leaves": len(tree.leaves),
             "bark_triangles": len(bark.faces), "leaf_triangles": len(leaves.faces)}
        rows.append(r)
        per_leaf = 1e6 * tg / max(r["leaves"], 1)
        print(f"{name:15s} {tg:7.3f} {tm:7.3f} {r['stems']:7d} {r['segments']:8d} "
              f"{r['knots']:6d} {r['leaves']:8d} {r['bark_triangles']:10d} "
              f"{r['leaf_triangles']:10d} {per_leaf:8.2f}")
    print("\nPeer: Blender Sapling Tree Gen 0.4.0 (README 'Performance'; Blender 5.2.2, "
          "Windows, 24 logical cores),\ntime to generate each of its presets with leaves:")
    for name, leaves, s in PEER:
        print(f"  {name:15s} {leaves:8d} leaves {s:6.3f} s  ({1e6 * s / leaves:5.2f} us/leaf)")
    print("  -> about 1-2 s for 50k-100k leaves (6-18 us per leaf).")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    from _record import Recorder
    rec = Recorder("weber_penn_generation", notes=f"median of {args.repeat}; peer: Blender "
                   "Sapling Tree Gen 0.4.0, 6-18 µs per leaf for 50k-100k leaves")
    for r in rows:
        rec.add(f"{r['preset']}_generate_s", r["generate_s"], "s",
                f"{r['preset']}: generate ({r['leaves']:,d} leaves)")
        rec.add(f"{r['preset']}_us_per_leaf", 1e6 * r["generate_s"] / max(r["leaves"], 1),
                "µs", f"{r['preset']}: generation per leaf")
        rec.add(f"{r['preset']}_mesh_s", r["mesh_s"], "s", f"{r['preset']}: meshing (smooth)")
    rec.write()
    return rows


if __name__ == "__main__":
    main()
