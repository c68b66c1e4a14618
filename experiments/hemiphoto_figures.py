"""The figures of docs/hemiphoto.md from the command outputs it names.

    python experiments/hemiphoto_figures.py --stand /work/runs/hemi_stand4_photos \
        --colour /work/runs/hemi_stand4_colour --courtyard /work/runs/hemi_courtyard_ls2

- ``docs/images/hemiphoto_stand_comparison.png``: ``comparison.png`` of the stand's
  ``hemiphoto --years --truth`` run;
- ``docs/images/hemiphoto_stand_years.png``: the colour and binary photographs of one point over
  the years (``hemiphoto --years --colour``), two by two;
- ``docs/images/hemiphoto_courtyard.png``: the courtyard light study's photograph under the
  aspen and its PAR by hour.
"""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
IMAGES = ROOT / "docs" / "images"


def montage(paths, out, columns=2, width=640):
    """Images side by side, ``columns`` a row, each scaled to ``width`` pixels."""
    ims = [Image.open(p).convert("RGB") for p in paths]
    ims = [im.resize((width, int(im.height * width / im.width)), Image.LANCZOS) for im in ims]
    h = max(im.height for im in ims)
    rows = (len(ims) + columns - 1) // columns
    canvas = Image.new("RGB", (columns * width, rows * h), "white")
    for k, im in enumerate(ims):
        canvas.paste(im, ((k % columns) * width, (k // columns) * h))
    # a 256-colour palette: a quarter of the bytes, the photographs' look kept
    canvas.quantize(256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    return out


def courtyard(folder: Path, out: Path):
    import pandas as pd
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = pd.read_csv(folder / "sensors.csv")
    d = d[(d.band == "par") & (d.component != "diffuse")]
    fig, ax = plt.subplots(1, 2, figsize=(13, 5.2), constrained_layout=True,
                           gridspec_kw={"width_ratios": [1.1, 1]})
    photo = Image.open(folder / "hemiphotos" / "under_aspen_2026-06-21.png").convert("RGB")
    ax[0].imshow(np.asarray(photo))
    ax[0].set_axis_off()
    for name, c in (("open_sand", "tab:orange"), ("under_aspen", "tab:green")):
        for comp, ls in (("total", "-"), ("direct", ":")):
            s = d[(d.sensor == name) & (d.component == comp)]
            hours = pd.to_datetime(s.time.str[:19]).dt.hour + 0.5
            ax[1].plot(hours, s.value, ls=ls, color=c, marker="o" if comp == "total" else None,
                       label=f"{name.replace('_', ' ')}: {comp}")
    ax[1].set_xlabel("hour (local, UTC+9), 21 June 2026")
    ax[1].set_ylabel("PPFD [µmol m$^{-2}$ s$^{-1}$] (hour mean)")
    ax[1].set_xlim(3, 20)
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3)
    ax[1].set_title("a plant under the aspen and one in the open sand", fontsize=10)
    fig.savefig(out, dpi=80)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stand", type=Path, required=True)
    ap.add_argument("--colour", type=Path, required=True)
    ap.add_argument("--courtyard", type=Path, required=True)
    a = ap.parse_args(argv)
    IMAGES.mkdir(parents=True, exist_ok=True)
    print(shutil.copyfile(a.stand / "comparison.png", IMAGES / "hemiphoto_stand_comparison.png"))
    print(montage(sorted(a.colour.glob("p1_*.png")), IMAGES / "hemiphoto_stand_years.png"))
    print(courtyard(a.courtyard, IMAGES / "hemiphoto_courtyard.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
