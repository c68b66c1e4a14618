"""Before/after pictures of the render's trees: leaves, bark, knots and litter (docs/images).

    .venv/bin/python experiments/render_trees_figures.py --stand RUN_DIR [--before REF] [--spp 32]

RUN_DIR is a forest-stand run of three years with snapshots (``mitsuba-veg run
scenes/forest_stand/scenario.toml --out RUN_DIR --days 1095``). The "before" pictures are made by
the same code of this script run on the package as it was at git ref REF (default ``ee03fd4``,
before the render drew leaf shapes, swept tubes, bark and litter: ``git archive`` into a temporary
folder put first on the Python path), the "after" ones on this checkout. Writes (each two panels
of 480 x 270 side by side, labelled, palette-quantised under 300 kB):

- docs/images/render_leaves_stand.png: a stand tree's crown in autumn (third year, 20 October)
- docs/images/render_leaves_aspen.png: a Weber-Penn aspen's crown against the light
- docs/images/render_bark.png: the trunk and limbs of paper 001's courtyard tree
- docs/images/render_knots.png: a knot on an aspen's trunk (paper 004)
- docs/images/render_litter.png: the stand's floor in late November of the third year

Rendering uses Mitsuba 3 (llvm_ad_spectral) on the CPU; 8-10 minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"
W, H = 480, 270
BEFORE = "ee03fd4"


# ---- panels (run with whichever mitsuba_veg is first on the path) --------------------------
def _scenario(path_or_scn, cameras):
    from mitsuba_veg.scenario import Scenario, load_scenario
    scn = path_or_scn if isinstance(path_or_scn, Scenario) else load_scenario(path_or_scn)
    data = dict(scn.data)
    data["render"] = dict(data.get("render") or {})
    data["render"]["cameras"] = cameras
    return Scenario(scn.path, data)


def _render(scn, trees, date, cam, out, spp, moss=None, moss_size=0.01, hour=10.0,
            terrain=None):
    from mitsuba_veg.render.scene import RenderOptions, build_scene
    from mitsuba_veg.render.still import render
    from mitsuba_veg.render import film
    opts = RenderOptions(width=W, height=H, spp=spp, camera=cam, hour=hour)
    t0 = time.perf_counter()
    rs = build_scene(scn, moss, moss_size=moss_size, trees=trees, date=date, options=opts,
                     terrain=terrain)
    t1 = time.perf_counter()
    img = render(rs)
    rgb8, _ = film.to_srgb8(img["rgb"], None)
    film.write_png(out, rgb8)
    return {"build_s": t1 - t0, "render_s": img["seconds"], "info": {
        k: v for k, v in rs.info.items() if isinstance(v, (int, float, str))}}


def _knot_view(tree):
    """Camera on the thickest level-1 knot of the trunk (origin, target)."""
    from mitsuba_veg.trees.junction import stem_structure
    st = stem_structure(tree)
    heads = (tree.kind == 1) & ~st["cont"] & (tree.level == 1)
    k = np.nonzero(heads)[0]
    c = k[np.argmax(tree.radius_start[k])]
    p = tree.parent[c]
    d = tree.end[c] - tree.start[c]
    radial = np.array([d[0], 0.0, d[2]])
    radial /= max(np.linalg.norm(radial), 1e-9)
    rp = tree.radius_start[p]
    side = np.cross([0.0, 1.0, 0.0], radial)
    target = tree.start[c] + 0.5 * rp * radial
    origin = target + 9.0 * rp * (0.8 * radial + 0.5 * side + np.array([0, 0.2, 0]))
    return origin.tolist(), target.tolist()


def panels(out: Path, stand: str | None, spp: int) -> dict:
    """Render every panel with the mitsuba_veg on the path into ``out`` (PNG files)."""
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    from mitsuba_veg.render.trees import make_tree
    out.mkdir(parents=True, exist_ok=True)
    court = ROOT / "scenes" / "courtyard" / "scenario.toml"
    log = {}
    # an aspen (Weber-Penn, knots on) in the courtyard's light, against the light
    aspen = make_tree({"preset": "quaking_aspen", "seed": 3, "height": 5.0,
                       "position": [0.0, 0.0, 0.0]})
    aspen.leaves.attrs["autumn_tau"] = np.full(len(aspen.leaves), 0.1)
    c = aspen.leaves.position.mean(0)
    ko, kt = _knot_view(aspen)
    cams = {"back": {"origin": [c[0] - 1.0, c[1] - 0.9, c[2] + 1.7], "target": c.tolist(),
                     "fov": 45.0},
            "knot": {"origin": ko, "target": kt, "fov": 40.0}}
    scn = _scenario(court, cams)
    date = dt.date(2026, 6, 21)
    log["leaves_aspen"] = _render(scn, [aspen], date, "back", out / "leaves_aspen.png", spp,
                                  hour=15.5)
    log["knots"] = _render(scn, [aspen], date, "knot", out / "knots.png", spp, hour=10.0)
    # paper 001's tree by the courtyard's house
    grown = make_tree({"model": "growth", "generations": 8, "seed": 1,
                       "growth": {"unit": 0.06}, "position": [0.0, 0.0, 0.0]})
    scn = _scenario(court, {"trunk": {"origin": [0.9, 0.7, 0.9], "target": [0.0, 0.8, 0.0],
                                      "fov": 40.0}})
    log["bark"] = _render(scn, [grown], date, "trunk", out / "bark.png", spp)
    if stand:
        log.update(_stand_panels(Path(stand), out, spp))
    (out / "log.json").write_text(json.dumps(log, indent=1, default=str))
    return log


def _ground_y(scn, x, z):
    """Height of the scenario's terrain at (x, z) [m] (a ray cast straight down)."""
    import mitsuba as mi
    scene = scn.load_scene(daylight=False)
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(float(x), 100.0, float(z)),
                                      mi.Vector3f(0.0, -1.0, 0.0)))
    return 100.0 - float(si.t[0]) if bool(si.is_valid()[0]) else 0.0


def _stand_panels(run_dir: Path, out: Path, spp: int) -> dict:
    from mitsuba_veg.render.history import load_run
    from mitsuba_veg.render.scene import Terrain
    from mitsuba_veg.render.world import trees_for_run
    run = load_run(run_dir)
    log = {}
    for name, date, hour in (("leaves_stand", dt.date(2028, 10, 20), 11.0),
                             ("litter", dt.date(2028, 11, 25), 11.0)):
        day = (date - run.start).days + 1
        trees, seasons = trees_for_run(run, None, day)
        for s in seasons:
            s.apply(date)
        base = np.array([t.start[0] for t in trees])
        # the east-most tree, seen from outside the stand (the crowns close above the floor)
        i = int(np.argmax(base[:, 0]))
        t = trees[i]
        b = t.start[0]
        p = t.leaves.position
        if name == "leaves_stand":
            c = np.array([p[:, 0].max(), np.percentile(p[:, 1], 60), b[2]])
            cam = {"origin": (c + [2.0, 0.4, 0.8]).tolist(), "target": c.tolist(),
                   "fov": 45.0}
        else:        # inside the plot's east edge, looking west and down onto the floor
            x0 = min(p[:, 0].max() + 1.0, 14.0) if len(p) else b[0] + 2.0
            cam = {"origin": [x0, _ground_y(run.scenario, x0, b[2] + 0.5) + 1.4, b[2] + 0.5],
                   "target": [x0 - 3.0, _ground_y(run.scenario, x0 - 3.0, b[2]), b[2]],
                   "fov": 60.0}
        scn = _scenario(run.scenario, {name: cam})
        terrain = Terrain.from_scenario(scn)
        frame = run.frame(min(day, run.final_day))
        log[name] = _render(scn, trees, date, name, out / f"{name}.png", spp, moss=frame.moss,
                            moss_size=run.moss_size, hour=hour, terrain=terrain)
        log[name]["day"] = day
    return log


# ---- the figures -----------------------------------------------------------------------------
def _label(img, text):
    from PIL import Image, ImageDraw
    im = Image.fromarray(img)
    d = ImageDraw.Draw(im)
    d.rectangle([0, 0, 8 + 6 * len(text), 16], fill=(0, 0, 0))
    d.text((4, 2), text, fill=(255, 255, 255))
    return np.asarray(im)


def _pair(before: Path, after: Path, dest: Path, labels):
    from PIL import Image
    a = np.asarray(Image.open(before).convert("RGB"))
    b = np.asarray(Image.open(after).convert("RGB"))
    img = np.concatenate([_label(a, labels[0]), np.full((H, 4, 3), 255, np.uint8),
                          _label(b, labels[1])], 1)
    im = Image.fromarray(img).quantize(colors=192, method=Image.Quantize.MEDIANCUT)
    im.save(dest, optimize=True)
    return dest.stat().st_size


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stand", help="a three-year forest-stand run folder")
    ap.add_argument("--before", default=BEFORE, help="git ref of the 'before' pictures")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--panels-only", metavar="DIR", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.panels_only:
        print(json.dumps(panels(Path(a.panels_only), a.stand, a.spp), default=str))
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = tmp / "before_src"
        src.mkdir()
        arc = subprocess.run(["git", "-C", str(ROOT), "archive", a.before],
                             check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(src)], input=arc, check=True)
        runs = {"before": str(src), "after": str(ROOT)}
        for k, path in runs.items():
            env = dict(os.environ, PYTHONPATH=path)
            cmd = [sys.executable, str(Path(__file__).resolve()), "--panels-only",
                   str(tmp / k), "--spp", str(a.spp)] + (["--stand", a.stand] if a.stand
                                                          else [])
            print(k, "...", flush=True)
            subprocess.run(cmd, check=True, env=env, cwd=str(tmp))
            print((tmp / k / "log.json").read_text())
        OUT.mkdir(parents=True, exist_ok=True)
        names = {"leaves_aspen": ("leaves: ovals", "leaves: aspen outline, folded"),
                 "knots": ("knots: cones", "knots: bark-covered swellings"),
                 "bark": ("bark: straight segments, plain", "bark: swept tubes, texture"),
                 "leaves_stand": ("stand leaves: quads", "stand leaves: ovate, folded"),
                 "litter": ("floor: no litter", "floor: litter")}
        for k, lab in names.items():
            b, f = tmp / "before" / f"{k}.png", tmp / "after" / f"{k}.png"
            if b.exists() and f.exists():
                dest = OUT / f"render_{k}.png"
                print(dest, _pair(b, f, dest, lab), "bytes")


if __name__ == "__main__":
    main()
