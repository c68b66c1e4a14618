"""Photon-pass throughput against Mitsuba's raw ray casting on the same scene, same ray count.

Prints, for 1M and 4M photons: photons/s, ray casts/s of the whole pass (every cast counted,
emission and pilot included), and the ratio to the throughput of
  - scene.ray_intersect (full surface interaction, all fields evaluated) and
  - scene.ray_intersect_preliminary (the BVH traversal limit)
on the same number of incoherent rays drawn like the photons (same emitters, same aiming).
Medians of several repetitions; Dr.Jit kernels are compiled before timing.

    python benchmarks/photon_throughput.py [--scene garden|moss_garden] [--reps 5]
"""
import argparse
import os
import sys
import time

import numpy as np

import mitsuba_veg  # noqa: F401
import mitsuba as mi
import drjit as dr

sys.path.insert(0, os.path.dirname(__file__))
from _scenes import garden_80k  # noqa: E402
from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex  # noqa


def load(name):
    if name == "garden":
        return garden_80k()
    root = os.path.join(os.path.dirname(__file__), "..", "scenes", "moss_garden", "scene.xml")
    return mi.load_file(root, optimize=False)


def raw_rays(integ, scene, n, seed):
    """n rays distributed like the photons' first rays (all emitters, same aiming)."""
    index = SceneIndex.build(scene)
    ems = scene.emitters()
    per = [n // len(ems) + (1 if i < n % len(ems) else 0) for i in range(len(ems))]
    O, D = [], []
    for i, (e, k) in enumerate(zip(ems, per)):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed + i, k)
        lam = 360.0 + 470.0 * sampler.next_1d()
        o, d, w, t = integ._emit(scene, e, index, sampler, mi.Spectrum(lam, lam, lam, lam),
                                 mi.Bool(True))
        dr.eval(o, d)
        O.append(np.stack([np.broadcast_to(np.asarray(c), (k,)) for c in (o.x, o.y, o.z)]))
        D.append(np.stack([np.broadcast_to(np.asarray(c), (k,)) for c in (d.x, d.y, d.z)]))
    return (np.concatenate(O, 1).astype(np.float32), np.concatenate(D, 1).astype(np.float32))


def time_raw(scene, O, D, kind, reps):
    ts = []
    for r in range(reps + 1):
        # fresh inputs each time (Dr.Jit could otherwise reuse a still-alive identical result)
        o = mi.Point3f(*[mi.Float(O[k] + np.float32(r * 1e-7)) for k in range(3)])
        d = mi.Vector3f(*[mi.Float(D[k]) for k in range(3)])
        dr.eval(o, d)
        dr.sync_thread()
        t = time.perf_counter()
        ray = mi.Ray3f(o, d)
        if kind == "full":
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False)
            dr.eval(si)
        else:
            pi = scene.ray_intersect_preliminary(ray, coherent=False)
            dr.eval(pi)
        dr.sync_thread()
        if r > 0:  # first one compiles
            ts.append(time.perf_counter() - t)
    return float(np.median(ts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="garden", choices=["garden", "moss_garden"])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--photons", type=int, nargs="*", default=[1_000_000, 4_000_000])
    a = ap.parse_args()
    scene = load(a.scene)
    ntri = sum(s.face_count() for s in scene.shapes() if s.is_mesh())
    print(f"scene {a.scene}: {ntri} triangles, {len(scene.emitters())} emitters, "
          f"variant {mi.variant()}, {os.cpu_count()} CPU threads")
    integ = PhotonIrradianceIntegrator()
    for n in a.photons:
        integ.trace(scene, photons=n, seed=0)  # compile
        ts, rays = [], 0
        for r in range(a.reps):
            t = time.perf_counter()
            res = integ.trace(scene, photons=n, seed=r + 1)
            ts.append(time.perf_counter() - t)
            rays = res.rays_traced
        t_pass = float(np.median(ts))
        O, D = raw_rays(integ, scene, rays, seed=99)
        t_full = time_raw(scene, O, D, "full", a.reps)
        t_pre = time_raw(scene, O, D, "prelim", a.reps)
        rps = rays / t_pass
        print(f"{n:>9,d} photons: pass {t_pass:.3f} s, {n / t_pass / 1e6:.2f} M photons/s, "
              f"{rays:,d} ray casts ({rays / n:.2f}/photon) = {rps / 1e6:.2f} M casts/s")
        print(f"          raw ray_intersect {rays / t_full / 1e6:.2f} M rays/s -> ratio "
              f"{rps / (rays / t_full):.2f};  ray_intersect_preliminary "
              f"{rays / t_pre / 1e6:.2f} M rays/s -> ratio {rps / (rays / t_pre):.2f}")


if __name__ == "__main__":
    main()
