"""How close is the relaxed (differentiable) moss model to the discrete one? (docs/tuning.md)

Part A - the life cycle alone, t -> 0: individuals of one species on 60 triangles with a random
daily environment (S, Ts, rhs) for 80 days, no space (no landing): the discrete
``MossPopulation.live_day`` against :class:`mitsuba_veg.tune.lifecycle.CohortLifeCycle` at
temperatures t = 0.1 ... 0.001 and t = 0. Reported: relative L1 error of the moss alive per
triangle and day, of the gemmae and spores made per triangle and day, and of their totals.

Part B - the whole moss garden: discrete runs (several seeds) against the relaxed model at a
few temperatures, moss alive / covered area per day (all surfaces, under the roof, open ground).

    python experiments/tune_relaxation_limit.py [--days 60] [--seeds 3] [--photons 250000]
        [--out out/tune_limit]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402

import mitsuba_veg as mv  # noqa: E402,F401
from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.moss.species import SPECIES  # noqa: E402
from mitsuba_veg.tune.lifecycle import discrete_life_cycle, relaxed_life_cycle  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def random_environment(n, days, seed=1):
    rng = np.random.default_rng(seed)
    d = np.arange(days)[:, None]
    S = np.clip(30 + 25 * np.sin(d / 7 + rng.random(n) * 6) + rng.normal(0, 8, (days, n)), 0, None)
    Ts = 285 + 6 * np.sin(d / 11 + rng.random(n) * 6) + rng.normal(0, 1.5, (days, n))
    rhs = np.clip(1.0 + 0.15 * np.sin(d / 5 + rng.random(n) * 6)
                  + rng.normal(0, 0.05, (days, n)), 0.5, 1.5)
    start = [rng.integers(0, 4, n) for _ in range(3)]  # moss (G = 1), gemmae, spores per triangle
    return [x.astype(np.float32) for x in (S, Ts, rhs)], start


def life_cycle_errors(temperatures=(0.1, 0.03, 0.01, 0.003, 0.001, 0.0), n=60, days=80,
                      species="bryum_argenteum", seed=1):
    sp = SPECIES[species]
    env, start = random_environment(n, days, seed)
    disc = discrete_life_cycle(sp, env, start)
    rows = []
    for t in temperatures:
        rel = relaxed_life_cycle(sp, env, start, t)
        row = {"t": t}
        for k in disc:
            row[f"{k}_daily"] = float(np.abs(rel[k] - disc[k]).sum() / disc[k].sum())
            if k != "moss":
                row[f"{k}_total"] = float(np.abs(rel[k].sum(0) - disc[k].sum(0)).sum()
                                          / disc[k].sum())
        rows.append(row)
    totals = {k: float(v.sum()) for k, v in disc.items()}
    return rows, totals


def garden(days, seeds, photons, temperatures, out):
    over = [f"light.photons={photons}", "simulation.checkpoint_every=0"]
    res = {"discrete": [], "relaxed": {}}
    for s in range(seeds):
        t0 = time.perf_counter()
        summ = mv.run(SCEN, out=out / f"discrete_{s}", days=days,
                      overrides=over + [f"light.seed={s}"], progress=False, frames=False,
                      resume=False)
        res["discrete"].append([{"day": r["day"], "moss": r["moss_alive"],
                                 "propagules": r["propagules"],
                                 "covered": r["covered_area_m2"], "regions": r["regions"]}
                                for r in summ["days_record"]])
        print(f"discrete seed {s}: {time.perf_counter() - t0:.1f} s", flush=True)
    data = tune.prepare(SCEN, days=days, photons=4 * photons, light_every=10)
    for t in temperatures:
        m = tune.SmoothMossModel(data, temperature=t, precision="float64")
        with dr.suspend_grad():
            r = m.run(record=True)
        res["relaxed"][str(t)] = [{"day": h["day"], "moss": h["moss_alive"],
                                   "propagules": h["propagules"], "covered": h["covered_area_m2"],
                                   "regions": h["regions"]} for h in r.history]
        print(f"relaxed t={t}: {r.seconds:.1f} s", flush=True)
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=int, default=60)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--photons", type=int, default=250_000)
    ap.add_argument("--out", default="out/tune_limit")
    ap.add_argument("--skip-garden", action="store_true")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, totals = life_cycle_errors()
    print("Part A: life cycle, relative L1 error against the discrete population "
          f"(totals: {totals})")
    print(f"{'t':>7} {'moss/day':>9} {'gemmae/day':>11} {'gemmae tot':>11} {'spores/day':>11} "
          f"{'spores tot':>11}")
    for r in rows:
        print(f"{r['t']:7.3f} {r['moss_daily']:9.4f} {r['gemmae_daily']:11.4f} "
              f"{r['gemmae_total']:11.4f} {r['spores_daily']:11.4f} {r['spores_total']:11.4f}")
    result = {"life_cycle": rows, "life_cycle_totals": totals}
    if not a.skip_garden:
        g = garden(a.days, a.seeds, a.photons, (0.1, 0.05, 0.01, 0.0), out)
        result["garden"] = g
        print("Part B: moss garden, moss alive / covered area [m2] (under roof, open)")
        for day in sorted({10, 20, 30, 40, 50, a.days} & set(range(1, a.days + 1))):
            ds = [run[day - 1] for run in g["discrete"]]
            line = (f"day {day:3d} discrete {np.mean([x['moss'] for x in ds]):8.0f} "
                    f"(sd {np.std([x['moss'] for x in ds]):6.0f}) "
                    f"{np.mean([x['covered'] for x in ds]):.3f} "
                    f"({np.mean([x['regions']['under_roof'] for x in ds]):.3f}, "
                    f"{np.mean([x['regions']['open'] for x in ds]):.4f})")
            for t, hist in g["relaxed"].items():
                h = hist[day - 1]
                line += (f" | t={t} {h['moss']:8.0f} {h['covered']:.3f} "
                         f"({h['regions']['under_roof']:.3f}, {h['regions']['open']:.4f})")
            print(line)
    (out / "relaxation_limit.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {out / 'relaxation_limit.json'}")


if __name__ == "__main__":
    main()
