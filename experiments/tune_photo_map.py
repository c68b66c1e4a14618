"""The photographed-map path (docs/tuning.md): a 20-day relaxed run of Bryum on the moss garden
is "photographed" from 5 m above (``tune.photo.render_cover_image``: an 8-bit colour image and a
16-bit classified map), mapped back to a cover per triangle (``cover_from_image``) and S1 is
fitted to it from 42 (truth 60). Prints the seen triangles, the round-trip errors and the fits;
writes the photograph.

    python experiments/tune_photo_map.py --out out/tune_photo
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import drjit as dr
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune import photo  # noqa: E402

CAM = {"origin": [0.0, 5.0, 0.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 0.0, -1.0],
       "fov": 26.0, "width": 400, "height": 400}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=int, default=20)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--out", default="out/tune_photo")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    data = tune.prepare(ROOT / "scenes" / "moss_garden" / "scenario.toml", days=a.days,
                        species=["bryum_argenteum"], photons=100_000, light_every=10)
    model = tune.SmoothMossModel(data, temperature=0.05)
    with dr.suspend_grad():
        cover = np.asarray(model.run({"S1": 60.0}).cover, float)
    (out / "camera.json").write_text(json.dumps(CAM, indent=1))
    maps = {}
    for name, kw in (("colour8", {"mode": "colour"}), ("gray16", {"mode": "gray", "bits": 16})):
        png = out / f"garden_{name}.png"
        photo.render_cover_image(cover, CAM, data.scene, data.index, png, **kw)
        maps[name] = photo.cover_from_image(png, CAM, data.scene, data.index, living=data.living,
                                            mode=kw["mode"])
        seen = np.isfinite(maps[name])
        print(f"{name}: {seen.sum()} of {data.n} triangles seen "
              + ", ".join(f"{k} {seen[sl].mean():.3f}" for k, sl in data.shape_slices.items())
              + f"; round trip max error {np.nanmax(np.abs(maps[name] - cover)):.2e}", flush=True)
    for name, loss in (("gray16", "sqrt"), ("colour8", "sqrt"), ("colour8", "mse")):
        r = tune.fit(model, maps[name], params=["S1"], init={"S1": 42.0}, steps=a.steps, lr=0.15,
                     loss=loss, out=None, progress=False)
        print(f"fit S1 to {name} ({loss} loss): 42 -> {r.values['S1']:.2f} (truth 60), loss "
              f"{r.history[0]['loss']:.3e} -> {r.loss:.3e}", flush=True)


if __name__ == "__main__":
    main()
