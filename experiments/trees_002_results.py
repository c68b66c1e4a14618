"""Paper 002's experiment (Noma, §6) reproduced: 5 x 5 identical sample trees deformed by the
branch-death and heliotropism rules in voxel-space light.

    .venv/bin/python experiments/trees_002_results.py [--out out/trees_002]

Sample tree: the pure binary branching model of paper 001 (G = 7, θ = 45°, L_t = 4, L_l = 5,
unit 0.25 m: 255 branches, ~8 m tall), copied onto a 4 m grid. Voxels 0.5 m, shading 0.3 per
tip, death threshold 0.5 (T/N with N = tips, bottom-up), heliotropism constant 1 rad, cap 30°. Writes:

- ``fig_stand.png``: top views of the stand as placed, after the death rule (paper fig 1) and
  after heliotropism (fig 3), with live-branch counts and lean arrows;
- ``fig_row3.png``: the third row from the side, same three states (figs 2 and 4);
- ``results.json``: live branches per tree, outward lean per tree, timings.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/trees_002")
    ap.add_argument("--spacing", type=float, default=4.0)
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.trees import GrowthParams, branching, nongrowth
    from mitsuba_veg.trees.analysis import lean
    from mitsuba_veg.trees.figures import draw

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    sample = branching(GrowthParams(branch_angle=45, lateral_length=5, random_phase=False), 7)
    sp = a.spacing
    trees = [sample.translated((sp * i, 0.0, sp * j)) for j in range(5) for i in range(5)]
    t0 = time.perf_counter()
    death = nongrowth.deform(trees, rules=("death",), death_threshold=0.5)
    helio = nongrowth.deform(death.trees, rules=("heliotropism",))
    seconds = time.perf_counter() - t0
    live = np.array([t.metrics()["live_branches"] for t in death.trees]).reshape(5, 5)
    bases = np.array([t.metrics()["base"] for t in trees])[:, [0, 2]]
    c = bases.mean(0)
    shifts = np.array([lean(h, d) for h, d in zip(helio.trees, death.trees)])
    outward = np.array([s @ (b - c) / np.linalg.norm(b - c) if np.linalg.norm(b - c) > 0
                        else np.nan for s, b in zip(shifts, bases)]).reshape(5, 5)
    inner = (slice(1, 4), slice(1, 4))
    edge_mask = np.ones((5, 5), bool)
    edge_mask[inner] = False
    res = {"spacing_m": sp, "sample_branches": len(sample), "seconds": seconds,
           "live_branches": live.tolist(),
           "live_inner_mean": float(live[inner].mean()), "live_edge_mean": float(live[edge_mask].mean()),
           "outward_lean_m": np.round(outward, 3).tolist(),
           "lean_edge_mean_m": float(np.nanmean(outward[edge_mask])),
           "lean_inner_mean_abs_m": float(np.nanmean(np.abs(outward[inner]))),
           "stats": death.stats + helio.stats}
    # ---- figures --------------------------------------------------------------------------
    fig, axs = plt.subplots(1, 3, figsize=(18, 6.4))
    for ax, ts, title in zip(axs, (trees, death.trees, helio.trees),
                             ("as placed (255 branches each)", "after the branch-death rule",
                              "after death + heliotropism")):
        draw(ax, ts, "top", sphere_alpha=0.05)
        ax.set_title(title, fontsize=10)
    for k, b in enumerate(bases):
        axs[1].text(b[0], b[1] - 1.2, str(live.ravel()[k]), ha="center", fontsize=8,
                    color="darkred", zorder=6)
    cen0 = np.array([t.metrics()["crown_centroid"] for t in death.trees])[:, [0, 2]]
    axs[2].quiver(cen0[:, 0], cen0[:, 1], 3 * shifts[:, 0], 3 * shifts[:, 1], angles="xy",
                  scale_units="xy", scale=1, color="red", width=0.004, zorder=6)
    axs[2].set_title("after death + heliotropism (red: crown lean x 3)", fontsize=10)
    fig.suptitle(f"Paper 002: 5 x 5 sample trees, {sp:g} m apart; live branches inner "
                 f"{res['live_inner_mean']:.0f} vs edge {res['live_edge_mean']:.0f}; edge trees "
                 f"lean out {res['lean_edge_mean_m']:.2f} m", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "fig_stand.png", dpi=90)
    plt.close(fig)
    fig, axs = plt.subplots(3, 1, figsize=(12, 10))
    for ax, ts, title in zip(axs, (trees, death.trees, helio.trees),
                             ("third row as placed", "after the branch-death rule (fig 2)",
                              "after heliotropism (fig 4)")):
        draw(ax, ts[10:15], "side", sphere_alpha=0.06)
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "fig_row3.png", dpi=90)
    plt.close(fig)
    (out / "results.json").write_text(json.dumps(res, indent=2, default=str))
    print("live branches after death:\n", live)
    print("outward lean after heliotropism [m]:\n", np.round(outward, 2))
    print(f"deformation of 25 trees: {seconds:.2f} s; wrote {out}/fig_stand.png, fig_row3.png, "
          "results.json")


if __name__ == "__main__":
    main()
