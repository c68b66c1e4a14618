"""Spectral light under leaves: PAR and red:far-red under random leaf canopies versus LAI (green
and red autumn leaves), and light-study maps under a tree in summer and in autumn.

    .venv/bin/python experiments/light_study_canopy.py [--out out/foliage] [--photons 3000000]

Writes ``light_study_lai.png`` (+ ``light_study_lai.json``) and two light studies,
``light_study_green/`` and ``light_study_autumn/`` (maps PNG, npz, leaves.csv, summary.json) of
the same 6000-leaf tree at noon on 15 October, 35° N, with green leaves and with the leaves'
autumn stages of that day (from the insolation model).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def canopy_point(lai, tau, photons, elevation=60.0, seed=0):
    import mitsuba_veg as mv
    from mitsuba_veg.foliage.canopy import random_leaf_cloud
    from mitsuba_veg.foliage.light_study import open_reference, tree_scene
    from mitsuba_veg.light.clear_sky import daylight_from_angles

    leaves = random_leaf_cloud(lai, (-3, 0.3, -3), (3, 1.5, 3), leaf_size=0.08, seed=seed)
    sc, _ = tree_scene(leaves, emitters=daylight_from_angles(180.0, elevation),
                       tau=np.full(len(leaves), tau), n_classes=1, ground_extent=6.0,
                       ground_resolution=30)
    res = mv.light.photon_irradiance(sc, photons=photons, seed=seed)
    c = res.index.centroids[res.index.shape_slice("ground")]
    m = (np.abs(c[:, 0]) < 1.0) & (np.abs(c[:, 2]) < 1.0)
    pf = res.photon_flux_density
    ref = open_reference(180.0, elevation)
    shade_r = pf("ground", "red", emitter="sky")[m].sum() + pf("ground", "red", emitter="sun",
                                                              component="indirect")[m].sum()
    shade_f = pf("ground", "far_red", emitter="sky")[m].sum() + pf(
        "ground", "far_red", emitter="sun", component="indirect")[m].sum()
    return {"lai": lai, "tau": tau, "ppfd_fraction": float(pf("ground", "par")[m].mean()
                                                          / ref["ppfd"]),
            "rfr": float(pf("ground", "red")[m].sum() / pf("ground", "far_red")[m].sum()),
            "rfr_shade": float(shade_r / shade_f), "open_rfr": ref["rfr"],
            "beer_lambert_beam": float(np.exp(-0.5 * lai / np.sin(np.radians(elevation)))),
            "seconds": res.seconds}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/foliage")
    ap.add_argument("--photons", type=int, default=3_000_000)
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import mitsuba_veg.foliage  # noqa: F401
    from mitsuba_veg.foliage.autumn import AutumnParams, autumn_time
    from mitsuba_veg.foliage.canopy import sphere_crown_tree
    from mitsuba_veg.foliage.insolation import leaf_insolation, sun_path
    from mitsuba_veg.foliage.light_study import run_light_study

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    lais = [0.5, 1.0, 2.0, 3.0, 4.0, 6.0]
    rows = [canopy_point(l, tau, a.photons) for tau in (0.0, 1.0) for l in lais]
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    for tau, col, name in ((0.0, "green", "green leaves (stage 1)"),
                           (1.0, "crimson", "red autumn leaves (stage 7)")):
        r = [x for x in rows if x["tau"] == tau]
        L = [x["lai"] for x in r]
        axs[0].semilogy(L, [x["ppfd_fraction"] for x in r], "o-", color=col, label=name)
        axs[1].plot(L, [x["rfr"] for x in r], "o-", color=col, label=f"{name}, all light")
        axs[1].plot(L, [x["rfr_shade"] for x in r], "s--", color=col,
                    label=f"{name}, shade (no sunflecks)")
    axs[0].semilogy(lais, [np.exp(-0.5 * l / np.sin(np.radians(60))) for l in lais], "k:",
                    label="direct beam exp(-G LAI / cos θ)")
    axs[0].set_ylabel("PPFD under the canopy / open PPFD")
    axs[0].legend(fontsize=8)
    axs[1].axhline(rows[0]["open_rfr"], color="k", lw=1, ls=":", label="open daylight")
    axs[1].axhline(0.5, color="grey", lw=0.8)
    axs[1].set_ylabel("red : far-red (photons) on the ground")
    axs[1].set_ylim(0, 1.5)
    axs[1].legend(fontsize=7, loc="upper right", ncol=2)
    for ax in axs:
        ax.set_xlabel("leaf area index (spherical leaf angles)")
        ax.grid(alpha=0.3, which="both")
    fig.suptitle("Under a random leaf canopy (6 m x 6 m, 0.3-1.5 m high; ground centre 2 m x 2 m),"
                 " sun 60° + sky, photon pass with veg_leaf PROSPECT-D leaves", fontsize=10)
    p1 = out / "light_study_lai.png"
    fig.savefig(p1, dpi=90)
    plt.close(fig)
    (out / "light_study_lai.json").write_text(json.dumps(rows, indent=2))
    t_lai = time.perf_counter() - t0

    # a tree in summer (green) and in autumn (its leaves' stages on 15 Oct + 30 days)
    tree = sphere_crown_tree(6000, seed=1)
    path = sun_path(35.0, 139.0, "2026-10-15", 30)
    st = autumn_time(leaf_insolation(tree, path), AutumnParams(), seed=0)
    tau = st.tau(-1)
    when = "2026-11-14T12:00:00+09:00"
    sums = {}
    for name, t in (("green", None), ("autumn", tau)):
        s = run_light_study(tree, out / f"light_study_{name}", photons=a.photons, when=when,
                            tau=t)
        sums[name] = {"ground": s["ground"], "leaves": s["leaves"]}
        print(f"{name}: ground PPFD {s['ground']['ppfd']:.0f} "
              f"({100 * s['ground']['ppfd_fraction_of_open']:.1f} % of open), R:FR min "
              f"{s['ground']['rfr_min']:.2f}, leaves R:FR mean {s['leaves']['rfr_mean']:.3f}")
    for r in rows:
        print(f"LAI {r['lai']:.1f} tau {r['tau']:.0f}: PPFD {100 * r['ppfd_fraction']:.1f} % of "
              f"open, R:FR {r['rfr']:.3f}, shade R:FR {r['rfr_shade']:.3f}")
    (out / "light_study_tree.json").write_text(json.dumps(sums, indent=2))
    print(f"LAI sweep {t_lai:.1f} s; wrote {p1}, {out / 'light_study_green'}, "
          f"{out / 'light_study_autumn'}")


if __name__ == "__main__":
    main()
