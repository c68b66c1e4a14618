"""An ensemble of discrete moss runs (different seeds) for comparing the relaxed model against.

Runs :class:`mitsuba_veg.daily.Simulation` of the moss garden for ``--days`` days with
``--photons`` photons a day, once per seed (``light.seed`` = seed: light, rain days, placement
and dispersal all change), and stores per seed and day the moss per triangle, the region cover,
the events, the histogram of moss neighbours of the live moss (the clump rule's input) and the
day's light (sun and sky fractions f_sun, f_sky per triangle, float32: the relaxed model can be
driven with the very light of each run, ``tune_closure.py --discrete-light``), in
``OUT/seed_<s>.npz``. ``experiments/tune_closure.py`` compares the relaxed model against it.

    python experiments/tune_discrete_ensemble.py --seeds 0-7 --days 60 --photons 100000 \
        --species bryum_argenteum --out out/tune_ensemble
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitsuba_veg.moss.population import MOSS  # noqa: E402
from mitsuba_veg.scenario import load_scenario  # noqa: E402
from mitsuba_veg.daily import Simulation  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def seeds_arg(s: str) -> list[int]:
    if "-" in s:
        a, b = s.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in s.split(",")]


def run_seed(seed: int, days: int, photons: int, species: list[str], extra=()) -> dict:
    """One discrete run; per-day arrays (moss per triangle, region cover, events)."""
    ov = [f"light.photons={photons}", f"light.seed={seed}",
          "moss.species=[" + ",".join(f"'{s}'" for s in species) + "]",
          "simulation.checkpoint_every=0"] + list(extra)
    scn = load_scenario(SCEN, ov)
    with tempfile.TemporaryDirectory() as tmp:
        sim = Simulation(scn, tmp, days=days, progress=False)
        sim.setup()
        sim.initialise()
        counts, regions, alive, cover, nbh, ev, prop = [], [], [], [], [], [], []
        f_sun, f_sky = [], []
        for _ in range(days):
            rec = sim.step()
            f_sun.append(np.asarray(sim.last["f_sun"], np.float32))
            f_sky.append(np.asarray(sim.last["f_sky"], np.float32))
            c = sim.counts()
            counts.append(c.astype(np.uint16))
            regions.append([rec["regions"][k] for k in sorted(sim.regions)])
            alive.append(rec["moss_alive"])
            prop.append(rec["propagules"])
            cover.append(rec["covered_area_m2"])
            e = rec["events"]
            ev.append([e.get(k, 0) for k in ("germinated", "died", "gemma_parents",
                                              "spore_parents", "propagules_settled")])
            moss = np.asarray(sim.pop.state) == MOSS
            nb = np.asarray(sim.grid.nb)[moss[:len(np.asarray(sim.grid.nb))]]
            nbh.append(np.bincount(np.minimum(nb, 26), minlength=27))
        return {"counts": np.array(counts), "regions": np.array(regions),
                "region_names": np.array(sorted(sim.regions)), "alive": np.array(alive), "propagules": np.array(prop),
                "cover": np.array(cover), "events": np.array(ev), "nb_hist": np.array(nbh),
                "f_sun": np.array(f_sun), "f_sky": np.array(f_sky)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0-7")
    ap.add_argument("--days", type=int, default=60)
    ap.add_argument("--photons", type=int, default=100_000)
    ap.add_argument("--species", default="bryum_argenteum")
    ap.add_argument("--set", action="append", default=[], help="extra scenario overrides")
    ap.add_argument("--out", default="out/tune_ensemble")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    species = a.species.split(",")
    (out / "settings.json").write_text(json.dumps(vars(a), indent=1))
    for s in seeds_arg(a.seeds):
        f = out / f"seed_{s}.npz"
        if f.exists():
            continue
        t0 = time.perf_counter()
        r = run_seed(s, a.days, a.photons, species, a.set)
        np.savez_compressed(f, **r)
        print(f"seed {s}: {time.perf_counter() - t0:.0f} s, day {a.days}: moss {r['alive'][-1]}, "
              f"covered {r['cover'][-1]:.4f} m2, regions "
              + ", ".join(f"{n} {v:.4f}" for n, v in zip(r["region_names"], r["regions"][-1])),
              flush=True)


if __name__ == "__main__":
    main()
