"""Paper 001's results (Yoshizawa 2007, §3.2-3.3) reproduced: figures and numbers.

    .venv/bin/python experiments/trees_001_results.py [--out out/trees_001] [--seed 0]

Table 3.1 parameters, G = 10, unit = 0.25 m. Writes into --out:

- ``fig_genetic.png``: side views for branch angle 30/45/60/90° (fig 3.2), death threshold
  0.1-0.4 (fig 3.5), far-red attenuation 0.3/0.7/0.9 = weaker/stronger shade signal (fig 3.9),
  and top views for phyllotaxis 1/2, 2/5, 5/8 (fig 3.11);
- ``fig_two_trees.png`` (fig 3.12), ``fig_forest_3x3.png`` (fig 3.14), ``fig_wall.png``
  (fig 3.16-3.17), ``fig_slope.png`` (fig 3.19-3.20): side and top views with the obstacles;
- ``results.json``: every number the tests assert (tests/test_tree_paper001.py).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/trees_001")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.trees import Environment, GrowthParams, grow, grow_forest
    from mitsuba_veg.trees.analysis import (crown_shift, flatness, main_axis_length,
                                            outward_shift)
    from mitsuba_veg.trees.figures import draw, picture

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    P = GrowthParams()
    seed = a.seed
    res = {"seed": seed, "params": P.to_dict()}
    t0 = time.perf_counter()
    ground = Environment.flat_ground(80)

    # ---- genetic differences (§3.2) -------------------------------------------------------
    rows = [("branch angle θ [deg]", "branch_angle", [30.0, 45.0, 60.0, 90.0], "side"),
            ("death threshold T_D", "death_threshold", [0.1, 0.2, 0.3, 0.4], "side"),
            ("far-red attenuation α_fr", "alpha_far_red", [0.3, 0.7, 0.9], "side"),
            ("phyllotaxis", "phyllotaxis", ["1/2", "2/5", "5/8"], "top")]
    fig, axs = plt.subplots(len(rows), 4, figsize=(16, 15))
    for r, (label, field, values, view) in enumerate(rows):
        entry = []
        for c, v in enumerate(values):
            t = grow(P.replace(**{field: v}), 10, seed=seed)
            m = t.metrics()
            e = {"value": v, "height": m["height"], "crown_radius": m["crown_radius"],
                 "live_branches": m["live_branches"], "dead_branches": m["dead_branches"],
                 "flatness": flatness(t), "main_axis_length": main_axis_length(t),
                 "median_red_far_red": float(np.median(t.attrs["red_far_red"]))}
            entry.append(e)
            draw(axs[r, c], t, view, sphere_alpha=0.05)
            axs[r, c].set_title(f"{label} = {v}\nh {m['height']:.1f} m, r {m['crown_radius']:.1f}"
                                f" m, {m['live_branches']} live, flat {e['flatness']:.2f}",
                                fontsize=8)
        for c in range(len(values), 4):
            axs[r, c].axis("off")
        res[field] = entry
    fig.suptitle("Paper 001 §3.2: genetic differences (table 3.1 otherwise)", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "fig_genetic.png", dpi=90)
    plt.close(fig)

    # ---- two trees (§3.3.1) ---------------------------------------------------------------
    two = grow_forest([(-3.0, 0.0, 0.0), (3.0, 0.0, 0.0)], P, 10, ground, seed)
    alone = grow(P, 10, scene=ground, seed=seed)
    res["two_trees"] = {"outward_shift_m": outward_shift(two).tolist(),
                        "lone_tree_shift_m": crown_shift(alone).tolist()}
    picture(two, out / "fig_two_trees.png", env=None, colors=["#6b3d14", "#1f4e79"],
            title=f"Two trees 6 m apart: crowns move apart by "
                  f"{np.round(outward_shift(two), 2).tolist()} m (lone tree "
                  f"{np.linalg.norm(crown_shift(alone)):.2f} m)")

    # ---- 3 x 3 forest (§3.3.2) ------------------------------------------------------------
    pos = [(i * 12.0, 0.0, j * 12.0) for j in (-1, 0, 1) for i in (-1, 0, 1)]
    tf = time.perf_counter()
    forest = grow_forest(pos, P, 10, ground, seed)
    tf = time.perf_counter() - tf
    ms = [t.metrics() for t in forest]
    res["forest_3x3"] = {
        "spacing_m": 12.0, "seconds": tf,
        "outward_shift_m": outward_shift(forest, (0.0, 0.0)).tolist(),
        "crown_radius_m": [m["crown_radius"] for m in ms],
        "height_m": [m["height"] for m in ms],
        "live_branches": [m["live_branches"] for m in ms]}
    fig, axs = plt.subplots(1, 2, figsize=(14, 6.5))
    draw(axs[0], forest, "top", sphere_alpha=0.04)
    bases = np.array([m["base"] for m in ms])
    cen = np.array([m["crown_centroid"] for m in ms])
    axs[0].quiver(bases[:, 0], bases[:, 2], cen[:, 0] - bases[:, 0], cen[:, 2] - bases[:, 2],
                  angles="xy", scale_units="xy", scale=1, color="red", width=0.004, zorder=5)
    axs[0].set_title("top view; red: base -> crown centroid", fontsize=9)
    draw(axs[1], forest[3:6], "side", sphere_alpha=0.05)
    axs[1].set_title(f"middle row from the side; centre tree h {ms[4]['height']:.1f} m, "
                     f"r {ms[4]['crown_radius']:.1f} m; corner mean h "
                     f"{np.mean([ms[k]['height'] for k in (0, 2, 6, 8)]):.1f} m, r "
                     f"{np.mean([ms[k]['crown_radius'] for k in (0, 2, 6, 8)]):.1f} m",
                     fontsize=9)
    fig.suptitle("Paper 001 §3.3.2: 3 x 3 forest, 12 m apart", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "fig_forest_3x3.png", dpi=90)
    plt.close(fig)

    # ---- wall (§3.3.3) and slope (§3.3.4) -------------------------------------------------
    wall = Environment().add_ground(60).add_box((-4, 0, -15), (-3, 20, 15), max_edge=2.0)
    tw = grow(P, 10, scene=wall, seed=seed)
    res["wall"] = {"shift_away_m": float(crown_shift(tw)[0]),
                   "far_side_fraction": float(np.mean(tw.attrs["leaf_sphere_center"][:, 0] > 0))}
    picture(tw, out / "fig_wall.png", env=wall,
            title=f"Tree 3 m east of a 20 m wall: crown {res['wall']['shift_away_m']:.2f} m "
                  f"east, {100 * res['wall']['far_side_fraction']:.0f} % of leaf spheres east")
    slope = Environment().add_slope(30.0, 60.0)
    ts = grow(P, 10, position=(0.0, 0.0), scene=slope, seed=seed)
    res["slope"] = {"angle_deg": 30.0, "downhill_shift_m": float(crown_shift(ts)[0]),
                    "flat_ground_shift_m": float(crown_shift(alone)[0])}
    picture(ts, out / "fig_slope.png", env=slope,
            title=f"Tree on a 30° slope (down to +x): crown {res['slope']['downhill_shift_m']:.2f}"
                  f" m downhill (flat ground: {res['slope']['flat_ground_shift_m']:.2f} m)")
    res["seconds"] = time.perf_counter() - t0
    (out / "results.json").write_text(json.dumps(res, indent=2, default=str))
    print(json.dumps({k: v for k, v in res.items() if k != "params"}, indent=1, default=str))
    print(f"wrote {out}/fig_genetic.png, fig_two_trees.png, fig_forest_3x3.png, fig_wall.png, "
          f"fig_slope.png, results.json ({res['seconds']:.1f} s)")


if __name__ == "__main__":
    main()
