"""Render Weber-Penn trees (bark + leaves) with Mitsuba 3 for the docs pictures.

Used by ``experiments/weber_penn_pictures.py``; also runnable on its own:

    .venv/bin/python experiments/weber_penn_render.py quaking_aspen out/wp_aspen.png
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _mi():
    import mitsuba as mi
    if mi.variant() is None:
        for v in ("llvm_ad_spectral", "scalar_spectral", "llvm_ad_rgb", "scalar_rgb"):
            if v in mi.variants():
                mi.set_variant(v)
                break
    return mi


def render(meshes, *, origin, target, fov=35.0, size=(480, 640), spp=64, ground=True,
           sun=(0.45, 0.8, 0.35), seed=0):
    """Render ``meshes`` = list of (trimesh, rgb, twosided) -> float RGB image (H, W, 3)."""
    mi = _mi()
    tmp = Path(tempfile.mkdtemp(prefix="wp_render_"))
    scene = {"type": "scene",
             "integrator": {"type": "path", "max_depth": 6},
             "sensor": {"type": "perspective", "fov": fov,
                        "to_world": mi.ScalarTransform4f().look_at(origin=list(origin),
                                                                   target=list(target),
                                                                   up=[0, 1, 0]),
                        "film": {"type": "hdrfilm", "width": size[1], "height": size[0],
                                 "rfilter": {"type": "gaussian"}},
                        "sampler": {"type": "independent", "sample_count": spp, "seed": seed}},
             "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.55, 0.62, 0.75]}},
             "sun": {"type": "directional", "direction": (-np.asarray(sun)
                                                           / np.linalg.norm(sun)).tolist(),
                     "irradiance": {"type": "rgb", "value": [2.6, 2.45, 2.2]}}}
    for i, (m, rgb, two) in enumerate(meshes):
        if m is None or len(m.faces) == 0:
            continue
        path = tmp / f"m{i}.ply"
        m.export(str(path))
        bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}
        if two:
            bsdf = {"type": "twosided", "bsdf": bsdf}
        scene[f"mesh{i}"] = {"type": "ply", "filename": str(path), "bsdf": bsdf,
                             "face_normals": True}
    if ground:
        scene["ground"] = {"type": "disk", "to_world": mi.ScalarTransform4f().rotate(
            [1, 0, 0], -90).scale(200.0),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                        "value": [0.42, 0.40, 0.36]}}}
    img = mi.render(mi.load_dict(scene))
    bmp = mi.Bitmap(img).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32,
                                 srgb_gamma=False)
    return np.clip(np.array(bmp), 0, None)


def to_srgb8(img, exposure=1.0):
    x = np.clip(img * exposure, 0, 1)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)


def tree_view(tree, *, elev=8.0, azim=30.0, margin=1.15, fov=35.0, aspect=0.75):
    """Camera (origin, target) framing the whole tree."""
    pts = np.concatenate([tree.end, tree.leaves.position]) if len(tree.leaves) else tree.end
    lo, hi = pts.min(0), pts.max(0)
    c = 0.5 * (lo + hi)
    h = hi[1] - lo[1]
    w = max(hi[0] - lo[0], hi[2] - lo[2])
    half = 0.5 * max(h, w / aspect) * margin
    dist = half / np.tan(np.radians(fov / 2))
    e, a = np.radians(elev), np.radians(azim)
    d = np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])
    return c + dist * d, c


BARK = (0.32, 0.24, 0.17)
KNOT = (0.45, 0.20, 0.12)
LEAF = (0.20, 0.42, 0.12)


def tree_meshes(tree, smooth=True, leaves=True, **kw):
    from mitsuba_veg.trees import weber_penn as wp
    bark, leaf = wp.mesh(tree, smooth=smooth, leaves=leaves, **kw)
    return [(bark, BARK, False), (leaf, LEAF, True)]


if __name__ == "__main__":
    from PIL import Image

    from mitsuba_veg.trees import weber_penn as wp
    name = sys.argv[1] if len(sys.argv) > 1 else "quaking_aspen"
    out = sys.argv[2] if len(sys.argv) > 2 else f"out/wp_{name}.png"
    t = wp.generate(name, seed=1)
    o, tg = tree_view(t)
    img = render(tree_meshes(t), origin=o, target=tg, size=(480, 360), spp=32)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(to_srgb8(img)).save(out)
    print(out)
