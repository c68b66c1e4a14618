"""The render page's denoiser figure: a crop of the courtyard's midsummer overview at 480x270,
32 spp as rendered, 32 spp denoised, and 512 spp (``make demo`` first, for ``out/demo/world``).

    python experiments/render_denoise_figure.py [RUN_DIR] --out docs/images/render_denoise.jpg
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir", nargs="?", default="out/demo/world")
    ap.add_argument("--out", default="docs/images/render_denoise.jpg")
    ap.add_argument("--crop", default="40,40,280,175", help="x0,y0,x1,y1 of the 480x270 image")
    a = ap.parse_args(argv)
    import mitsuba_veg  # noqa: F401
    from PIL import Image, ImageDraw
    from mitsuba_veg.render import film, history, scene as S, still
    from mitsuba_veg.render.world import trees_for_run

    s = json.loads((Path(a.run_dir) / "summary.json").read_text())
    day = max(s["days_record"], key=lambda r: sum(t["absorbed_par_W"]
                                                   for t in r["trees"].values()))["day"]
    run = history.load_run(a.run_dir)
    fr = run.frame(day)
    trees, seasons = trees_for_run(run, None, day)
    for x in seasons:
        x.apply(fr.date)
    terrain = S.Terrain.from_scenario(run.scenario)
    imgs = []
    for spp in (32, 512):
        o = S.RenderOptions(width=480, height=270, spp=spp, camera="overview")
        rs = S.build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=trees,
                           date=fr.date, options=o, terrain=terrain)
        im = still.render(rs, denoise=spp < 512)
        imgs += [im["rgb"], im["display"]] if spp < 512 else [im["rgb"]]
    exposure = film.auto_exposure(imgs[-1])
    box = tuple(int(v) for v in a.crop.split(","))
    tiles = [Image.fromarray(film.to_srgb8(x, exposure)[0]).crop(box).resize(
        ((box[2] - box[0]) * 2, (box[3] - box[1]) * 2), Image.NEAREST) for x in imgs]
    w, h = tiles[0].size
    out = Image.new("RGB", (3 * w + 16, h), "white")
    for k, (t, label) in enumerate(zip(tiles, ("32 spp", "32 spp, denoised", "512 spp"))):
        out.paste(t, (k * (w + 8), 0))
        d = ImageDraw.Draw(out)
        d.rectangle([k * (w + 8) + 2, 2, k * (w + 8) + 8 + 7 * len(label), 18], fill="black")
        d.text((k * (w + 8) + 5, 4), label, fill="white")
    out.save(a.out, quality=88)
    err = [float(np.sqrt(np.mean((x - imgs[-1]) ** 2)) / np.mean(imgs[-1])) for x in imgs[:2]]
    print(f"{a.out}: RMS error / mean against 512 spp {err[0]:.3f} raw, {err[1]:.3f} denoised")


if __name__ == "__main__":
    main()
