"""One maple leaf through Ishikura's stages 1-7 (paper 003 fig. 5) and its PROSPECT-D spectra.

    .venv/bin/python experiments/autumn_leaf_strip.py [--out out/foliage]

Writes ``autumn_leaf_strip.png``: top row, the Barnsley maple leaf (chaos game, 300k points)
coloured point by point from its aging (margin and tip first); bottom, the leaf-mean
reflectance and transmittance spectra per stage (400-900 nm), with the red and far-red bands.
Prints the area fractions of the tissue states per stage.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/foliage")
    ap.add_argument("--points", type=int, default=300_000)
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import mitsuba_veg.foliage as fo
    from mitsuba_veg.foliage.ifs import leaf_image, maple_leaf

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    leaf = maple_leaf(a.points, seed=0)
    t_leaf = time.perf_counter() - t0
    tb = fo.stage_table()
    fig = plt.figure(figsize=(15, 6.6), constrained_layout=True)
    gs = fig.add_gridspec(2, 7, height_ratios=[1.0, 1.05])
    rows = {}
    for s in range(1, 8):
        ax = fig.add_subplot(gs[0, s - 1])
        ax.imshow(leaf_image(leaf, stage=float(s), size=260))
        ax.set_axis_off()
        w = leaf.state_weights(float(s)).mean(0)
        rows[s] = {"green": float(w[0]), "dark_green_red": float(w[1]), "red": float(w[2]),
                   "Cab": float(tb.cab[s - 1]), "Car": float(tb.car[s - 1]),
                   "Anth": float(tb.anth[s - 1])}
        ax.set_title(f"stage {s}\nCab {tb.cab[s - 1]:.0f}  Car {tb.car[s - 1]:.1f}  "
                     f"Anth {tb.anth[s - 1]:.0f}", fontsize=9)
    spec = fo.leaf_spectra(stage=np.arange(1, 8, dtype=float))
    wl = spec.wavelength
    m = wl <= 900
    line_rgb = ["#1b7837", "#5aae61", "#a6911c", "#8c6d31", "#d95f02", "#d6604d", "#b2182b"]
    axr = fig.add_subplot(gs[1, :4])
    axt = fig.add_subplot(gs[1, 4:])
    for i in range(7):
        c = line_rgb[i]
        axr.plot(wl[m], spec.reflectance[i, m], color=c, label=f"stage {i + 1}")
        axt.plot(wl[m], spec.transmittance[i, m], color=c, label=f"stage {i + 1}")
    for ax, name in ((axr, "reflectance"), (axt, "transmittance")):
        ax.axvspan(655, 665, color="red", alpha=0.15, lw=0)
        ax.axvspan(725, 735, color="darkred", alpha=0.15, lw=0)
        ax.set_xlabel("wavelength [nm]")
        ax.set_ylabel(name)
        ax.set_xlim(400, 900)
        ax.set_ylim(0, 0.6)
        ax.grid(alpha=0.3)
    axr.legend(fontsize=8, ncol=2, loc="upper left")
    axr.set_title("leaf-mean spectra (PROSPECT-D), shaded: red 655-665, far-red 725-735 nm",
                  fontsize=9)
    fig.suptitle("Barnsley maple leaf through Ishikura's 7 autumn stages (colour from the "
                 "margin and tip inwards; contents in µg cm$^{-2}$)", fontsize=11)
    path = out / "autumn_leaf_strip.png"
    fig.savefig(path, dpi=85)
    plt.close(fig)
    summary = {"leaf_points": a.points, "leaf_seconds": t_leaf, "stages": rows,
               "png": str(path)}
    (out / "autumn_leaf_strip.json").write_text(json.dumps(summary, indent=2))
    for s, r in rows.items():
        print(f"stage {s}: green {r['green']:.2f}  dark green-red {r['dark_green_red']:.2f}  "
              f"red {r['red']:.2f}")
    print(f"leaf ({a.points} points) in {t_leaf:.2f} s -> {path}")


if __name__ == "__main__":
    main()
