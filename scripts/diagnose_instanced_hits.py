"""Instanced hits on this backend (on a GPU: ``MITSUBA_VEG_VARIANT=cuda_ad_spectral python
scripts/diagnose_instanced_hits.py``, the package installed).

The instanced-plant tests failed on OptiX (extra ray casts, recorded flux 2.6 % above the
emitted energy): there a hit inside an instance names the mesh as its ``shape`` with
``shape_index`` 0, where Embree gives a null shape and the mesh's place in its group, and the
kernel took every instanced hit for its group's first mesh's BSDF (the stems reflected like
leaves). This prints, for the 1,000-plant scene with instances
and with the same plants as plain meshes:

A. the photon pass of the tests (1M photons, seed 3): rays cast, the absorption re-estimated
   from the recorded flux, and the direct / indirect flux per part;
B. the element and BSDF the kernel's lookup gives against Mitsuba's own surface interaction;
C. how often a ray spawned off a hit hits at once, with the hit point taken along the ray
   (``ray(t)``), from Mitsuba's interaction (barycentric) and projected onto the element's
   plane, and whether that hit is the same element or another one.
"""
import sys
from collections import Counter

import numpy as np
import mitsuba as mi
import drjit as dr
import mitsuba_veg as mv  # noqa: F401  (sets the variant)
from mitsuba_veg.light import validation as V
from mitsuba_veg.light.photon import photon_irradiance
from mitsuba_veg.integrators.scene_index import SceneIndex, _children, registry_id

print("variant", mi.variant(), flush=True)
A = lambda x, n: np.broadcast_to(np.asarray(x), (n,))
ALB = {"leaves": 0.4, "stem": 0.1, "ground": 0.2}
for name, inst in (("inst", True), ("plain", False))[:int(sys.argv[1]) if len(sys.argv) > 1 else 2]:
    sc = mi.load_dict(V.plant_scene(1000, instanced=inst), optimize=False)
    # A. the pass of the tests
    res = photon_irradiance(sc, photons=int(sys.argv[2]) if len(sys.argv) > 2 else 1_000_000, seed=3, max_depth=100, bands=("total",))
    emitted, escaped = res.emitted[:, 0].sum(), res.escaped[:, 0].sum()
    parts = {"ground": [("ground", "ground")]}
    for i in range(1000):
        k = i % 3
        for part in ("leaves", "stem"):
            sid = f"p{i:04d}/{part}{k}" if inst else f"p{i:04d}_{part}"
            parts.setdefault(part, []).append((sid, part))
    absorbed = 0.0
    line = []
    for part, ids in parts.items():
        tot = {c: sum(res.flux_of(s, "total", component=c, side="both").sum() for s, _ in ids)
               for c in ("direct", "indirect")}
        back = sum(res.flux_of(s, "total", side="back").sum() for s, _ in ids)
        # one-sided diffuse (Mitsuba's semantics): a back-face hit is absorbed whole
        absorbed += (1 - ALB[part]) * (tot["direct"] + tot["indirect"] - back) + back
        line.append(f"{part} direct {tot['direct']:.5g} indirect {tot['indirect']:.5g} "
                    f"back {back:.5g}")
    print(f"A {name}: rays {res.rays_traced}, (re-estimated absorbed + escaped) / emitted "
          f"{(absorbed + escaped) / emitted:.5f}; " + "; ".join(line), flush=True)

    # B. lookup against Mitsuba's interaction
    idx = SceneIndex.build(sc)
    bb = idx.aim_bbox
    n = 400_000
    rng = np.random.default_rng(1)
    lo, hi = np.array(bb.min), np.array(bb.max)
    o = rng.uniform(lo, hi, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k]) for k in range(3)]),
                   mi.Vector3f(*[mi.Float(d[:, k]) for k in range(3)]))
    pi = sc.ray_intersect_preliminary(ray, coherent=False)
    hit = pi.is_valid()
    sid = dr.reinterpret_array(mi.UInt32, pi.shape)
    elem = dr.gather(mi.UInt32, idx.lookup, sid, hit) + pi.prim_index
    bsdf = dr.gather(mi.UInt32, idx.bsdf_lookup, sid, hit)
    iid = dr.reinterpret_array(mi.UInt32, pi.instance)
    if inst:   # as the kernel: OptiX names the mesh as the shape, Embree by shape_index
        in_inst = hit & (iid > 0)
        by_slot = in_inst & (sid == 0)
        slot = dr.gather(mi.UInt32, idx.group_base, iid, by_slot) + pi.shape_index
        elem += dr.select(in_inst, dr.gather(mi.UInt32, idx.lookup, iid, in_inst), 0) \
            + dr.select(by_slot, dr.gather(mi.UInt32, idx.group_local, slot, by_slot), 0)
        bsdf = dr.select(by_slot, dr.gather(mi.UInt32, idx.group_bsdf, slot, by_slot), bsdf)
    si = pi.compute_surface_interaction(ray, mi.RayFlags.All, hit)
    bsdf_mi = dr.reinterpret_array(mi.UInt32, si.bsdf(ray))
    h = np.asarray(hit)
    e = np.asarray(elem)[h]
    ng = np.stack([np.asarray(si.n[k]) for k in range(3)], 1)[h]
    p_si = np.stack([np.asarray(si.p[k]) for k in range(3)], 1)[h]
    t = np.asarray(pi.t)[h]
    p_t = (o[h] + d[h] * t[:, None]).astype(np.float32)
    nt = idx.normals[e]
    ct = idx.centroids[e]
    dot = np.abs((ng * nt).sum(1))
    dist = np.linalg.norm(p_si - ct, axis=1)
    wrong = np.asarray(bsdf)[h] != np.asarray(bsdf_mi)[h]
    wrong_bsdf = int(wrong.sum())
    if inst:
        names = {}
        for sh in sc.shapes():
            if sh.class_name() == "Instance":
                continue
            if sh.bsdf() is not None:
                names[registry_id(sh.bsdf())] = sh.id()
        for gname, g in _children(sc).items():
            if isinstance(g, mi.Shape) and g.class_name().startswith("ShapeGroup"):
                print("  group", gname, [(n, registry_id(s_), registry_id(s_.bsdf()))
                                         for n, s_ in _children(g).items()
                                         if isinstance(s_, mi.Shape)], flush=True)
        shp = dr.reinterpret_array(mi.UInt32, si.shape)
        c4 = Counter((int(a), int(b), int(c_)) for a, b, c_ in
                     zip(np.asarray(shp)[h], np.asarray(bsdf_mi)[h], np.asarray(bsdf)[h]))
        print("  (si.shape, si.bsdf, kernel bsdf):", sorted(c4.items()), flush=True)
        print("  group_base", np.asarray(idx.group_base)[np.asarray(idx.group_base) > 0][:8],
              "group_local", np.asarray(idx.group_local), "group_bsdf",
              [names.get(int(b), int(b)) for b in np.asarray(idx.group_bsdf)], flush=True)
        si_idx = A(pi.shape_index, n)[h]
        pr = A(pi.prim_index, n)[h]
        kb, mb = np.asarray(bsdf)[h], np.asarray(bsdf_mi)[h]
        ii = A(iid, n)[h]
        c = Counter((names.get(int(a), int(a)), names.get(int(b), int(b)), int(s_))
                    for a, b, s_ in zip(kb[wrong], mb[wrong], si_idx[wrong]))
        print("  wrong (kernel, mitsuba, shape_index):", c.most_common(8), flush=True)
        c2 = Counter((names.get(int(a), int(a)), int(s_)) for a, s_ in zip(kb[~wrong], si_idx[~wrong]))
        print("  right (bsdf, shape_index):", c2.most_common(8), flush=True)
        # does the wrong one depend on the instance's group?
        gb = np.asarray(idx.group_base)[ii]
        c3 = Counter((int(g_), bool(w_)) for g_, w_ in zip(gb, wrong))
        print("  (group_base, wrong):", sorted(c3.items()), flush=True)
    off_plane_t = np.abs(((p_t - ct) * nt).sum(1))
    off_plane_si = np.abs(((p_si - ct) * nt).sum(1))
    print(f"B {name}: hits {h.sum()}, in instances {int(np.asarray(iid > 0)[h].sum())}, "
          f"|n.n_elem| < 0.999: {int((dot < 0.999).sum())}, far from centroid (> 0.5 m): "
          f"{int((dist > 0.5).sum())}, BSDF differs from Mitsuba's: {wrong_bsdf}; distance to "
          f"the element's plane: ray(t) median {np.median(off_plane_t):.2e} p99.9 "
          f"{np.quantile(off_plane_t, 0.999):.2e} max {off_plane_t.max():.2e}, si.p median "
          f"{np.median(off_plane_si):.2e} max {off_plane_si.max():.2e}", flush=True)

    # C. spawn off the hit into the hemisphere facing back to the origin
    side = -np.sign((nt * d[h]).sum(1))[:, None]
    nn = nt * side
    w = rng.normal(size=(len(e), 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    w = np.where(((w * nn).sum(1) < 0)[:, None], -w, w).astype(np.float32)
    plane = (p_t - nt * ((p_t - ct) * nt).sum(1)[:, None]).astype(np.float32)
    for label, p in (("ray(t)", p_t), ("si.p", p_si), ("on plane", plane)):
        off = (1.0 + np.abs(p).max(1)) * float(mi.math.RayEpsilon)
        o2 = (p + nn * off[:, None]).astype(np.float32)
        r2 = mi.Ray3f(mi.Point3f(*[mi.Float(o2[:, k]) for k in range(3)]),
                      mi.Vector3f(*[mi.Float(w[:, k]) for k in range(3)]))
        pi2 = sc.ray_intersect_preliminary(r2, coherent=False)
        h2 = np.asarray(pi2.is_valid())
        t2 = np.asarray(pi2.t)
        sid2 = dr.reinterpret_array(mi.UInt32, pi2.shape)
        e2 = dr.gather(mi.UInt32, idx.lookup, sid2, pi2.is_valid()) + pi2.prim_index
        if inst:
            iid2 = dr.reinterpret_array(mi.UInt32, pi2.instance)
            in2 = pi2.is_valid() & (iid2 > 0)
            by2 = in2 & (sid2 == 0)
            slot2 = dr.gather(mi.UInt32, idx.group_base, iid2, by2) + pi2.shape_index
            e2 += dr.select(in2, dr.gather(mi.UInt32, idx.lookup, iid2, in2), 0) \
                + dr.select(by2, dr.gather(mi.UInt32, idx.group_local, slot2, by2), 0)
        e2 = np.asarray(e2)
        near = h2 & (t2 < 1e-3)
        print(f"C {name} {label}: spawned rays hitting within 1e-3 m {int(near.sum())} "
              f"(same element {int((near & (e2 == e)).sum())}, another "
              f"{int((near & (e2 != e)).sum())}), within 1e-2 m {int((h2 & (t2 < 1e-2)).sum())}",
              flush=True)
