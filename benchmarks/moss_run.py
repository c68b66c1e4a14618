"""Moss scenario performance: a 300-day moss-garden run and the population update at 1M moss.

(a) 300 days at 1,000,000 photons/day and the paper's capacity 16,384: total wall time and the
    split light / soil / moss per day (target: under 5 minutes on a 2-core machine);
(b) capacity 1,000,000 (900,000 moss placed at the start, 1.5 mm spots): time of the soil + moss
    update against the whole day (light at 1M photons included), while the population fills
    and once it is full - target under 10 %.

    python benchmarks/moss_run.py [--days 300] [--skip-a] [--skip-b]
"""
import argparse
import time
from pathlib import Path

import numpy as np

import mitsuba_veg as mv
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.daily import Simulation

from _record import Recorder

SCEN = Path(__file__).resolve().parent.parent / "scenes" / "moss_garden" / "scenario.toml"


def part_a(days, out, recorder):
    t = time.perf_counter()
    s = mv.run(SCEN, out=out, days=days, resume=False, progress=False, frames=True,
               overrides=["light.photons=1000000"])
    total = time.perf_counter() - t
    per = s["timings_s"]["per_day"]
    day = per["light"] + per["soil"] + per["moss"]
    print(f"(a) {days} days, 1M photons/day, capacity 16384: {total:.1f} s total "
          f"({total / 60:.2f} min; target < 5 min -> {'met' if total < 300 else 'NOT met'})")
    print(f"    per day: light {per['light']:.3f} s ({per['light'] / day:.0%}), soil "
          f"{per['soil'] * 1e3:.2f} ms, moss {per['moss'] * 1e3:.1f} ms; outputs "
          f"{s['timings_s']['output']:.1f} s in all; final {s['final']['moss_alive']} moss")
    recorder.add("garden_run_s", total, "s", f"{days}-day moss-garden run, 1M photons a day, capacity "
            "16,384 (outputs included)")
    recorder.add("garden_light_s", per["light"], "s", "light per day (garden run)")
    recorder.add("garden_soil_ms", per["soil"] * 1e3, "ms", "soil per day (garden run)")
    recorder.add("garden_moss_ms", per["moss"] * 1e3, "ms", "moss per day (garden run)")
    recorder.add("garden_outputs_s", s["timings_s"]["output"], "s",
            "maps and checkpoints in all (garden run)")


def part_b(out, recorder, capacity=1_000_000, initial=900_000, days=20):
    """Soil + moss update against the whole day at a million individuals.

    900,000 moss placed at random (1.5 mm spots) fill the 1,000,000 slots within a few days:
    while they fill (days 2-7) up to ~100,000 newcomers a day are landed, settled and added and
    ~80,000 propagules germinate; once the population is full (days 8-19: the steady state of a
    capacity-bound run, and of the paper's runs after day ~130) every day still releases
    ~500,000 propagules, of which only as many are traced as can find a free slot. Both phases
    are reported; days 0-1 compile the kernels."""
    scn = load_scenario(SCEN, ["light.photons=1000000", f"moss.capacity={capacity}",
                               f"moss.initial={initial}", "moss.size=0.0015"])
    sim = Simulation(scn, out, days=days, progress=False)
    sim.out.mkdir(parents=True, exist_ok=True)
    sim.setup()
    sim.initialise()
    print(f"(b) capacity {capacity:,d}, 1,000,000 photons/day, 1.5 mm spots (per day: live moss, "
          "germinated, placed, light / soil / moss [ms], soil + moss share of the day)")
    rows = []
    for day in range(days):
        rec = sim.step()
        sec, ev = rec["seconds"], rec["events"]
        share = (sec["soil"] + sec["moss"]) / (sec["light"] + sec["soil"] + sec["moss"])
        rows.append((day, sec["light"], sec["soil"], sec["moss"], share))
        print(f"    day {day:2d}: {rec['moss_alive']:9,d} {ev['germinated']:7,d} "
              f"{ev['propagules_settled']:7,d}   {sec['light'] * 1e3:4.0f} / {sec['soil'] * 1e3:4.1f} "
              f"/ {sec['moss'] * 1e3:5.1f}   {share:5.1%}")
    a = np.array(rows)
    for name, sel in (("filling (days 2-7)", (a[:, 0] >= 2) & (a[:, 0] <= 7)),
                      ("full (days 8-19)", a[:, 0] >= 8)):
        light, soil, moss = (a[sel, k].mean() for k in (1, 2, 3))
        share = (soil + moss) / (light + soil + moss)
        verdict = f"; target < 10 % -> {'met' if share < 0.10 else 'NOT met'}" \
            if name.startswith("full") else ""
        print(f"    {name}: light {light * 1e3:.0f} ms, soil {soil * 1e3:.1f} ms, moss "
              f"{moss * 1e3:.1f} ms a day (mean) -> soil + moss = {share:.1%} of the day "
              f"(median day {np.median(a[sel, 4]):.1%}){verdict}")
        key = "full" if name.startswith("full") else "filling"
        recorder.add(f"moss_share_{key}", share, "fraction",
                     f"soil + moss share of a day at 1M moss, {name}")
        recorder.add(f"moss_ms_{key}", moss * 1e3, "ms", f"moss per day at 1M moss, {name}")
        recorder.add(f"light_ms_{key}", light * 1e3, "ms", f"light per day at 1M moss, {name}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=300)
    ap.add_argument("--skip-a", action="store_true")
    ap.add_argument("--skip-b", action="store_true")
    ap.add_argument("--out", default="out/bench_moss")
    a = ap.parse_args()
    rec = Recorder("moss_run", notes="(b) capacity 1,000,000, 900,000 initial moss, 1.5 mm "
                   "spots, 1M photons a day, 20 days; (a) the moss garden as shipped")
    if not a.skip_b:
        part_b(Path(a.out) / "b", rec)
    if not a.skip_a:
        part_a(a.days, Path(a.out) / "a", rec)
    rec.write()


if __name__ == "__main__":
    main()
