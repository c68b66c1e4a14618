"""Paper 000's two experiments on the moss garden, side by side (figs 4.1/4.2 and 4.3).

1. indirect light on vs off (figs 4.1 / 4.2): moss area under the roof after N days;
2. air temperature 288.15 K vs 293.15 K (fig 4.3): moss area overall.

Writes out/experiments/moss_<name>.png (final coverage maps side by side + coverage over the
days) and prints the ratios. Runs are independent, seeded and resumable.

    python experiments/moss_paper_experiments.py [--days 300] [--photons 1000000] [--out DIR]
"""
import argparse
import json
from pathlib import Path

import numpy as np

import mitsuba_veg as mv

SCENARIO = Path(__file__).resolve().parent.parent / "scenes" / "moss_garden" / "scenario.toml"

PAIRS = {
    "indirect": [("indirect light on", ["light.indirect=true"]),
                 ("indirect light off", ["light.indirect=false"])],
    "temperature": [("T = 288.15 K", ["climate.temperature=288.15"]),
                    ("T = 293.15 K", ["climate.temperature=293.15"])],
}


def run_pair(name, days, photons, out, progress=True):
    res = []
    for label, sets in PAIRS[name]:
        tag = label.replace(" ", "_").replace("=", "").replace(".", "")
        s = mv.run(SCENARIO, out=out / name / tag, days=days, progress=progress, frames=False,
                   overrides=sets + [f"light.photons={photons}"])
        res.append((label, s))
    return res


def figure(name, res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axs = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    for ax, (label, s) in zip(axs[:2], res):
        ck = np.load(Path(s["scenario_out"]) / "checkpoint.npz")
        live = ck["state"] == 2
        p = ck["pos"][live]
        ax.scatter(p[:, 0], -p[:, 2], s=0.5, c=np.clip(p[:, 1], 0, 0.8), cmap="viridis_r")
        ax.set_aspect("equal")
        ax.set_xlim(-1.05, 1.05)
        ax.set_ylim(-1.05, 1.05)
        ax.axhspan(-0.15, 0.95, color="grey", alpha=0.12, label="roof above")
        f = s["final"]
        ax.set_title(f"{label}: {f['moss_alive']} moss\nunder roof "
                     f"{f['regions']['under_roof']['covered_area_m2']:.3f} m², total "
                     f"{f['covered_area_m2']:.3f} m²", fontsize=10)
        ax.set_xlabel("x (east) [m]")
        ax.set_ylabel("-z (north) [m]")
        ax.legend(loc="lower right", fontsize=8)
    for label, s in res:
        d = [r["day"] for r in s["days_record"]]
        axs[2].plot(d, [r["regions"]["under_roof"] for r in s["days_record"]],
                    label=f"{label}: under roof")
        axs[2].plot(d, [r["covered_area_m2"] for r in s["days_record"]], "--",
                    label=f"{label}: all surfaces")
    axs[2].set_xlabel("day")
    axs[2].set_ylabel("covered area [m²]")
    axs[2].legend(fontsize=8)
    fig.suptitle(f"moss garden, {name} experiment (colour of points: height, roof underside "
                 "dark)", fontsize=11)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=300)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--out", default="out/experiments")
    ap.add_argument("--only", choices=list(PAIRS))
    a = ap.parse_args()
    out = Path(a.out)
    report = {}
    for name in ([a.only] if a.only else PAIRS):
        res = run_pair(name, a.days, a.photons, out)
        for (label, sets), (_, s) in zip(PAIRS[name], res):
            s["scenario_out"] = str(out / name / label.replace(" ", "_").replace("=", "")
                                    .replace(".", ""))
        figure(name, res, out / f"moss_{name}.png")
        (l1, s1), (l2, s2) = res
        ur = [s["final"]["regions"]["under_roof"]["covered_area_m2"] for _, s in res]
        tot = [s["final"]["covered_area_m2"] for _, s in res]
        report[name] = {"labels": [l1, l2], "under_roof_m2": ur, "total_m2": tot,
                        "ratio_under_roof": ur[0] / ur[1] if ur[1] > 0 else float("inf"),
                        "ratio_total": tot[0] / tot[1] if tot[1] > 0 else float("inf")}
        print(f"{name}: {l1} vs {l2}: under roof {ur[0]:.4f} / {ur[1]:.4f} m² "
              f"(ratio {report[name]['ratio_under_roof']:.2f}), all surfaces {tot[0]:.4f} / "
              f"{tot[1]:.4f} m² (ratio {report[name]['ratio_total']:.2f}) -> "
              f"{out / f'moss_{name}.png'}")
    (out / "report.json").write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
