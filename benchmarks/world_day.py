"""A steady world day against its bare photon pass, and the kernels a day launches.

    python benchmarks/world_day.py [--photons 1000000] [--days 6] [--start 2026-07-01]
                                   [--time-only]

The courtyard world of benchmarks/world_year.py (117,636 leaves, in full leaf on 1 July). After
two warm-up days, ``--days`` days are run; each day is followed by a bare photon pass of the
same scene with the same device tables (albedo, leaf stages and modes, recorded shapes) and the
same photon split, so that load from other processes hits both. Printed:

- the day's wall time and its stages, the bare pass's wall time and their ratio (median of the
  per-day ratios; the issue's target on the CPU is <= 1.2);
- kernel launches per day (Dr.Jit's kernel history, every kind: JIT kernels, reductions,
  compress, memset/memcpy, host tasks) and how many kernels were compiled (cache misses; 0 in
  a steady day) or loaded from Dr.Jit's disk cache (new to the process: a machine with an
  empty cache compiles these too; run with HOME set to an empty folder to see that case on the
  CPU), and the same for the bare pass; the launches per stage of the day (the
  record's ``launches``, counted by the day itself while the history is on);
- the device and backend.

Reading Dr.Jit's kernel history waits for the kernels launched so far, so the counted day waits
at every stage's end. On the CPU a run's day does too (DayPipeline.run_day); on a GPU it does
not: ``--time-only`` runs the days without the history, as a run runs them (no launch counts).
"""
from __future__ import annotations

import argparse
import collections
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--days", type=int, default=6)
    ap.add_argument("--start", default="2026-07-01")
    ap.add_argument("--time-only", action="store_true",
                    help="run the days without the kernel history (no launch counts)")
    a = ap.parse_args(argv)
    import drjit as dr
    import mitsuba as mi

    import mitsuba_veg as mv
    from mitsuba_veg.daily import Simulation
    from mitsuba_veg.daily.config import BANDS
    from mitsuba_veg.scenario import load_scenario
    from world_year import EXTRA

    tmp = Path(tempfile.mkdtemp())
    shutil.copytree(ROOT / "scenes" / "courtyard", tmp / "courtyard")
    f = tmp / "courtyard" / "scenario.toml"
    f.write_text(f.read_text().replace("[phenology]", EXTRA + "\n[phenology]", 1))
    scn = load_scenario(f, [f'simulation.start_date="{a.start}"', f"light.photons={a.photons}"])
    sim = Simulation(scn, tmp / "run", days=a.days + 2, progress=False)
    t0 = time.perf_counter()
    sim.setup()
    sim.initialise()
    setup = time.perf_counter() - t0
    for _ in range(2):                       # compiles; the leaves come out
        sim.step()
    light = sim.pipeline.light
    integ, tables = sim.site.integrator, light.tables

    def bare(day):
        dr.sync_thread()
        t = time.perf_counter()
        res = integ.trace(sim.scene, photons=a.photons, seed=(light.seed * 10_007 + day)
                          & 0x7FFFFFFF, max_depth=light.max_depth, bands=BANDS,
                          indirect=light.indirect, tables=tables, counts=light.counts[day])
        dr.eval(res.device.acc)
        dr.sync_thread()
        return time.perf_counter() - t

    bare(sim.day)                             # this path's own kernels compile once
    days, passes, ratios, stages = [], [], [], collections.defaultdict(list)
    k_day, k_bare, c_day, c_bare, kinds, n_day = [], [], [], [], [], []

    def _kind(t):
        t = str(t).split(".")[-1]
        if t == "JIT":
            return "kernels"
        if t in ("BlockReduce", "BlockPrefixReduce", "Compress", "MkPerm"):
            return "reductions"
        return "memory/host"     # memset, memcpy, aggregate, host tasks (copies of inputs)
    per_stage = collections.defaultdict(list)
    dr.set_flag(dr.JitFlag.KernelHistory, not a.time_only)
    for _ in range(a.days):
        dr.sync_thread()
        dr.kernel_history()
        t = time.perf_counter()
        rec = sim.step()
        dr.sync_thread()
        dt = time.perf_counter() - t
        # the day counts its stages' launches itself (the record's "launches", read from the
        # kernel history while it is on); anything after the day is added
        h = dr.kernel_history() if not a.time_only else []
        lc = rec.get("launches", {"stages": {}, "kinds": {}, "compiled": 0, "loaded": 0})
        k_day.append(sum(lc["stages"].values()) + len(h))
        c_day.append(lc["compiled"] + sum(1 for x in h if x["type"] == dr.KernelType.JIT
                                          and not x["cache_hit"]))
        n_day.append(lc.get("loaded", 0) + sum(
            1 for x in h if x["type"] == dr.KernelType.JIT and x["cache_hit"] and x["cache_disk"]))
        kc = collections.Counter()
        for k, v in lc["kinds"].items():
            kc[_kind(k)] += v
        kc.update(_kind(x["type"]) for x in h)
        kinds.append(kc)
        for k, v in lc["stages"].items():
            per_stage[k].append(v)
        tb = bare(sim.day - 1)
        h = dr.kernel_history() if not a.time_only else []
        k_bare.append(len(h))
        c_bare.append(sum(1 for x in h if x["type"] == dr.KernelType.JIT and not x["cache_hit"]))
        days.append(dt)
        passes.append(tb)
        ratios.append(dt / tb)
        for k, v in rec["seconds"].items():
            stages[k].append(v)
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    dev = "CPU" if "llvm" in mi.variant() else "GPU"
    print(f"variant {mi.variant()} ({dev}, {os.cpu_count()} CPU threads); world: "
          f"{sim.canopy.n_leaves:,d} leaves, {a.photons:,d} photons/day, set-up {setup:.1f} s")
    print(f"steady day (median of {a.days}): {np.median(days) * 1e3:.1f} ms "
          f"(" + ", ".join(f"{k} {np.median(v) * 1e3:.1f} ms" for k, v in stages.items())
          + ")")
    if not a.time_only:
        still = [t for t, c in zip(days, c_day) if c == 0]
        print(f"days that compiled nothing: {len(still)} of {a.days}, median "
              + (f"{np.median(still) * 1e3:.1f} ms" if still else "-")
              + " (target <= 30 ms on a GPU: a day of a run past its first compilations)")
    print("bare photon pass, same scene, tables and photon split: "
          f"{np.median(passes) * 1e3:.1f} ms")
    print(f"world day / bare pass: {np.median(ratios):.2f} (per day: "
          + ", ".join(f"{r:.2f}" for r in ratios) + "; target <= 1.2 on the CPU)")
    if a.time_only:
        print("(--time-only: the days ran without the kernel history; no launch counts)")
        shutil.rmtree(tmp, ignore_errors=True)
        return 0
    med = {k: float(np.median([c.get(k, 0) for c in kinds]))
           for k in ("kernels", "reductions", "memory/host")}
    print(f"kernel launches per day: {np.median(k_day):.0f} (min {min(k_day)}, max {max(k_day)};"
          f" target <= 40): " + ", ".join(f"{k} {v:.0f}" for k, v in med.items())
          + f"; compiled {max(c_day)} (max of a day), on {sum(c > 0 for c in c_day)} of "
          f"{a.days} days; loaded from the disk cache {max(n_day)} (max of a day), on "
          f"{sum(n > 0 for n in n_day)} days; bare pass: {np.median(k_bare):.0f} "
          f"launches, compiled {max(c_bare)}")
    print("launches per stage (min-max over the days): " + ", ".join(
        f"{k} {min(v)}-{max(v)}" for k, v in per_stage.items() if max(v) > 0))
    from _record import Recorder
    rec = Recorder(f"world_day_{dev.lower()}",
                   notes=f"the courtyard world of world_year.py ({sim.canopy.n_leaves:,d} "
                         f"leaves, full leaf), {a.photons:,d} photons a day, {a.days} days "
                         "after two warm-up days")
    rec.add("day_ms", float(np.median(days)) * 1e3, "ms", "steady world day (median)")
    for k, v in stages.items():
        rec.add(f"{k}_ms", float(np.median(v)) * 1e3, "ms", f"of which {k}")
    if still:
        rec.add("day_no_compile_ms", float(np.median(still)) * 1e3, "ms",
                "day that compiled nothing (median)")
    rec.add("bare_pass_ms", float(np.median(passes)) * 1e3, "ms",
            "bare photon pass, same scene, tables and photon split")
    rec.add("day_over_pass", float(np.median(ratios)), "ratio", "world day ÷ its bare pass")
    rec.add("launches_per_day", float(np.median(k_day)), "", "kernel launches a day (median)")
    rec.write()
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
