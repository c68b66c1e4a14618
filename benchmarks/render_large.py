"""Large-scene render: >= 100,000 moss tufts and >= 10 trees with >= 100,000 leaves at
1280x720 / 64 spp (issue 7). Reports build and render times.

The scene is generated in a temporary folder: a 12 m x 12 m terrain (1/f relief, humus with
sand and asphalt patches painted in the geology colours), moss in 1/f-noise patches on a 1-cm
grid (three species, random growth), ten Weber-Penn quaking aspens scaled to 4-7 m (the simple
procedural tree when :mod:`mitsuba_veg.trees.weber_penn` is unavailable), physical sun and sky.
Tufts are merged into one mesh per species and leaves into one mesh per autumn bin (Mitsuba 3.9.1
does not scale to one ``instance`` per tuft; ../shared/MITSUBA_NOTES.md).

    python benchmarks/render_large.py [--tufts 120000] [--trees 10] [--width 1280]
                                      [--height 720] [--spp 64] [--out out/bench_render]

Measured (2 cores, llvm_ad_spectral, load average 3 from other jobs): 120,000 tufts + 10 trees
with 227,235 leaves = 10.4 M triangles; build 23 s (moss points 6 s, moss meshes 5.9 s, tree
meshes 1.5 s, Mitsuba load + BVH 9.9 s); render 272 s (0.22 M samples/s), kernel compile ~15 s
when not cached; peak memory 2.1 GiB. Writes render_large.json/.png/.exr into --out.
"""
from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

import numpy as np


def make_scenario(folder: Path, size=12.0, cells=120) -> Path:
    import trimesh
    from PIL import Image

    from mitsuba_veg.render.noise import pink_noise, pink_noise_image
    from mitsuba_veg.terrain import GEOLOGY_COLOURS

    s = np.linspace(-size / 2, size / 2, cells + 1)
    X, Z = np.meshgrid(s, s)
    p = np.c_[X.ravel(), np.zeros(X.size), Z.ravel()]
    Y = 0.25 * pink_noise(p, 6.0, octaves=4, seed=11).reshape(X.shape)
    V = np.stack([X, Y, Z], -1).reshape(-1, 3)
    UV = np.stack([(X + size / 2) / size, (Z + size / 2) / size], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(cells), np.arange(cells))
    a = (j * (cells + 1) + i).ravel()
    b, c = a + 1, a + cells + 1
    d = c + 1
    F = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    m = trimesh.Trimesh(V, F, process=False,
                        visual=trimesh.visual.TextureVisuals(uv=UV))
    m.export(folder / "ground.ply")
    n = pink_noise_image((512, 512), scale_px=160.0, seed=5)
    img = np.empty((512, 512, 3), np.uint8)
    img[:] = GEOLOGY_COLOURS["humus"]
    img[n > np.quantile(n, 0.78)] = GEOLOGY_COLOURS["sand"]
    img[:, 300:330] = GEOLOGY_COLOURS["asphalt"]
    Image.fromarray(img).save(folder / "geology.png")
    (folder / "scene.xml").write_text(
        '<scene version="3.0.0">\n  <shape type="ply" id="ground">\n'
        '    <string name="filename" value="ground.ply"/>\n'
        '    <bsdf type="diffuse"><spectrum name="reflectance" value="0.2"/></bsdf>\n'
        '  </shape>\n</scene>\n')
    (folder / "scenario.toml").write_text(
        '[scene]\nfile = "scene.xml"\n[site]\nlatitude = 35.0\nlongitude = 139.0\n'
        '[terrain]\nground = "ground"\ngeology_texture = "geology.png"\n'
        '[render.cameras.bench]\norigin = [7.5, 3.2, 8.0]\ntarget = [-0.5, 0.6, -1.0]\n'
        'fov = 55.0\n')
    return folder / "scenario.toml"


def make_moss(terrain, n_target: int, seed=0):
    """Moss on a 1-cm grid inside 1/f-noise patches of the ground, ~n_target tufts."""
    from mitsuba_veg.render import MossSet
    from mitsuba_veg.render.noise import pink_noise

    v, f, _, _ = terrain.meshes[terrain.ground]
    lo, hi = v.min(0), v.max(0)
    rng = np.random.default_rng(seed)
    # candidate points, thinned to the patches
    xs = np.arange(lo[0] + 0.3, hi[0] - 0.3, 0.01)
    zs = np.arange(lo[2] + 0.3, hi[2] - 0.3, 0.01)
    X, Z = np.meshgrid(xs, zs)
    P = np.c_[X.ravel(), np.zeros(X.size), Z.ravel()]
    P[:, [0, 2]] += rng.normal(0, 0.002, (len(P), 2))
    w = pink_noise(P, 3.0, octaves=5, seed=seed + 3)
    thr = np.quantile(w, 1.0 - n_target / len(P))
    P = P[w >= thr]
    # heights and normals by ray casts onto the terrain
    import mitsuba as mi
    o = P + [0, 5.0, 0]
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k].astype(np.float32)) for k in range(3)]),
                   mi.Vector3f(0, -1, 0))
    si = terrain.base_scene.ray_intersect(ray)
    ok = np.asarray(si.is_valid())
    pos = np.stack([np.asarray(si.p[k]) for k in range(3)], 1)[ok]
    nrm = np.stack([np.asarray(si.n[k]) for k in range(3)], 1)[ok]
    n = len(pos)
    sp = rng.choice(3, n, p=[0.45, 0.35, 0.20])
    return MossSet(pos, nrm, sp, rng.gamma(2.0, 4.0, n),
                   ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"])


def make_trees(n_trees: int, terrain, seed=0):
    from mitsuba_veg.render.trees import make_tree
    rng = np.random.default_rng(seed)
    lo, hi = terrain.ground_bbox()
    trees = []
    ang = np.linspace(0, 2 * np.pi, n_trees, endpoint=False) + 0.3
    for k in range(n_trees):
        r = 4.3 + 0.8 * rng.random()
        x, z = r * np.cos(ang[k]), r * np.sin(ang[k]) - 0.5
        trees.append(make_tree({"preset": "quaking_aspen", "seed": k, "position": [x, 0.0, z],
                                "height": float(4.0 + 3.0 * rng.random())}))
    return trees


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tufts", type=int, default=120_000)
    ap.add_argument("--trees", type=int, default=10)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--out", default="out/bench_render")
    a = ap.parse_args(argv)

    import mitsuba_veg  # noqa: F401
    import drjit as dr
    from mitsuba_veg.render import RenderOptions, build_scene, render, write_outputs
    from mitsuba_veg.render.scene import Terrain
    from mitsuba_veg.scenario import load_scenario

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        scn = load_scenario(make_scenario(Path(tmp)))
        terrain = Terrain.from_scenario(scn)
        moss = make_moss(terrain, a.tufts)
        t1 = time.perf_counter()
        trees = make_trees(a.trees, terrain)
        t2 = time.perf_counter()
        opts = RenderOptions(width=a.width, height=a.height, spp=a.spp, camera="bench",
                             when="2026-10-25T14:00:00+09:00", cover_resolution=2048)
        for t in trees:    # some autumn colour
            n = len(t.leaves)
            t.leaves.attrs["autumn_tau"] = np.clip(np.random.default_rng(n).normal(0.45, 0.25,
                                                                                    n), 0, 1)
        rs = build_scene(scn, moss, moss_size=0.01, trees=trees, options=opts,
                         terrain=terrain)
        t3 = time.perf_counter()
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        images = render(rs)
        t4 = time.perf_counter()
        hist = dr.kernel_history()
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        compile_s = sum(h.get("codegen_time", 0.0) + h.get("backend_time", 0.0)
                        for h in hist) / 1000.0
        files = write_outputs(images, out, stem="render_large")
    leaves = sum(len(t.leaves) for t in trees)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    samples = a.width * a.height * a.spp
    res = {"tufts": rs.info["tufts"], "trees": len(trees), "leaves": leaves,
           "triangles": rs.info["triangles"], "moss_triangles": rs.info["moss_triangles"],
           "tree_triangles": rs.info["tree_triangles"],
           "resolution": [a.width, a.height], "spp": a.spp,
           "seconds": {"terrain_and_moss_points": t1 - t0, "trees_generate": t2 - t1,
                       "scene_build": t3 - t2, "scene_build_parts": rs.info["seconds"],
                       "render_incl_compile": t4 - t3, "kernel_compile": compile_s,
                       "render": t4 - t3 - compile_s},
           "msamples_per_s": samples / (t4 - t3 - compile_s) / 1e6, "peak_rss_MiB": rss,
           "cpu_count": __import__("os").cpu_count(),
           "load_average_at_end": list(__import__("os").getloadavg()),
           "files": files["files"], "variant": __import__("mitsuba").variant()}
    (out / "render_large.json").write_text(json.dumps(res, indent=2))
    print(f"{res['tufts']:,d} moss tufts, {len(trees)} trees with {leaves:,d} leaves: "
          f"{res['triangles']:,d} triangles")
    print(f"build: moss points {t1 - t0:.1f} s, trees {t2 - t1:.1f} s, scene "
          f"{t3 - t2:.1f} s (moss meshes {rs.info['seconds']['moss']:.1f} s, tree meshes "
          f"{rs.info['seconds']['trees']:.1f} s, load + BVH {rs.info['seconds']['load']:.1f} s)")
    print(f"render {a.width}x{a.height} @ {a.spp} spp: {t4 - t3 - compile_s:.1f} s "
          f"({res['msamples_per_s']:.2f} M samples/s) + kernel compile {compile_s:.1f} s; "
          f"peak memory {rss:,.0f} MiB; load average {res['load_average_at_end'][0]:.1f} on "
          f"{res['cpu_count']} cores")
    print(f"wrote {out / 'render_large.json'} and {files['files']['png']}")
    dr.sync_thread()
    return res


if __name__ == "__main__":
    main()
