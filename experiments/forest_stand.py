"""Stand layouts on one hectare and a stand on a sloped, rolling floor (docs/forest.md).

    python experiments/forest_stand.py [--out out/experiments/forest]

Writes ``stand_layouts.png`` (Poisson-disc, Thomas and Matérn stands of 400 trees/ha with their
Clark-Evans R, and a mixed stand with logs and rocks on a 15 deg rolling slope, coloured by
ground height) and ``results.json`` (R, nearest-neighbour distances, counts), printed too.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import mitsuba_veg  # noqa: E402,F401
from mitsuba_veg.forest_floor import rolling_ground, scatter_floor  # noqa: E402
from mitsuba_veg.trees.stand import StandSpec, layout  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
HA = [0.0, 0.0, 100.0, 100.0]
SPECS = {
    "Poisson-disc, s = 3 m": dict(min_spacing=3.0),
    "Thomas, sigma = 4 m, 20 parents/ha, s = 1 m": dict(placement="clumped", cluster="thomas",
                                                         cluster_radius=4.0, parent_density=20,
                                                         min_spacing=1.0),
    "Matern, R = 6 m, 20 parents/ha": dict(placement="clumped", cluster="matern",
                                           cluster_radius=6.0, parent_density=20,
                                           min_spacing=0.0),
}
COLOURS = {"quaking_aspen": "#4f9a3a", "black_tupelo": "#a0522d", "sassafras": "#d4a017",
           "growth": "#3a6ea5"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(ROOT / "out" / "experiments" / "forest"))
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 4, figsize=(19, 5.2))
    results = {}
    for ax, (title, kw) in zip(axes, SPECS.items()):
        st = layout(StandSpec(plot=HA, density=400, seed=1, **kw))
        xz = st.positions[:, [0, 2]]
        d = np.hypot(xz[:, None, 0] - xz[None, :, 0], xz[:, None, 1] - xz[None, :, 1])
        np.fill_diagonal(d, np.inf)
        results[title] = {"trees": len(st), "clark_evans_R": st.clark_evans(),
                          "nn_min_m": float(d.min()), "nn_mean_m": float(d.min(1).mean())}
        ax.scatter(xz[:, 0], xz[:, 1], s=6, c="#2f6b2f")
        ax.set_title(f"{title}\n{len(st)} trees, Clark-Evans R = {st.clark_evans():.2f}",
                     fontsize=10)
    ground = rolling_ground(HA, slope_deg=15.0, aspect_deg=180.0, roughness=0.6,
                            roughness_scale=15.0, seed=2, resolution=1.0)
    mix = {"quaking_aspen": 3, "black_tupelo": 1, "sassafras": 1, "growth": 1}
    st = layout(StandSpec(plot=[2, 2, 98, 98], density=300, mix=mix, min_spacing=3.0, seed=3),
                ground)
    floor = scatter_floor(ground, plot=[2, 2, 98, 98], logs=12, rocks=25, seed=4,
                          avoid=st.positions[:, [0, 2]], clearance=0.8)
    ax = axes[3]
    x0, z0, x1, z1 = ground.bounds
    im = ax.imshow(ground.heights, origin="lower", extent=(x0, x1, z0, z1), cmap="cividis")
    # (origin lower + the inverted axis below: row j = z0 + j dz stays at its z)
    for sp, c in COLOURS.items():
        m = st.species == sp
        ax.scatter(st.positions[m, 0], st.positions[m, 2], s=8, c=c, label=f"{sp} ({m.sum()})")
    for o in floor:
        v = o.vertices
        ax.fill(*(v[:, [0, 2]][np.argsort(np.arctan2(v[:, 2] - o.centre[2],
                                                     v[:, 0] - o.centre[0]))].T),
                color="#5b4636" if o.kind == "log" else "#8c8c8c", lw=0)
    ax.set_title("mixed stand, 300/ha, on a 15 deg south-facing rolling slope\n"
                 "(logs brown, rocks grey; colour: ground height)", fontsize=10)
    ax.legend(fontsize=7, loc="lower left")
    fig.colorbar(im, ax=ax, label="ground height y [m]", fraction=0.046)
    dy = st.positions[:, 1] - ground.height(st.positions[:, 0], st.positions[:, 2])
    results["mixed on slope"] = {"trees": len(st), "logs": 12, "rocks": 25,
                                 "species": {k: int((st.species == k).sum()) for k in mix},
                                 "max_base_off_ground_m": float(np.abs(dy).max()),
                                 "ground_y_range_m": [float(ground.heights.min()),
                                                      float(ground.heights.max())]}
    for ax in axes:
        ax.set_aspect("equal")
        ax.invert_yaxis()                       # a map: north (-z) up
        ax.set_xlabel("x (east) [m]")
        ax.set_ylabel("z (south) [m], north up")
    fig.tight_layout()
    fig.savefig(out / "stand_layouts.png", dpi=110)
    (out / "results.json").write_text(json.dumps(results, indent=1))
    print(json.dumps(results, indent=1))
    print(f"wrote {out / 'stand_layouts.png'}")


if __name__ == "__main__":
    main()
