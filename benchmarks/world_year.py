"""A year of the courtyard world with 117,636 leaves: the per-day split of the time.

    python benchmarks/world_year.py [--days 365] [--photons 1000000] [--start YYYY-MM-DD]
                                    [--out out/bench/world]

The courtyard scenario plus a Weber-Penn sassafras and a second aspen brings the leaf count to
117,636 (235,272 leaf triangles; the issue's target is 100,000 and more). Prints the leaf
count, the time per day of light (the photon pass), leaves (phenology, the leaf tables and
mesh updates, per-leaf light), soil and moss, the leaves' share of a day, the whole year's wall
and CPU time with the machine's load average, the same split over the days with leaves on the
trees, and the leaf mesh's vertex updates.
"""
from __future__ import annotations

import argparse
import os
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

[[trees]]
name = "aspen_south"
model = "weber_penn"
preset = "quaking_aspen"
position = [-1.6, 0.0, 2.6]
height = 4.5
seed = 11
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--days", type=int, default=365)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--out", default="out/bench/world")
    ap.add_argument("--start", default=None, help="start date YYYY-MM-DD (default: the "
                    "scenario's 1 March); e.g. 2026-07-01 to time days in full leaf")
    a = ap.parse_args(argv)
    import mitsuba_veg as mv
    tmp = Path(tempfile.mkdtemp())
    scen = tmp / "courtyard"
    shutil.copytree(ROOT / "scenes" / "courtyard", scen)
    text = (scen / "scenario.toml").read_text()
    text = text.replace("[phenology]", EXTRA + "\n[phenology]", 1)
    (scen / "scenario.toml").write_text(text)
    load0 = os.getloadavg()
    c0 = time.process_time()
    t0 = time.perf_counter()
    s = mv.run(scen / "scenario.toml", out=a.out, days=a.days, resume=False,
               overrides=[f"light.photons={a.photons}"]
               + ([f'simulation.start_date="{a.start}"'] if a.start else []),
               progress=True, frames=False)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    load1 = os.getloadavg()
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
    print(f"whole run: {wall:.0f} s wall ({wall / 60:.1f} min); target < 5 min for 365 days; "
          f"process CPU time {cpu:.0f} s ({cpu / wall:.2f} of one core on average, "
          f"{os.cpu_count()} cores); 1-min load average {load0[0]:.1f} at the start, "
          f"{load1[0]:.1f} at the end (load from other processes slows the wall time)")
    if "leaf_mesh_updates" in s["world"]:
        print(f"leaf mesh: {s['world']['leaf_triangles']:,d} triangles, "
              f"{s['world']['leaf_mesh_updates']} vertex updates (leaf-out growth, fallen "
              f"blades collapsed); stage and fall changes are per-triangle tables")
    from _record import Recorder
    rec = Recorder("world_year", notes=f"the courtyard plus a sassafras and a second aspen "
                   f"({leaves:,d} leaves), {a.photons:,d} photons a day, {a.days} days")
    rec.add("run_s", wall, "s", f"{a.days} days of the world, wall time")
    rec.add("cpu_cores_used", cpu / wall, "", "process CPU time ÷ wall time")
    t = {k: float(np.mean([r["seconds"].get(k, 0.0) for r in recs])) for k in keys}
    for k in keys:
        rec.add(f"{k}_ms", t[k] * 1e3, "ms", f"{k} per day (mean)")
    rec.add("leaves_share", t["leaves"] / sum(t.values()), "fraction", "leaves' share of a day")
    rec.write()
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
