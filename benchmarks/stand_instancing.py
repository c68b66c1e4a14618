"""A stand's trees as Mitsuba instances vs plain meshes: load time, memory, ray throughput.

For each tree count N a stand of N trees of one Weber-Penn preset (400 trees/ha, Poisson-disc,
3 geometry variants, heights 15 m +- 15 %, random yaw) is laid out on a gently rolling ground
(2 m cells; mitsuba_veg.trees.stand, mitsuba_veg.forest_floor) and loaded as ``shapegroup`` +
``instance`` (one mesh per variant) and as plain meshes (every tree's copy merged into one bark
and one leaf mesh, as the world loop's canopy does). Printed per N:

- the estimate of :func:`mitsuba_veg.trees.instancing.stand_memory` (leaves recorded, as in the
  world loop) and the bytes per leaf;
- per mode, each in its own process: load [s] (building the scene dict and ``mi.load_dict``,
  the acceleration structure included) and resident memory after the load minus before it
  (Dr.Jit's allocation cache flushed) against the geometry estimate; up to
  ``--photon-max-elements`` triangles also one photon pass (every triangle recorded) and the
  memory it keeps, against the estimate;
- ray throughput of ``scene.ray_intersect_preliminary``, both modes loaded in one process and
  timed in turns (``--reps`` rounds, best per mode; the ratio is the median of the rounds'
  ratios, so load from other processes hits both), for 2^20 rays of two kinds: ``sun``
  (parallel rays from above the stand at 50 deg elevation, like the photons' first casts) and
  ``inside`` (random origins in the stand's box, random directions, like bounce casts); equal
  hit fractions show that both scenes hold the same geometry.

Plain meshes whose geometry estimate exceeds ``--max-plain-gb`` are skipped (said so).

    python benchmarks/stand_instancing.py [--counts 50 200 500] [--preset quaking_aspen]
        [--variants 3] [--max-plain-gb 8] [--photons 200000] [--reps 5] [--json FILE]

Full ``ray_intersect`` is not timed: MITSUBA_NOTES records that it scales badly with the
instance count in 3.9.1, and the photon pass casts preliminary rays only.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def make_stand(n: int, preset: str, variants: int, density: float = 400.0):
    """The benchmark's stand of ``n`` trees and its ground."""
    from mitsuba_veg.forest_floor import rolling_ground
    from mitsuba_veg.trees.stand import StandSpec, layout

    side = math.sqrt(n / density * 1e4)
    ground = rolling_ground((0.0, 0.0, side, side), slope_deg=5.0, aspect_deg=180.0,
                            roughness=0.3, roughness_scale=20.0, seed=0, resolution=2.0)
    spec = StandSpec(plot=[0.0, 0.0, side, side], density=density, mix={preset: 1.0},
                     min_spacing=2.5, height_mean=15.0, height_cv=0.15, variants=variants,
                     seed=0)
    return layout(spec, ground), ground


def _rays(n: int, kind: str, bounds, top: float, seed: int = 1):
    import mitsuba as mi

    rng = np.random.default_rng(seed)
    x0, z0, x1, z1 = bounds
    if kind == "sun":
        el, az = math.radians(50.0), math.radians(150.0)
        d = np.array([-math.cos(el) * math.sin(az), -math.sin(el), math.cos(el) * math.cos(az)])
        o = np.column_stack([rng.uniform(x0, x1, n), np.full(n, top + 1.0),
                             rng.uniform(z0, z1, n)])
        dirs = np.broadcast_to(d, (n, 3))
    else:
        o = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(0.2, top, n),
                             rng.uniform(z0, z1, n)])
        v = rng.normal(size=(n, 3))
        dirs = v / np.linalg.norm(v, axis=1, keepdims=True)
    return mi.Ray3f(mi.Point3f(*[mi.Float(np.ascontiguousarray(o[:, i], np.float32))
                                  for i in range(3)]),
                    mi.Vector3f(*[mi.Float(np.ascontiguousarray(dirs[:, i], np.float32))
                                  for i in range(3)]))


def _cast(scene, ray) -> float:
    """Seconds of one ``ray_intersect_preliminary`` over all rays (evaluated)."""
    import drjit as dr

    t = time.perf_counter()
    pi = scene.ray_intersect_preliminary(ray)
    dr.eval(pi.t)
    dr.sync_thread()
    return time.perf_counter() - t


def _load(mode: str, stand, ground, variants):
    """The light scene of the stand (ground, a sun, the trees): scene, load seconds."""
    import mitsuba as mi

    from mitsuba_veg.meshes import make_mesh
    from mitsuba_veg.trees.instancing import scene_dict

    gv, gf = ground.mesh()
    t0 = time.perf_counter()
    el, az = math.radians(50.0), math.radians(150.0)
    sun = [-math.cos(el) * math.sin(az), -math.sin(el), math.cos(el) * math.cos(az)]
    d = {"type": "scene", "ground": make_mesh("ground", gv, gf, bsdf={"type": "diffuse"}),
         "sun": {"type": "directional", "direction": sun,
                 "irradiance": {"type": "uniform", "value": 1.0}}}
    d.update(scene_dict(stand, variants, instanced=(mode == "instanced")))
    scene = mi.load_dict(d, optimize=False)
    return scene, time.perf_counter() - t0


def memory_case(mode: str, n: int, preset: str, variants: int, photons: int = 0,
                max_elements: int = 10_000_000) -> dict:
    """Load time and resident memory of one mode (run alone in a process)."""
    import drjit as dr

    import mitsuba_veg  # noqa: F401  (selects the variant)
    from mitsuba_veg.trees.instancing import build_variants, stand_memory

    stand, ground = make_stand(n, preset, variants)
    var = build_variants(stand)
    est = stand_memory(stand, var, recorded="all")      # the pass below records everything
    dr.flush_malloc_cache()
    rss0 = _rss_mb()
    scene, t_load = _load(mode, stand, ground, var)
    dr.flush_malloc_cache()
    out = {"mode": mode, "trees": n, "variants": len(var), "leaves": est.leaves,
           "faces": est.faces, "load_s": t_load, "rss_mb": _rss_mb() - rss0,
           "peak_mb": _peak_mb(),
           "estimate_geometry_mb": (est.geometry_instanced if mode == "instanced"
                                    else est.geometry_plain) / 2 ** 20,
           "estimate_photon_mb": (est.photon_instanced if mode == "instanced"
                                  else est.photon_plain) / 2 ** 20}
    # the photon pass keeps ~0.5 kB per element at its peak: measured below a cap only
    if photons and est.faces <= max_elements:
        from mitsuba_veg.light import photon_irradiance

        rss2 = _rss_mb()
        t0 = time.perf_counter()
        res = photon_irradiance(scene, photons=photons, seed=0, max_depth=4)
        out["photon_s"] = time.perf_counter() - t0
        dr.flush_malloc_cache()
        out["photon_rss_mb"] = _rss_mb() - rss2
        out["photon_elements"] = int(res.tensor().shape[0])
        out["peak_mb"] = _peak_mb()
    return out


def rays_case(n: int, modes, preset: str, variants: int, rays: int, reps: int = 5) -> dict:
    """Ray throughput of the modes, loaded side by side and timed in turns (shared cores)."""
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.trees.instancing import build_variants

    stand, ground = make_stand(n, preset, variants)
    var = build_variants(stand)
    scenes = {m: _load(m, stand, ground, var)[0] for m in modes}
    top = float(stand.heights.max() * 1.1 + stand.positions[:, 1].max())
    out = {"trees": n}
    for kind in ("sun", "inside"):
        ray = _rays(rays, kind, ground.bounds, top)
        times = {m: [] for m in modes}
        for m in modes:
            _cast(scenes[m], ray)                       # compile
            out[f"hit_{kind}_{m}"] = float(np.isfinite(np.asarray(
                scenes[m].ray_intersect_preliminary(ray).t)).mean())
        for _ in range(reps):
            for m in modes:
                times[m].append(_cast(scenes[m], ray))
        for m in modes:
            out[f"mrays_{kind}_{m}"] = rays / min(times[m]) / 1e6
        if len(modes) == 2:
            out[f"ratio_{kind}"] = float(np.median(np.array(times["plain"])
                                                   / np.array(times["instanced"])))
    out["load_average"] = os.getloadavg()[0]
    return out


def _run(args) -> dict | None:
    p = subprocess.run([sys.executable, __file__, *map(str, args)], capture_output=True,
                       text=True)
    if p.returncode:
        print(f"  failed (exit {p.returncode}): {p.stderr.strip()[-400:]}", flush=True)
        return None
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[50, 200, 500])
    ap.add_argument("--preset", default="quaking_aspen")
    ap.add_argument("--variants", type=int, default=3)
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--max-plain-gb", type=float, default=8.0)
    ap.add_argument("--photons", type=int, default=200_000,
                    help="photons of one pass (0: none) whose memory is measured (the pass "
                    "here records every triangle)")
    ap.add_argument("--photon-max-elements", type=int, default=10_000_000,
                    help="measure the pass only up to this many triangles (its peak is "
                    "~0.5 kB each)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--memory-case", nargs=2, metavar=("MODE", "N"), help=argparse.SUPPRESS)
    ap.add_argument("--rays-case", nargs="+", metavar="N MODE", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    common = ["--preset", a.preset, "--variants", a.variants]
    if a.memory_case:
        print(json.dumps(memory_case(a.memory_case[0], int(a.memory_case[1]), a.preset,
                                     a.variants, a.photons, a.photon_max_elements)))
        return
    if a.rays_case:
        print(json.dumps(rays_case(int(a.rays_case[0]), a.rays_case[1:], a.preset, a.variants,
                                   a.rays, a.reps)))
        return
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.backend import versions
    from mitsuba_veg.trees.instancing import build_variants, stand_memory

    print(f"{versions()}; {os.cpu_count()} CPU threads; load average "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    rows = []
    from _record import Recorder
    rec = Recorder("stand_instancing", notes=f"stands of {a.preset} ({a.variants} variants): "
                   "memory and rays, instanced vs plain meshes")
    for n in a.counts:
        stand, _ = make_stand(n, a.preset, a.variants)
        est = stand_memory(stand, build_variants(stand))      # the world loop: leaves recorded
        pl = est.per_leaf()
        print(f"N = {n}: {est.leaves:,d} leaves, {est.faces:,d} triangles; estimate with the "
              f"leaves recorded: plain {est.plain / 2 ** 30:.2f} GB (geometry "
              f"{est.geometry_plain / 2 ** 30:.2f}, photon pass {est.photon_plain / 2 ** 30:.2f}),"
              f" instanced {est.instanced / 2 ** 30:.2f} GB (geometry "
              f"{est.geometry_instanced / 2 ** 30:.3f}, photon pass "
              f"{est.photon_instanced / 2 ** 30:.2f}); per leaf {pl['plain']:.0f} B plain, "
              f"{pl['instanced']:.0f} B instanced", flush=True)
        rec.add(f"n{n}_leaves", est.leaves, "", f"{n} trees: leaves")
        rec.add(f"n{n}_bytes_per_leaf_plain", pl["plain"], "B", f"{n} trees: estimate per leaf, plain")
        rec.add(f"n{n}_bytes_per_leaf_instanced", pl["instanced"], "B",
                f"{n} trees: estimate per leaf, instanced")
        modes = ["instanced"]
        if est.geometry_plain / 2 ** 30 > a.max_plain_gb:
            print(f"  plain     skipped: geometry estimate {est.geometry_plain / 2 ** 30:.1f} GB "
                  f"> --max-plain-gb {a.max_plain_gb:g}", flush=True)
        else:
            modes.append("plain")
        for mode in modes:
            r = _run(["--memory-case", mode, n, *common, "--photons", a.photons,
                      "--photon-max-elements", a.photon_max_elements])
            if r is None:
                continue
            rows.append(r)
            rec.add(f"n{n}_{mode}_rss_mb", r["rss_mb"], "MB", f"{n} trees, {mode}: memory after load")
            print(f"  {mode:9s} load {r['load_s']:7.2f} s  RSS +{r['rss_mb']:7.0f} MB "
                  f"(estimate {r['estimate_geometry_mb']:7.0f} MB)  peak {r['peak_mb']:6.0f} MB",
                  flush=True)
            if "photon_s" in r:
                print(f"  {'':9s} photon pass ({a.photons:,d} photons, every triangle recorded) "
                      f"{r['photon_s']:.1f} s: RSS +{r['photon_rss_mb']:.0f} MB (estimate "
                      f"{r['estimate_photon_mb']:.0f} MB) for {r['photon_elements']:,d} "
                      f"elements", flush=True)
        r = _run(["--rays-case", n, *modes, *common, "--rays", a.rays, "--reps", a.reps])
        if r is not None:
            rows.append(r)
            for kind in ("sun", "inside"):
                line = "  ".join(f"{m} {r[f'mrays_{kind}_{m}']:5.2f} M rays/s (hit "
                                 f"{r[f'hit_{kind}_{m}']:.4f})" for m in modes)
                if len(modes) == 2:
                    line += f"  time plain / instanced {r[f'ratio_{kind}']:.2f}"
                print(f"  rays {kind:6s} {line}  (load average {r['load_average']:.1f})",
                      flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    rec.write()


if __name__ == "__main__":
    main()
