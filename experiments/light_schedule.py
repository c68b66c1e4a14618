"""What a light schedule (``simulation.light_every``) changes, against the seed-to-seed noise.

    python experiments/light_schedule.py [--out out/experiments/light_schedule]
                                         [--every 1 2 4 7] [--garden-days 300]
                                         [--courtyard-days 75] [--photons 300000]
                                         [--cases moss_garden courtyard]

Two runs of each case with a photon pass every day (light seeds 0 and 1: the noise of the light
itself) and one per longer schedule (seed 0):

- **moss garden** (``scenes/moss_garden``, paper 000, from 1 March): the final covered area
  and live moss, and the mean insolation S over the days;
- **courtyard** (``scenes/courtyard``) from 1 April through leaf-out at ``--photons`` a pass:
  the absorbed PAR of the trees' leaves summed over the days, the PAR on the ground under
  their crowns averaged over the days, and the final covered area.

Prints and writes ``results.json``: each quantity per schedule, its relative difference to
the every-day run of seed 0, the same for the every-day run of seed 1 (the noise a schedule's
difference should be compared with), and the light stage's seconds.
"""
from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _run(scenario, days, overrides):
    from mitsuba_veg.daily import Simulation
    from mitsuba_veg.scenario import load_scenario
    out = Path(tempfile.mkdtemp(prefix="light_schedule_"))
    try:
        scn = load_scenario(scenario, ["simulation.checkpoint_every=0"] + overrides)
        sim = Simulation(scn, out, days=days, progress=False)
        t0 = time.perf_counter()
        s = sim.run()
        s["wall_s"] = time.perf_counter() - t0
        return s
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _garden(s) -> dict:
    h = s["days_record"]
    return {"covered_area_m2": s["final"]["covered_area_m2"],
            "moss_alive": s["final"]["moss_alive"],
            "mean_S_W_m2": float(np.mean([r["mean_S_W_m2"] for r in h]))}


def _courtyard(s) -> dict:
    h = s["days_record"]
    names = list(h[-1]["trees"])
    par = [r["trees"][n]["ground_under_crown"]["par_W_m2"] for r in h for n in names]
    return {"absorbed_par_MJ": float(sum(r["trees"][n]["absorbed_par_W"] for r in h
                                         for n in names) * 86_400 / 1e6),
            "ground_par_under_crowns_W_m2": float(np.mean([p for p in par if p is not None])),
            "covered_area_m2": s["final"]["covered_area_m2"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="out/experiments/light_schedule")
    ap.add_argument("--every", type=int, nargs="+", default=[1, 2, 4, 7])
    ap.add_argument("--garden-days", type=int, default=300)
    ap.add_argument("--courtyard-days", type=int, default=75)
    ap.add_argument("--photons", type=int, default=300_000)
    ap.add_argument("--cases", nargs="+", default=["moss_garden", "courtyard"],
                    choices=["moss_garden", "courtyard"])
    a = ap.parse_args(argv)
    import mitsuba_veg  # noqa: F401  (the variant)
    cases = {
        "moss_garden": (ROOT / "scenes" / "moss_garden" / "scenario.toml", a.garden_days, [],
                        _garden),
        "courtyard": (ROOT / "scenes" / "courtyard" / "scenario.toml", a.courtyard_days,
                      ["simulation.start_date='2026-04-01'", f"light.photons={a.photons}"],
                      _courtyard),
    }
    results = {}
    for name in a.cases:
        scen, days, ov, metric = cases[name]
        rows = {}
        for every, seed in [(1, 0), (1, 1)] + [(n, 0) for n in a.every if n != 1]:
            s = _run(scen, days, ov + [f"simulation.light_every={every}", f"light.seed={seed}"])
            key = f"every {every}, seed {seed}"
            rows[key] = {**metric(s), "light_s": s["timings_s"]["light"],
                         "wall_s": s["wall_s"]}
            print(name, key, rows[key], flush=True)
        ref = rows["every 1, seed 0"]
        keys = [k for k in ref if k not in ("light_s", "wall_s")]
        for key, r in rows.items():
            r["relative_to_every_day"] = {k: (r[k] - ref[k]) / ref[k] if ref[k] else None
                                          for k in keys}
        results[name] = {"days": days, "overrides": ov, "runs": rows}
        print(f"\n{name} ({days} days): relative to the every-day run of seed 0")
        for key, r in rows.items():
            d = ", ".join(f"{k} {v:+.3%}" for k, v in r["relative_to_every_day"].items()
                          if v is not None)
            print(f"  {key:18s} {d}; light {r['light_s']:.1f} s")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=1))
    print(f"wrote {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
