"""Day-N cover of blocks of discrete runs at the same parameters: how far apart two ensembles
(a fit's seeds and a target's) are by chance (docs/tuning.md, "24 + 24 seeds").

    python experiments/tune_seed_blocks.py --blocks 0,100,200,300,1000,5000 --size 24 \
        --start-date 2026-03-01 --temperature 288.15
"""
from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitsuba_veg.scenario import Scenario, load_scenario  # noqa: E402
from mitsuba_veg.tune.discrete import DiscreteMossModel  # noqa: E402


def main():
    """Run every block and print its mean cover, the s.e. of that mean and its distance from
    the mean of all runs in s.e."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenes" / "moss_garden" / "scenario.toml"))
    ap.add_argument("--species", default="bryum_argenteum")
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--photons", type=int, default=250_000)
    ap.add_argument("--blocks", default="0,100,200,300,1000,5000", help="first seed of each block")
    ap.add_argument("--size", type=int, default=24, help="seeds per block")
    ap.add_argument("--start-date", default="2026-03-01")
    ap.add_argument("--temperature", type=float, default=288.15, help="air temperature [K]")
    a = ap.parse_args()
    scn = load_scenario(a.scenario)
    d = copy.deepcopy(scn.data)
    d.setdefault("simulation", {})["start_date"] = a.start_date
    d.setdefault("climate", {})["temperature"] = a.temperature
    scn = Scenario(scn.path, d)
    covers = {}
    for b in (int(x) for x in a.blocks.split(",")):
        dm = DiscreteMossModel(scn, a.days, species=a.species.split(","),
                               seeds=range(b, b + a.size), photons=a.photons)
        covers[b] = dm.run({}).total[:, -1]
        print(f"seeds {b}-{b + a.size - 1}: day {a.days} covered {covers[b].mean():.4f} m2 "
              f"(s.e. {covers[b].std(ddof=1) / np.sqrt(a.size):.4f})", flush=True)
    grand = np.mean(np.concatenate(list(covers.values())))
    print(f"all {a.size * len(covers)} runs: {grand:.4f} m2")
    for b, c in covers.items():
        se = c.std(ddof=1) / np.sqrt(len(c))
        print(f"seeds {b}-{b + a.size - 1}: {(c.mean() - grand) / se:+.1f} s.e. from the mean")


if __name__ == "__main__":
    main()
