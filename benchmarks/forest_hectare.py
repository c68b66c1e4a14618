"""A year of a 1-hectare Weber-Penn stand: more than 5 million leaves on the 2-core machine.

    python benchmarks/forest_hectare.py [--days 366] [--photons 1000000] [--out DIR]
                                        [--set key=value ...]

(``--set simulation.start_date=2026-12-12 --days 40``: a short run across a year's end.)

Runs ``scenes/forest_hectare`` (a 100 m x 100 m rolling ground, 1 ha, on a 5° south-facing
slope with 0.3 m of relief, 20 logs and 30 rocks clear of the tree bases; a ``[stand]`` of 300
quaking aspens per hectare: Weber-Penn, paper 004, Poisson-disc >= 3.5 m apart, three geometry
variants, 12 m tall on average, aged 20 so that they grow every 31 December; a moss floor; a
photon pass every fourth day, ``--photons`` a pass; no checkpoints) from 1 January for
``--days`` days (the default crosses the year's end: the trees age, the scene is rebuilt) and
prints:

- the set-up (trees, leaves, recorded elements, seconds) and the resident memory before and
  after it and after the first photon pass, with the memory per leaf;
- every 30 days the wall time and the memory;
- the year's end (ageing and rebuild) and its share of the year's time;
- the process's peak resident memory against the machine's 24 GB;
- when the run crosses a year's end, ten years projected from its days and its year's end
  (set-up + 3,652 days at the mean ordinary day + 10 year ends) against the 15-minute target
  of a GPU.
"""
from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GB = 1e9


def rss() -> float:
    """Resident memory of the process now [bytes]."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return float(line.split()[1]) * 1e3
    return float("nan")


def peak() -> float:
    """Peak resident memory of the process so far [bytes]."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1e3


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=366)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override")
    a = ap.parse_args(argv)
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.daily import Simulation
    from mitsuba_veg.moss.population import MOSS
    from mitsuba_veg.scenario import load_scenario
    out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="forest_hectare_"))
    scn = load_scenario(ROOT / "scenes" / "forest_hectare" / "scenario.toml",
                        [f"light.photons={a.photons}", "simulation.checkpoint_every=0"] + a.set)
    sim = Simulation(scn, out / "run", days=a.days, progress=False)
    m0, t0 = rss(), time.perf_counter()
    sim.setup()
    sim.initialise()
    t_setup, m_setup = time.perf_counter() - t0, rss()
    leaves = sim.site.canopy.n_leaves
    n_rec = sim.pipeline.light.tables.n_rec
    print(f"set-up {t_setup:.1f} s: {len(sim.site.trees)} trees on 1 ha, {leaves:,d} leaves, "
          f"{sim.site.index.n_elements:,d} triangles in the light scene"
          f" ({n_rec:,d} of them recorded: terrain and leaves)"
          + f"; memory {m0 / GB:.2f} GB before, {m_setup / GB:.2f} GB after", flush=True)
    t_run = time.perf_counter()
    n_log, year_end_s, year_end_day = 0, 0.0, None
    day_s, year_end_days = [], []
    while sim.day < a.days:
        t_day = time.perf_counter()
        sim.step()
        dt = time.perf_counter() - t_day
        day_s.append(dt)
        if sim.day == 1:
            m1 = rss()
            print(f"day 1 (a photon pass, kernels compiled): {dt:.1f} s, memory {m1 / GB:.2f} "
                  f"GB: {(m1 - m0) / leaves:,.0f} bytes per leaf with its share of the wood, "
                  "the floor and the pass", flush=True)
        if len(sim.state.growth_log) > n_log:
            n_log = len(sim.state.growth_log)
            year_end_s, year_end_day = dt, sim.day
            year_end_days.append(sim.day)
            aged = [r for r in sim.state.growth_log if r.get("model") == "weber_penn"]
            print(f"year end (night after day {sim.day - 1}): {len(aged)} trees aged to "
                  f"{aged[-1]['age']:.0f} years, mean height "
                  f"{np.mean([r['height_m'] for r in aged[-len(sim.site.trees):]]):.2f} m; "
                  f"that day {dt:.1f} s, memory {rss() / GB:.2f} GB", flush=True)
        if sim.day % 30 == 0:
            el = time.perf_counter() - t_run
            print(f"day {sim.day:4d}: {el:7.1f} s ({el / sim.day:.2f} s a day), moss "
                  f"{sim.pop.count(MOSS):,d}, memory {rss() / GB:.2f} GB (peak "
                  f"{peak() / GB:.2f})", flush=True)
    wall = time.perf_counter() - t_run
    print(f"{a.days} days: {wall:.0f} s ({wall / a.days:.2f} s a day) after a set-up of "
          f"{t_setup:.0f} s; peak memory {peak() / GB:.2f} GB of the machine's 24 GB "
          f"(ratio {peak() / 24e9:.2f}); {leaves:,d} leaves")
    if year_end_day is not None:
        ends = [day_s[d - 1] for d in year_end_days]
        print(f"year end: the day with the ageing and the rebuild took {year_end_s:.1f} s, "
              f"{year_end_s / wall:.3f} of the run's time"
              + (f"; {len(ends)} year ends {min(ends):.1f}-{max(ends):.1f} s, "
                 f"{sum(ends):.0f} s in all ({sum(ends) / wall:.2f} of the run)"
                 if len(ends) > 1 else ""))
    # ten years from what this run measured (when it is shorter): the mean of its ordinary
    # days (neither the first, which compiles, nor a year's end) for 3,652 days, plus the
    # set-up and ten year ends like its last
    plain = [d for i, d in enumerate(day_s) if i > 0 and i + 1 not in year_end_days]
    if plain and year_end_days:
        # the year's end itself: the regrowth (ageing, the scene and its tables built anew)
        # and the year's figures, without that day's own stages (its photon pass, moss, ...)
        grow, out_s = sim.timings.get("growth", 0.0), sim.timings.get("output", 0.0)
        year = 365 * float(np.mean(plain))
        print(f"the year's end without its day: regrowth {grow / len(year_end_days):.1f} s, "
              f"the year's figures {out_s / len(year_end_days):.1f} s (outputs); against 365 "
              f"days at the mean ordinary day ({year:.0f} s): regrowth "
              f"{grow / len(year_end_days) / year:.3f} of a year (target <= 0.05), with the "
              f"figures {(grow + out_s) / len(year_end_days) / year:.3f}")
    if plain and year_end_day is not None and a.days < 3652:
        ten = t_setup + day_s[0] + 3651 * float(np.mean(plain)) + 10 * year_end_s
        print(f"ten years projected from this run: {ten:.0f} s ({ten / 60:.1f} min: set-up, "
              f"3,652 days at the mean ordinary day {np.mean(plain):.3f} s, 10 year ends); "
              f"the GPU target 15 min: ratio {ten / 900:.2f}")
    elif a.days >= 3652:
        total = t_setup + wall
        print(f"ten years with the set-up: {total:.0f} s ({total / 60:.1f} min); the GPU "
              f"target 15 min: ratio {total / 900:.2f}")
    from _record import Recorder
    import mitsuba as mi
    dev = "cpu" if "llvm" in mi.variant() else "gpu"
    rec = Recorder(f"forest_hectare_{dev}", notes=f"{len(sim.site.trees)} Weber-Penn aspens on "
                   f"1 ha ({leaves:,d} leaves), {a.photons:,d} photons a pass, {a.days} days")
    rec.add("setup_s", t_setup, "s", "set-up")
    rec.add("run_s", wall, "s", f"{a.days} days after the set-up")
    rec.add("day_s", wall / a.days, "s", "per day (mean)")
    rec.add("peak_memory_gb", peak() / GB, "GB", "peak memory")
    if a.days >= 3652:
        rec.add("ten_years_s", t_setup + wall, "s", "ten years with the set-up")
    elif plain and year_end_day is not None:
        rec.add("ten_years_projected_s", ten, "s", "ten years projected from this run")
    rec.write()
    if not a.out:
        shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
