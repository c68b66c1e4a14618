"""The courtyard world through a year: figures of light under the crowns, leaves, and moss.

    python experiments/world_courtyard.py [--run out/demo/world] [--out out/experiments/world]

Without ``--run`` it first runs ``scenes/courtyard/scenario.toml`` for 365 days at 500,000
photons a day into ``OUT/run`` (about 6 minutes on 2 cores; resumed when run again). Writes:

- ``light_under_crowns.png``: ground PAR [W m-2] and red:far-red under each crown and in the
  open, day by day (leaf-out, summer, autumn, leaf fall);
- ``leaves.png``: leaves on each tree and their mean Ishikura stage;
- ``moss_mechanism.png``: moss cover, insolation S, surface temperature Ts and surface humidity
  rhs under the crowns and in the open (the mechanism behind the moss difference);
- ``results.json``: the numbers the figures show (seasonal means), printed too.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _series(recs, tree, key):
    out = []
    for r in recs:
        src = r["ground_open"] if tree is None else r["trees"][tree]["ground_under_crown"]
        v = src.get(key)
        out.append(np.nan if v is None else v)
    return np.array(out, float)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", help="a finished world run folder (default: run one)")
    ap.add_argument("--out", default="out/experiments/world")
    ap.add_argument("--photons", type=int, default=500_000)
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.run is None:
        import mitsuba_veg as mv
        run_dir = out / "run"
        mv.run(ROOT / "scenes" / "courtyard" / "scenario.toml", out=run_dir, days=365,
               overrides=[f"light.photons={a.photons}"])
    else:
        run_dir = Path(a.run)
    s = json.loads((run_dir / "summary.json").read_text())
    recs = s["days_record"]
    trees = list(recs[0]["trees"])
    day = np.array([r["day"] for r in recs])

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2), constrained_layout=True)
    for t in trees + [None]:
        lab = t or "open ground"
        ax[0].plot(day, _series(recs, t, "par_W_m2"), lw=1.2, label=lab)
        ax[1].plot(day, _series(recs, t, "red_far_red"), lw=1.2, label=lab)
    ax[0].set(xlabel=f"day (from {recs[0]['date']})", ylabel="ground PAR [W m$^{-2}$]",
              title="PAR on the ground (daily mean)")
    ax[1].set(xlabel="day", ylabel="red : far-red (photons)", title="R:FR on the ground")
    ax[0].legend(fontsize=8)
    fig.savefig(out / "light_under_crowns.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2), constrained_layout=True)
    for t in trees:
        on = np.array([r["trees"][t]["leaves_on_tree"] for r in recs], float)
        st = np.array([np.nan if r["trees"][t]["mean_stage"] is None else
                       r["trees"][t]["mean_stage"] for r in recs])
        ax[0].plot(day, on / max(on.max(), 1), label=t)
        ax[1].plot(day, st, label=t)
    ax[0].set(xlabel="day", ylabel="leaves on the tree (fraction)", title="leaf-out and fall")
    ax[1].set(xlabel="day", ylabel="mean Ishikura stage (1 green .. 7 red)",
              title="autumn colour (paper 003, light from the world's pass)")
    ax[0].legend(fontsize=8)
    fig.savefig(out / "leaves.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(1, 4, figsize=(18, 4), constrained_layout=True)
    for t in trees + [None]:
        for k, (key, lab) in enumerate((("moss_cover", "moss cover [-]"),
                                        ("S_W_m2", "insolation S [W m$^{-2}$]"),
                                        ("Ts_K", "surface temperature Ts [K]"),
                                        ("rhs", "surface humidity rhs [-]"))):
            ax[k].plot(day, _series(recs, t, key), lw=1.1, label=t or "open ground")
            ax[k].set(xlabel="day", ylabel=lab)
    ax[0].legend(fontsize=8)
    fig.savefig(out / "moss_mechanism.png", dpi=90)
    plt.close(fig)

    seasons = {"summer (full leaf)": [r for r in recs if all(
        v["leaves_on_tree"] > 0.9 * max(v["leaves"], 1) for v in r["trees"].values())],
        "after leaf fall": [r for r in recs[len(recs) // 2:] if all(
            v["leaves_on_tree"] == 0 for v in r["trees"].values())]}
    res = {}
    for name, rs in seasons.items():
        if not rs:
            continue
        res[name] = {"days": len(rs)}
        for t in trees + [None]:
            res[name][t or "open"] = {k: float(np.nanmean(_series(rs, t, k))) for k in
                                      ("par_W_m2", "red_far_red", "moss_cover", "S_W_m2",
                                       "Ts_K", "rhs")}
    res["final_moss_cover"] = {t or "open": float(_series(recs[-1:], t, "moss_cover")[0])
                               for t in trees + [None]}
    (out / "results.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    print("wrote", out / "light_under_crowns.png", out / "leaves.png",
          out / "moss_mechanism.png", out / "results.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
