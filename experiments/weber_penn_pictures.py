"""Pictures of the Weber-Penn presets with and without knots / smooth junctions (docs/images).

    .venv/bin/python experiments/weber_penn_pictures.py [--spp 32] [--only quaking_aspen]

Writes docs/images/weber_penn_<preset>.png (top: whole tree, plain Weber-Penn | with knots and
smoothed junctions; bottom: bark close-up of the same trunk region, knots tinted red-brown),
docs/images/weber_penn_junction.png (one branch junction: unsmoothed, paper scale, gain,
swapped Stretch/Compress, subdivisions) and docs/images/weber_penn_knots.png (knots: plain,
paper-scale junctions, smooth and lumpy knot junctions). Each PNG is palette-quantised to stay
under 300 KB. Rendering uses Mitsuba 3 (llvm_ad_spectral) on the CPU.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from weber_penn_render import BARK, KNOT, LEAF, render, to_srgb8, tree_view  # noqa: E402

from mitsuba_veg.trees import junction as J  # noqa: E402
from mitsuba_veg.trees import weber_penn as wp  # noqa: E402

OUT = ROOT / "docs" / "images"


def _unit(v):
    return np.asarray(v, float) / np.linalg.norm(v)


def label(img, text, xy=(6, 4)):
    im = Image.fromarray(img)
    d = ImageDraw.Draw(im)
    x, y = xy
    for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        d.text((x + dx, y + dy), text, fill=(255, 255, 255))
    d.text((x, y), text, fill=(0, 0, 0))
    return np.asarray(im)


def save(img, path, colors=192):
    im = Image.fromarray(img).quantize(colors=colors, method=Image.Quantize.MEDIANCUT,
                                       dither=Image.Dither.NONE)
    im.save(path, optimize=True)
    kb = path.stat().st_size / 1024
    if kb > 290:                      # keep the docs light
        im = Image.fromarray(img).quantize(colors=96, dither=Image.Dither.NONE)
        im.save(path, optimize=True)
        kb = path.stat().st_size / 1024
    print(f"  {path.relative_to(ROOT)}: {img.shape[1]}x{img.shape[0]}, {kb:.0f} KB")


def split_bark(tree, bark):
    """Bark faces of knots (kind != 0) as a separate mesh, for tinting."""
    import trimesh
    kind = tree.kind[bark.metadata["segment"]]
    out = []
    for m, rgb in ((kind == 0, BARK), (kind != 0, KNOT)):
        if m.any():
            out.append((trimesh.Trimesh(bark.vertices, bark.faces[m], process=False), rgb,
                        False))
    return out


def closeup_view(tree, scale=9.0, rank=0):
    """Camera on the trunk where a thick level-1 knot sits (or the crown base);
    ``scale`` = camera distance in parent radii, ``rank`` = which knot by thickness."""
    a = tree.attrs
    heads = (tree.parent >= 0) & (a["stem"][np.maximum(tree.parent, 0)] != a["stem"])
    k = np.nonzero(heads & (tree.kind != 0) & (tree.level == 1))[0]
    if len(k):
        c = k[np.argsort(-tree.radius_start[k])[min(rank, len(k) - 1)]]
        S = tree.start[c]
        d = tree.end[c] - S
    else:
        c = np.nonzero(heads & (tree.level == 1))[0][0]
        S, d = tree.start[c], tree.end[c] - tree.start[c]
    radial = np.array([d[0], 0.0, d[2]])
    radial /= max(np.linalg.norm(radial), 1e-9)
    p = tree.parent[c]
    rp = tree.radius_start[p]
    dist = max(0.35 if scale < 10 else 1.5, scale * rp)
    side = np.cross([0.0, 1.0, 0.0], radial)
    target = tree.start[p] + (S[1] - tree.start[p][1]) * np.array([0, 1.0, 0]) + radial * rp
    origin = target + dist * (0.75 * radial + 0.55 * side + np.array([0, 0.18, 0]))
    return origin, target


def preset_picture(name, spp, seed=1):
    t0 = time.perf_counter()
    plain = wp.generate(name, seed=seed, knots=False)
    knotty = wp.generate(name, seed=seed, knots=True)
    o, tg = tree_view(knotty, aspect=0.75, margin=1.0)
    W, H = 300, 400
    top = []
    for tree, smooth in ((plain, False), (knotty, True)):
        bark, leaves = wp.mesh(tree, smooth=smooth)
        img = render([(bark, BARK, False), (leaves, LEAF, True)], origin=o, target=tg,
                     size=(H, W), spp=spp, fov=35.0)
        top.append(to_srgb8(img))
    co, ct = closeup_view(knotty, scale=14.0)
    bottom = []
    for tree, smooth in ((plain, False), (knotty, True)):
        bark, _ = wp.mesh(tree, smooth=smooth, leaves=False)
        img = render(split_bark(tree, bark), origin=co, target=ct, size=(H // 2 + 60, W),
                     spp=spp, fov=40.0, ground=True)
        bottom.append(to_srgb8(img))
    st = knotty.weber_penn.stats
    top[0] = label(top[0], "Weber-Penn 1995")
    top[1] = label(top[1], f"+ knots ({st['knots']}), smoothed junctions")
    bottom[0] = label(bottom[0], "bark, no knots, unsmoothed")
    bottom[1] = label(bottom[1], "knots (tinted) + eq 4.2 junctions")
    img = np.concatenate([np.concatenate(top, 1), np.concatenate(bottom, 1)], 0)
    img = label(img, name.replace("_", " "), (6, 18))
    save(img, OUT / f"weber_penn_{name}.png")
    print(f"  {name}: {time.perf_counter() - t0:.1f} s")


def demo_junction_tree(angle=55.0, rp=0.25, rc=(0.12, 0.1, 0.0), h=1.2, node=0.5):
    """A straight trunk with a node every ``node`` metres and one branch at height ``h``."""
    from mitsuba_veg.trees.structure import Tree
    n_t = 8
    start = [[0, i * node, 0] for i in range(n_t)]
    end = [[0, (i + 1) * node, 0] for i in range(n_t)]
    r0, r1 = [rp] * n_t, [rp] * n_t
    par, lvl, stem = [-1] + list(range(n_t - 1)), [0] * n_t, [0] * n_t
    k = int(h / node)
    attach, arc = [0.0] + [1.0] * (n_t - 1), [i * node for i in range(n_t)]
    a = np.radians(angle)
    d = np.array([np.sin(a), np.cos(a), 0.0])
    for j in range(2):
        start.append(np.array([0, h, 0]) + j * d)
        end.append(np.array([0, h, 0]) + (j + 1) * d)
        r0.append(rc[j])
        r1.append(rc[j + 1])
        par.append(k if j == 0 else n_t)
        lvl.append(1)
        stem.append(1)
        attach.append((h - k * node) / node if j == 0 else 1.0)
        arc.append(float(j))
    n = len(start)
    attrs = {"stem": np.array(stem), "attach": np.array(attach), "arc": np.array(arc),
             "stem_length": np.array([n_t * node] * n_t + [2.0, 2.0]),
             "stem_radius": np.array([rp] * n_t + [rc[0]] * 2),
             "frame_x": np.tile([0.0, 0.0, 1.0], (n, 1)), "clone": np.zeros(n, bool)}
    return Tree(start, end, r0, r1, par, lvl, attrs=attrs)


def junction_picture(spp):
    t = demo_junction_tree()
    cases = [("unsmoothed", dict(smooth=False)),
             ("eq 4.2, paper scale", dict()),
             ("gain 4", dict(gain=4.0)),
             ("gain 4, Stretch 3 / Compress 1", dict(gain=4.0, stretch=3.0, compress=1.0)),
             ("gain 4, Stretch 0.6 / Compress 0.6", dict(gain=4.0, stretch=0.6, compress=0.6)),
             ("gain 4, D_u = 1", dict(gain=4.0, D_u=1)),
             ("gain 4, D_u = 8", dict(gain=4.0, D_u=8))]
    tiles = []
    for text, kw in cases:
        bark, _ = J.tree_mesh(t, leaves=False, sides=(24, 12), **kw)
        img = render([(bark, BARK, False)], origin=[0.55, 1.75, 2.6], target=[0.42, 1.35, 0.0],
                     fov=32, size=(230, 200), spp=spp, ground=False)
        tiles.append(label(to_srgb8(img), text))
    tiles.append(np.full_like(tiles[0], 255))
    img = np.concatenate([np.concatenate(tiles[:4], 1), np.concatenate(tiles[4:], 1)], 0)
    save(img, OUT / "weber_penn_junction.png")


def demo_knot_tree(rp=0.25, node=0.5):
    """A straight trunk with four knots (cones, kind KNOT) and one sprouted knot with its
    branch, built directly as a Tree so that the knots are seen in isolation."""
    from mitsuba_veg.trees.structure import KNOT, SPROUTED_KNOT, Tree
    n_t = 8
    rows = {k: [] for k in ("start", "end", "r0", "r1", "par", "lvl", "kind", "stem", "attach",
                            "arc", "slen", "srad", "fx")}

    def add(s, e, r0, r1, par, lvl, kind, stem, attach, arc, slen, srad, fx):
        for k, v in zip(rows, (s, e, r0, r1, par, lvl, kind, stem, attach, arc, slen, srad,
                               fx)):
            rows[k].append(v)
        return len(rows["start"]) - 1

    for i in range(n_t):
        add([0, i * node, 0], [0, (i + 1) * node, 0], rp, rp, i - 1, 0, 0, 0,
            0.0 if i == 0 else 1.0, i * node, n_t * node, rp, [0, 0, 1])
    # (height, azimuth, angle from the trunk, length, base radius, kind)
    knots = [(1.05, 0.0, 80.0, 0.30, 0.16, KNOT), (1.55, 180.0, 75.0, 0.26, 0.13, KNOT),
             (2.05, -70.0, 85.0, 0.24, 0.12, SPROUTED_KNOT), (2.6, 10.0, 70.0, 0.2, 0.1, KNOT)]
    for j, (h, az, ang, L, r, kind) in enumerate(knots):
        a, b = np.radians(ang), np.radians(az)
        d = np.array([np.sin(a) * np.cos(b), np.cos(a), -np.sin(a) * np.sin(b)])
        sink = rp / np.sin(a)                     # knots start on the bark
        base = np.array([0, h, 0]) + sink * d
        k = int(h / node)
        fx = np.cross(d, [0, 1.0, 0])
        prev = k
        for m in range(3):
            idx = add(base + m * L / 3 * d, base + (m + 1) * L / 3 * d, r * (1 - m / 3),
                      r * (1 - (m + 1) / 3), prev, 1, kind, 1 + j,
                      (h - k * node) / node if m == 0 else 1.0, m * L / 3, L, r, fx)
            prev = idx
        if kind == SPROUTED_KNOT:       # the branch grown from its dormant bud (eq 3.3-3.4)
            tip = base + 0.7 * L * d
            d2 = _unit(d + np.array([0.9, 1.1, 0.0]))
            pb = prev - 1
            for m in range(3):
                prev = add(tip + m * 0.5 * d2, tip + (m + 1) * 0.5 * d2, 0.035 * (1 - m / 3),
                           0.035 * (1 - (m + 1) / 3), pb if m == 0 else prev, 2, 0, 10,
                           0.1 if m == 0 else 1.0, m * 0.5, 1.5, 0.035, np.cross(d2, [0, 0, 1]))
    n = len(rows["start"])
    attrs = {"stem": np.array(rows["stem"]), "attach": np.array(rows["attach"]),
             "arc": np.array(rows["arc"]), "stem_length": np.array(rows["slen"]),
             "stem_radius": np.array(rows["srad"]), "frame_x": np.array(rows["fx"], float),
             "clone": np.zeros(n, bool)}
    return Tree(rows["start"], rows["end"], rows["r0"], rows["r1"], rows["par"], rows["lvl"],
                kind=rows["kind"], attrs=attrs)


def knots_picture(spp):
    t = demo_knot_tree()
    cases = [("knots, unsmoothed", dict(smooth=False)),
             ("eq 4.2, paper scale", dict()),
             ("KnotGain 60, F = 2: smooth knots", dict(knot_gain=60.0, stretch=2.0,
                                                       compress=2.0)),
             ("KnotGain 60, F = 0.6: lumpy knots", dict(knot_gain=60.0, stretch=0.6,
                                                        compress=0.6))]
    tiles = []
    for text, kw in cases:
        bark, _ = J.tree_mesh(t, leaves=False, sides=(24, 12, 8), **kw)
        img = render(split_bark(t, bark), origin=[0.35, 2.2, 3.0], target=[0.1, 1.85, 0.0],
                     fov=30, size=(300, 260), spp=spp, ground=False, sun=(0.5, 0.6, 0.7))
        tiles.append(label(to_srgb8(img), text))
    img = np.concatenate([np.concatenate(tiles[:2], 1), np.concatenate(tiles[2:], 1)], 0)
    save(img, OUT / "weber_penn_knots.png")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--only", default=None)
    args = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    names = [args.only] if args.only else list(wp.PRESETS)
    for n in names:
        if n in wp.PRESETS:
            preset_picture(n, args.spp)
    if args.only in (None, "junction"):
        junction_picture(args.spp)
    if args.only in (None, "knots"):
        knots_picture(args.spp)


if __name__ == "__main__":
    main()
