"""Non-growth deformation (paper 002) timing: the 5 x 5 stand of sample trees, death +
heliotropism, against Mitsuba's raw ray throughput measured in the same run.

    .venv/bin/python benchmarks/trees_nongrowth.py [--reps 5] [--out FILE.json]

Reports the wall time of ``deform`` (median of --reps warm runs; the cold first run compiles
the DDA kernel), the voxel rays traced (36 per query point: tips for the death rule, every voxel
centre for the heliotropism gradient field), rays/s and DDA voxel steps/s. The raw reference:
the 25 trees as one triangle mesh (tubes + one quad per tip leaf) in Mitsuba, the same number
of rays from the same points in the same 36 directions, one ``ray_intersect_preliminary``
each.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--out")
    a = ap.parse_args(argv)
    import drjit as dr
    import mitsuba as mi

    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.meshes import make_mesh
    from mitsuba_veg.trees import GrowthParams, Leaves, branching, nongrowth
    from mitsuba_veg.trees.voxel import VoxelSpace, sky_rays

    sample = branching(GrowthParams(branch_angle=45, lateral_length=5, random_phase=False), 7)
    trees = [sample.translated((4.0 * i, 0.0, 4.0 * j)) for j in range(5) for i in range(5)]
    t = time.perf_counter()
    nongrowth.deform(trees)
    cold = time.perf_counter() - t
    times, stats = [], None
    for _ in range(a.reps):
        t = time.perf_counter()
        r = nongrowth.deform(trees, death_threshold=0.5)
        times.append(time.perf_counter() - t)
        stats = r.stats
    wall = float(np.median(times))
    rays = sum(s["rays"] for s in stats)
    steps = sum(s["dda_steps"] for s in stats)
    light_s = sum(s["light_s"] for s in stats)
    # raw Mitsuba on the same geometry and rays
    meshes = []
    for tr in trees:
        tips = tr.tips()
        tr = tr.copy()
        tr.leaves = Leaves(tr.end[tips], np.tile([0, 1.0, 0], (len(tips), 1)),
                           np.full(len(tips), 0.3), tips)
        meshes.append(tr.to_mesh(sides=6))
    import trimesh
    m = trimesh.util.concatenate(meshes)
    scene = mi.load_dict({"type": "scene", "trees": make_mesh("trees", m.vertices, m.faces)},
                         optimize=False)
    pts = np.concatenate([t.end[t.tips()] for t in trees])
    vs = VoxelSpace.build(pts, 0.5, 0.3)
    query = np.concatenate([pts, vs.centers()])
    D, _ = sky_rays()
    n = len(query) * len(D)
    ts = []
    for rep in range(4):
        q = mi.Point3f(*[mi.Float(np.repeat(query[:, k] + rep * 1e-6, len(D)).astype(np.float32))
                         for k in range(3)])
        d = mi.Vector3f(*[mi.Float(np.tile(D[:, k], len(query)).astype(np.float32))
                          for k in range(3)])
        dr.eval(q, d)
        dr.sync_thread()
        t = time.perf_counter()
        pi = scene.ray_intersect_preliminary(mi.Ray3f(q, d), coherent=False)
        dr.eval(pi.t, pi.prim_index)
        dr.sync_thread()
        if rep:
            ts.append(time.perf_counter() - t)
    raw = n / float(np.median(ts))
    res = {"case": "5 x 5 non-growth deformation (death + heliotropism)", "seconds": wall,
           "cold_seconds": cold, "voxel_rays": rays, "dda_steps": steps,
           "rays_per_s": rays / wall, "light_rays_per_s": rays / light_s,
           "dda_steps_per_s": steps / light_s, "raw_mitsuba_rays_per_s": raw,
           "raw_mesh_triangles": int(len(m.faces)), "ratio_to_raw": rays / wall / raw,
           "stats": stats}
    print(f"5 x 5 deformation: {wall:.3f} s (cold {cold:.2f} s), {rays / 1e6:.2f} M voxel rays "
          f"({steps / 1e6:.1f} M DDA steps), {rays / wall / 1e6:.2f} M rays/s overall, "
          f"{rays / light_s / 1e6:.2f} M rays/s and {steps / light_s / 1e6:.0f} M steps/s in the "
          f"DDA kernel; raw Mitsuba ray_intersect_preliminary on the trees' mesh "
          f"({len(m.faces):,d} triangles, same rays): {raw / 1e6:.2f} M rays/s -> ratio "
          f"{rays / wall / raw:.2f}")
    for s in stats:
        print(f"  {s['rule']:>12s}: {s['seconds']:.3f} s, {s['rays']:,d} rays, "
              f"{s['voxels']:,d} voxels")
    if a.out:
        with open(a.out, "w") as f:
            json.dump(res, f, indent=2, default=str)
    from _record import Recorder
    rec = Recorder("trees_nongrowth", notes="5 x 5 stand grown by paper 001's model, then "
                   "deformed by paper 002's rules (death, heliotropism) in its voxel light")
    rec.add("deform_s", wall, "s", "5 x 5 deformation (death + heliotropism)")
    rec.add("voxel_rays_per_s", rays / wall / 1e6, "M rays/s", "voxel rays per second overall")
    rec.add("ratio_to_raw", rays / wall / raw, "ratio",
            "voxel rays/s ÷ raw `ray_intersect_preliminary` on the trees' mesh, same rays")
    rec.write()


if __name__ == "__main__":
    main()
