"""Moss scenario performance: a 300-day moss-garden run and the population update at 1M moss.

(a) 300 days at 1,000,000 photons/day and the paper's capacity 16,384: total wall time and the
    split light / soil / moss per day (target: under 5 minutes on a 2-core machine);
(b) capacity 1,000,000 with ~900,000 live moss: time of the soil + moss update against the whole
    day (light at 1M photons included) - target under 10 %.

    python benchmarks/moss_run.py [--days 300] [--skip-a] [--skip-b]
"""
import argparse
import time
from pathlib import Path

import mitsuba_veg as mv
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.simulation import MossSimulation

SCEN = Path(__file__).resolve().parent.parent / "scenes" / "moss_garden" / "scenario.toml"


def part_a(days, out):
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


def part_b(out, capacity=1_000_000, initial=900_000, days=3):
    scn = load_scenario(SCEN, ["light.photons=1000000", f"moss.capacity={capacity}",
                               f"moss.initial={initial}", "moss.size=0.0015"])
    sim = MossSimulation(scn, out, days=days + 2, progress=False)
    sim.out.mkdir(parents=True, exist_ok=True)
    sim.setup()
    sim.initialise()
    sim.step()  # compile; the first days meet new code paths (propagules, conflicts)
    sim.step()
    sim.timings.update({"light": 0.0, "soil": 0.0, "moss": 0.0})
    for _ in range(days):
        sim.step()
    light, soil, moss = (sim.timings[k] / days for k in ("light", "soil", "moss"))
    total = light + soil + moss
    print(f"(b) {sim.pop.count(2):,d} live moss (capacity {capacity:,d}): soil + moss update "
          f"{(soil + moss) * 1e3:.0f} ms of a {total:.2f} s day = {(soil + moss) / total:.1%} "
          f"(target < 10 % -> {'met' if (soil + moss) / total < 0.10 else 'NOT met'})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=300)
    ap.add_argument("--skip-a", action="store_true")
    ap.add_argument("--skip-b", action="store_true")
    ap.add_argument("--out", default="out/bench_moss")
    a = ap.parse_args()
    if not a.skip_b:
        part_b(Path(a.out) / "b")
    if not a.skip_a:
        part_a(a.days, Path(a.out) / "a")


if __name__ == "__main__":
    main()
