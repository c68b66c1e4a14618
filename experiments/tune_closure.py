"""The relaxed model against the mean of an ensemble of discrete runs, per region and day.

Reads the ensemble of ``experiments/tune_discrete_ensemble.py`` (``--ensemble``), runs the
relaxed model (:class:`mitsuba_veg.tune.SmoothMossModel`) with the same species, days and
scenario for each closure in ``--closures`` and prints, every ``--every`` days, the covered area
per region and in total: the discrete mean (and the standard error of the mean) and the relaxed
model's ratio to it. The largest deviation per closure over the reported days is printed last.

    python experiments/tune_closure.py --ensemble out/tune_ensemble --closures mean-field,near-field
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402

from mitsuba_veg import tune  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def load_ensemble(folder: Path) -> dict:
    files = sorted(folder.glob("seed_*.npz"))
    runs = [np.load(f) for f in files]
    names = [str(x) for x in runs[0]["region_names"]]
    reg = np.array([r["regions"] for r in runs])          # [seed, day, region]
    tot = np.array([r["cover"] for r in runs])            # [seed, day]
    alive = np.array([r["alive"] for r in runs])
    settings = json.loads((folder / "settings.json").read_text())
    return {"n": len(runs), "names": names, "regions": reg, "total": tot, "alive": alive,
            "settings": settings, "counts": np.array([r["counts"] for r in runs])}


def relaxed_series(model, params=None) -> dict:
    with dr.suspend_grad():
        out = model.run(params, record=True)
    names = sorted(out.history[0]["regions"])
    return {"regions": np.array([[h["regions"][k] for k in names] for h in out.history]),
            "total": np.array([h["covered_area_m2"] for h in out.history]),
            "alive": np.array([h["moss_alive"] for h in out.history]), "names": names}


def compare(ens: dict, rel: dict, every: int, label: str, floor: float = 0.0) -> float:
    """Print the table; return the largest |relaxed / discrete - 1| over the reported days
    and the regions + total (where the discrete mean is above ``floor`` m2)."""
    days = ens["total"].shape[1]
    rep = [d for d in range(every, days + 1, every)]
    names = ens["names"] + ["total"]
    dm = np.concatenate([ens["regions"], ens["total"][..., None]], axis=2)   # seed, day, k
    rm = np.concatenate([rel["regions"], rel["total"][:, None]], axis=1)
    mean = dm.mean(0)
    sem = dm.std(0, ddof=1) / np.sqrt(dm.shape[0])
    print(f"{label}: covered area [m2], discrete mean of {ens['n']} (s.e.) / relaxed ratio")
    print("day  " + "  ".join(f"{n:>26s}" for n in names))
    worst = 0.0
    for d in rep:
        cells = []
        for k in range(len(names)):
            r = rm[d - 1, k] / max(mean[d - 1, k], 1e-12)
            if max(mean[d - 1, k], rm[d - 1, k]) < 1e-4:   # neither holds a moss (1 cm2)
                r = 1.0
            if mean[d - 1, k] > floor:
                worst = max(worst, abs(r - 1))
            cells.append(f"{mean[d - 1, k]:.4f} ({sem[d - 1, k]:.4f}) / {r:5.3f}")
        print(f"{d:4d} " + "  ".join(f"{c:>26s}" for c in cells))
    print(f"{label}: largest deviation {worst:.1%}", flush=True)
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ensemble", default="out/tune_ensemble")
    ap.add_argument("--closures", default="mean-field,near-field")
    ap.add_argument("--temperature", type=float, default=0.0)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--light-every", type=int, default=15,
                    help="days between the relaxed model's sun-path passes (1: a new pass, i.e. "
                         "new photon noise, every day as in the discrete run)")
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--near-cells", default="kernel",
                    help="z of the near-field closure (list; 'kernel': from the gemma kernel)")
    ap.add_argument("--near-scale", type=float, default=1.0,
                    help="factor on the kernel's z (near-field closure)")
    ap.add_argument("--days", type=int, default=0, help="compare the first days only")
    ap.add_argument("--floor", type=float, default=0.0,
                    help="ignore region-days whose discrete mean is below this [m2]")
    a = ap.parse_args()
    ens = load_ensemble(Path(a.ensemble))
    st = ens["settings"]
    days = a.days or ens["total"].shape[1]
    for k in ("regions", "total", "alive"):
        ens[k] = ens[k][:, :days]
    species = st["species"].split(",")
    data = tune.prepare(SCEN, days=days, species=species, photons=a.photons,
                        light_every=a.light_every,
                        overrides=list(st.get("set", [])))
    for cl in a.closures.split(","):
        for z in (a.near_cells.split(",") if cl == "near-field" else ["kernel"]):
            model = tune.SmoothMossModel(data, temperature=a.temperature, closure=cl,
                                         near_cells=None if z == "kernel" else float(z),
                                         near_scale=a.near_scale)
            lab = f"{cl}{' z = ' + z if cl == 'near-field' else ''} (t = {a.temperature:g})"
            compare(ens, relaxed_series(model), a.every, lab, a.floor)


if __name__ == "__main__":
    main()
