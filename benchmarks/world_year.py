"""A year of the courtyard world with about 94,000 leaves: the per-day split of the time.

    python benchmarks/world_year.py [--days 365] [--photons 1000000] [--out out/bench/world]

The courtyard scenario plus a Weber-Penn sassafras brings the leaf count to 93,785 (the issue's
target is 100,000 and more: add a tree for that). Prints the leaf count, the time per day of light (the photon pass), leaves
(phenology, canopy meshes, per-leaf light), soil and moss, the leaves' share of a day, the
whole year's wall time, and the same split over the days with leaves on the trees.
"""
from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
EXTRA = """
[[trees]]
name = "sassafras"
model = "weber_penn"
preset = "sassafras"
position = [2.4, 0.0, 0.8]
height = 5.5
seed = 5
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--days", type=int, default=365)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--out", default="out/bench/world")
    a = ap.parse_args(argv)
    import mitsuba_veg as mv
    tmp = Path(tempfile.mkdtemp())
    scen = tmp / "courtyard"
    shutil.copytree(ROOT / "scenes" / "courtyard", scen)
    text = (scen / "scenario.toml").read_text()
    text = text.replace("[phenology]", EXTRA + "\n[phenology]", 1)
    (scen / "scenario.toml").write_text(text)
    t0 = time.perf_counter()
    s = mv.run(scen / "scenario.toml", out=a.out, days=a.days, resume=False,
               overrides=[f"light.photons={a.photons}"], progress=True, frames=False)
    wall = time.perf_counter() - t0
    recs = s["days_record"]
    leaves = s["world"]["leaf_elements"]
    keys = ("light", "leaves", "soil", "moss")
    print(f"world: {len(s['world']['trees'])} trees, {leaves:,d} leaves, {a.days} days at "
          f"{a.photons:,d} photons/day; set-up {s['timings_s']['setup']:.1f} s "
          f"(trees built in {s['world']['trees_built_s']:.1f} s)")

    def split(rs, label):
        if not rs:
            return
        t = {k: float(np.mean([r["seconds"].get(k, 0.0) for r in rs])) for k in keys}
        day = sum(t.values())
        print(f"{label} ({len(rs)} days): " + ", ".join(f"{k} {v * 1e3:.0f} ms" for k, v in
                                                          t.items())
              + f"; leaves {100 * t['leaves'] / day:.1f} % of a day of {day:.2f} s")
    split(recs, "all days")
    split([r for r in recs if any(v["leaves_on_tree"] for v in r["trees"].values())],
          "days with leaves")
    print(f"whole run: {wall:.0f} s wall ({wall / 60:.1f} min); target < 5 min for 365 days")
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
