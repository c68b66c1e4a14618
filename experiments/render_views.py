"""Render a run's day from named views, for the render page's before/after pictures.

Uses only what every version of the renderer offers (``build_scene``, ``render``, the film's
sRGB encoding and ``[render.cameras]`` views given in the scenario), so the same script renders
with the code of an earlier commit:

    python experiments/render_views.py RUN_DIR --out DIR --view corner=ox,oy,oz:tx,ty,tz:fov \\
        --preset overview --width 640 --height 360 --spp 32

``--view NAME=origin:target:fov`` adds a camera (metres, degrees), ``--preset NAME`` renders a
built-in preset of that code. Writes ``DIR/<name>.png``. ``--combine BEFORE_DIR AFTER_DIR
--out FILE`` puts the pictures of two such folders side by side, labelled.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def render_views(run_dir, out, views, presets, width, height, spp, day=None, scenario=None):
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.render import film, history, scene as S, still
    from mitsuba_veg.render.world import trees_for_run

    run = history.load_run(run_dir, scenario)
    day = run.final_day if day is None else day
    fr = run.frame(day)
    cams = run.scenario.data.setdefault("render", {}).setdefault("cameras", {})
    for name, (o, t, fov) in views.items():
        cams[name] = {"origin": o, "target": t, "fov": fov}
    trees, seasons = trees_for_run(run, None, day)
    for s in seasons:
        s.apply(fr.date)
    terrain = S.Terrain.from_scenario(run.scenario)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in list(views) + list(presets):
        o = S.RenderOptions(width=width, height=height, spp=spp, camera=name)
        rs = S.build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=trees,
                           date=fr.date, options=o, terrain=terrain)
        im = still.render(rs)
        img8, _ = film.to_srgb8(im.get("display", im["rgb"]))
        film.write_png(out / f"{name}.png", img8)
        print(f"{out / (name + '.png')}: day {day} ({fr.date})")


def combine(before, after, out, names=None, labels=("before", "after")):
    from PIL import Image, ImageDraw

    names = names or sorted(p.stem for p in Path(after).glob("*.png"))
    rows = []
    for n in names:
        a, b = Image.open(Path(before) / f"{n}.png"), Image.open(Path(after) / f"{n}.png")
        w, h = a.size
        row = Image.new("RGB", (2 * w + 8, h), "white")
        row.paste(a, (0, 0))
        row.paste(b.resize((w, h)), (w + 8, 0))
        d = ImageDraw.Draw(row)
        for x, t in ((6, labels[0]), (w + 14, labels[1])):
            d.rectangle([x - 4, 4, x + 7 * len(t) + 4, 20], fill="black")
            d.text((x, 6), t, fill="white")
        rows.append(row)
    W = max(r.size[0] for r in rows)
    img = Image.new("RGB", (W, sum(r.size[1] for r in rows) + 8 * (len(rows) - 1)), "white")
    y = 0
    for r in rows:
        img.paste(r, (0, y))
        y += r.size[1] + 8
    img.save(out, optimize=True)
    print(out)


def _vec(s):
    return [float(x) for x in s.split(",")]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir", nargs="?")
    ap.add_argument("--out", required=True)
    ap.add_argument("--scenario")
    ap.add_argument("--day", type=int)
    ap.add_argument("--view", action="append", default=[])
    ap.add_argument("--preset", action="append", default=[])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--combine", nargs=2, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--names", help="comma-separated picture names to combine (default all)")
    a = ap.parse_args(argv)
    if a.combine:
        combine(*a.combine, a.out, a.names.split(",") if a.names else None)
        return
    views = {}
    for v in a.view:
        name, rest = v.split("=", 1)
        o, t, fov = rest.split(":")
        views[name] = (_vec(o), _vec(t), float(fov))
    render_views(a.run_dir, a.out, views, a.preset, a.width, a.height, a.spp, a.day,
                 a.scenario)


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
