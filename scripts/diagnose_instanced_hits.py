"""Instanced hits on this backend (on a GPU: MITSUBA_VEG_VARIANT=cuda_ad_spectral python
scripts/diagnose_instanced_hits.py, the package installed): the element and BSDF the kernel's lookup gives against Mitsuba's own surface interaction, and
how often a ray spawned off a hit hits again at once (the open point of the instanced-plant
tests on OptiX: extra ray casts with instances)."""
import numpy as np, mitsuba as mi, drjit as dr
import mitsuba_veg as mv
A = lambda x, n: np.broadcast_to(np.asarray(x), (n,))
from mitsuba_veg.light import validation as V
from mitsuba_veg.integrators.photon_irradiance import SceneIndex
print("variant", mi.variant(), flush=True)
for name, inst in (("inst", True), ("plain", False)):
    sc = mi.load_dict(V.plant_scene(1000, instanced=inst), optimize=False)
    idx = SceneIndex.build(sc)
    bb = idx.aim_bbox
    n = 400000
    rng = np.random.default_rng(1)
    lo, hi = np.array(bb.min), np.array(bb.max)
    o = rng.uniform(lo, hi, (n, 3)).astype(np.float32); o[:, 1] = hi[1] + 0.5 if False else o[:, 1]
    d = rng.normal(size=(n, 3)).astype(np.float32); d /= np.linalg.norm(d, axis=1, keepdims=True)
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k]) for k in range(3)]), mi.Vector3f(*[mi.Float(d[:, k]) for k in range(3)]))
    pi = sc.ray_intersect_preliminary(ray, coherent=False)
    hit = pi.is_valid()
    sid = dr.reinterpret_array(mi.UInt32, pi.shape)
    elem = dr.gather(mi.UInt32, idx.lookup, sid, hit) + pi.prim_index
    iid = dr.reinterpret_array(mi.UInt32, pi.instance)
    if inst:
        in_inst = hit & (iid > 0)
        slot = dr.gather(mi.UInt32, idx.group_base, iid, in_inst) + pi.shape_index
        elem += dr.select(in_inst, dr.gather(mi.UInt32, idx.lookup, iid, in_inst) + dr.gather(mi.UInt32, idx.group_local, slot, in_inst), 0)
    si = pi.compute_surface_interaction(ray, mi.RayFlags.All, hit)
    h = np.asarray(hit); e = np.asarray(elem)[h]
    ng = np.stack([np.asarray(si.n[k]) for k in range(3)], 1)[h]
    p = np.stack([np.asarray(si.p[k]) for k in range(3)], 1)[h]
    nt = idx.normals[e]; ct = idx.centroids[e]
    dot = np.abs((ng * nt).sum(1))
    dist = np.linalg.norm(p - ct, axis=1)
    print(name, "hits", h.sum(), "in instances", int(np.asarray(iid > 0)[h].sum()), "|n.n_elem| < 0.999:", int((dot < 0.999).sum()),
          "hit far from elem centroid (>0.5 m):", int((dist > 0.5).sum()), "median dist", float(np.median(dist)), flush=True)
    # spawn off the hit as the kernel does, into the hemisphere of ng facing back to the origin
    pp = mi.Point3f(*[mi.Float(p[:, k]) for k in range(3)])
    side = -np.sign((ng * d[h]).sum(1))[:, None]
    nn = ng * side
    w = rng.normal(size=(len(p), 3)); w /= np.linalg.norm(w, axis=1, keepdims=True)
    w = np.where(((w * nn).sum(1) < 0)[:, None], -w, w).astype(np.float32)
    off = (1.0 + np.abs(p).max(1)) * float(mi.math.RayEpsilon)
    o2 = (p + nn * off[:, None]).astype(np.float32)
    r2 = mi.Ray3f(mi.Point3f(*[mi.Float(o2[:, k]) for k in range(3)]), mi.Vector3f(*[mi.Float(w[:, k]) for k in range(3)]))
    pi2 = sc.ray_intersect_preliminary(r2, coherent=False)
    h2 = np.asarray(pi2.is_valid()); t2 = np.asarray(pi2.t)
    sid2 = dr.reinterpret_array(mi.UInt32, pi2.shape)
    print(name, "spawned rays hitting within 1e-3 m:", int((h2 & (t2 < 1e-3)).sum()), "within 1e-2:", int((h2 & (t2 < 1e-2)).sum()),
          "same prim+shape+inst:", int((h2 & (A(pi2.prim_index, len(p)) == A(pi.prim_index, n)[h]) & (A(pi2.shape_index, len(p)) == A(pi.shape_index, n)[h]) & (A(dr.reinterpret_array(mi.UInt32, pi2.instance), len(p)) == A(iid, n)[h]) & (t2 < 1e-2)).sum()), flush=True)
