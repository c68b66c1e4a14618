"""The differentiable photon pass (the integrator's recorded weights-mode paths replayed by
mitsuba_veg.integrators.photon_replay, and the plugin's render_forward / render_backward behind
``mi.render(scene, params)``): same light as the integrator, gradients w.r.t. per-triangle
reflectance, BSDF parameters and emitter parameters against finite differences."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex
from mitsuba_veg.light.validation import roof_wall_scene
from mitsuba_veg.integrators import photon_replay

F64 = dr.float64_array_t(mi.Float)
TRACER = PhotonIrradianceIntegrator()
ALBEDO = {"ground": 0.3, "roof": 0.5, "wall": 0.5}


@pytest.fixture(scope="module")
def scene():
    s = mi.load_dict(roof_wall_scene(n=12), optimize=False)
    return s, SceneIndex.build(s)


@pytest.fixture(scope="module")
def paths(scene):
    s, idx = scene
    return {e: TRACER.trace_paths(s, e, 400_000, index=idx, max_depth=8, seed=5)
            for e in ("sun", "sky")}


def albedo(idx, values=ALBEDO):
    a = np.zeros(idx.n_elements)
    for sid, v in values.items():
        a[idx.shape_slice(sid)] = v
    return a


def test_same_light_as_the_integrator(scene, paths):
    s, idx = scene
    res = PhotonIrradianceIntegrator().trace(s, photons=2_000_000, seed=1, max_depth=8,
                                             bands=("total",))
    ref = res.element_irradiance("total")
    a = F64(albedo(idx))
    ours = sum(np.asarray(photon_replay.irradiance(paths[e], a)) for e in ("sun", "sky"))
    for sid in ("ground", "roof", "wall"):
        sl = idx.shape_slice(sid)
        tot_ref = (ref[sl] * idx.areas[sl]).sum()
        tot = (ours[sl] * idx.areas[sl]).sum()
        assert tot == pytest.approx(tot_ref, rel=0.02), sid
    g = idx.shape_slice("ground")
    rms = np.sqrt(np.mean((ours[g] - ref[g]) ** 2)) / ref[g].mean()
    assert rms < 0.04  # measured 1.3 % with 1M photons per emitter


def test_replay_is_deterministic_and_linear_in_strength(scene, paths):
    _, idx = scene
    a = F64(albedo(idx))
    f1 = np.asarray(photon_replay.replay(paths["sun"], a))
    f2 = np.asarray(photon_replay.replay(paths["sun"], a))
    f3 = np.asarray(photon_replay.replay(paths["sun"], a, strength=2.5))
    assert np.allclose(f1, f2, rtol=1e-12, atol=0)  # float atomics: only the summation order varies
    assert np.allclose(f3, 2.5 * f1, rtol=1e-12)
    both = np.asarray(photon_replay.replay(paths["sun"], a, side="both"))
    back = np.asarray(photon_replay.replay(paths["sun"], a, side="back"))
    assert np.allclose(both, f1 + back)
    # black surfaces: only the direct light remains (first hits)
    direct = np.asarray(photon_replay.replay(paths["sun"], F64(np.zeros(idx.n_elements))))
    assert np.all(direct <= f1 + 1e-12) and direct.sum() < f1.sum()


def test_reflectance_and_strength_gradients_match_finite_differences(scene, paths):
    _, idx = scene
    a0 = albedo(idx)
    g = idx.shape_slice("ground")
    # loss: light on the shaded back half of the ground (lit only indirectly and by the sky)
    back = np.zeros(idx.n_elements)
    back[g] = (idx.centroids[g][:, 2] < -0.2).astype(float)
    w = F64(back * idx.areas)

    def loss(a_np, s_sun=1.0, s_sky=1.0):
        a = F64(a_np)
        return dr.sum((photon_replay.irradiance(paths["sun"], a, s_sun)
                       + photon_replay.irradiance(paths["sky"], a, s_sky)) * w)

    a = F64(a0)
    s_sun, s_sky = F64(1.0), F64(1.0)
    dr.enable_grad(a, s_sun, s_sky)
    L = dr.sum((photon_replay.irradiance(paths["sun"], a, s_sun)
                + photon_replay.irradiance(paths["sky"], a, s_sky)) * w)
    dr.backward(L)
    ga = np.asarray(dr.grad(a))
    # a roof underside triangle, a wall triangle facing the ground, a shaded ground triangle
    roof = idx.shape_slice("roof")
    wall = idx.shape_slice("wall")
    cand = [roof.start + int(np.argmax(-idx.normals[roof][:, 1])),
            wall.start + int(np.argmax(idx.normals[wall][:, 2])),
            g.start + int(np.argmax(back[g] * (ga[g] + 0)))]
    h = 1e-3
    for e in cand:
        up, dn = a0.copy(), a0.copy()
        up[e] += h
        dn[e] -= h
        fd = (float(loss(up)[0]) - float(loss(dn)[0])) / (2 * h)
        assert abs(fd) > 0
        assert ga[e] == pytest.approx(fd, rel=0.01), e
    # the whole roof's albedo at once
    up, dn = a0.copy(), a0.copy()
    up[roof] += h
    dn[roof] -= h
    fd = (float(loss(up)[0]) - float(loss(dn)[0])) / (2 * h)
    assert ga[roof].sum() == pytest.approx(fd, rel=0.01)
    # emitter strengths: the loss is linear in them
    fd_sun = (float(loss(a0, 1.01)[0]) - float(loss(a0, 0.99)[0])) / 0.02
    assert float(dr.grad(s_sun)[0]) == pytest.approx(fd_sun, rel=1e-6)
    assert float(dr.grad(s_sky)[0]) > 0


def test_errors(scene, paths):
    s, idx = scene
    with pytest.raises(ParameterError, match="albedo"):
        photon_replay.replay(paths["sun"], F64(np.zeros(3)))
    with pytest.raises(ParameterError, match="emitter"):
        TRACER.trace_paths(s, "moon", 1000, index=idx)


# ---- mi.render(scene, params): the plugin's render_forward / render_backward -----------------
def _ad_scene(integrator=None):
    """A one-sided diffuse floor, a two-sided diffuse wall beside it and a sun (uniform spectra:
    the replay's band-mean albedo is exact)."""
    T = mi.ScalarTransform4f()
    return mi.load_dict({
        "type": "scene",
        "integrator": integrator or {"type": "veg_photon_irradiance", "photons": 100_000,
                                     "bands": "par,red"},
        "sensor": {"type": "perspective"},
        "floor": {"type": "rectangle", "to_world": T.scale([2, 2, 1]),
                  "bsdf": {"type": "diffuse",
                           "reflectance": {"type": "uniform", "value": 0.3}}},
        "wall": {"type": "rectangle", "to_world": T.translate([0, 1, 1]).rotate([1, 0, 0], 90),
                 "bsdf": {"type": "twosided", "bsdf": {
                     "type": "diffuse", "reflectance": {"type": "uniform", "value": 0.6}}}},
        "sun": {"type": "directional", "direction": [0.3, 0.5, -1.0],
                "irradiance": {"type": "uniform", "value": 2.0}},
    }, optimize=False)


AD_KEYS = {"floor.bsdf.reflectance.value": 0.3, "wall.bsdf.brdf_0.reflectance.value": 0.6,
           "sun.irradiance.value": 2.0}


def _tensor_at(scene, key, value, seed):
    p = mi.traverse(scene)
    p[key] = value
    p.update()
    with dr.suspend_grad():
        return np.asarray(scene.integrator()._render_ad(scene, p, seed, 0))


def test_bsdf_albedo_follows_mitsubas_sides():
    from mitsuba_veg.integrators.photon_replay import bsdf_albedo
    s = _ad_scene()
    idx = SceneIndex.build(s)
    front, back = (np.asarray(x) for x in bsdf_albedo(s, idx, (400.0, 700.0)))
    f, w = idx.shape_slice("floor"), idx.shape_slice("wall")
    assert np.allclose(front[f], 0.3, rtol=1e-5) and np.all(back[f] == 0)  # one-sided diffuse
    assert np.allclose(front[w], 0.6, rtol=1e-5) and np.allclose(back[w], 0.6, rtol=1e-5)


@pytest.mark.parametrize("key", list(AD_KEYS))
def test_render_forward_is_the_derivative_of_the_replay(key):
    """Forward mode equals a central difference of the replay with the same paths (the replay
    is a polynomial in the albedos and linear in the emitter's power)."""
    s = _ad_scene()
    p = mi.traverse(s)
    dr.enable_grad(p[key])
    p.update()
    dr.set_grad(p[key], 1.0)
    g = np.asarray(s.integrator().render_forward(s, p, seed=3))
    assert g.shape == (4, 2, 2, 2)   # 2 rectangles x 2 triangles, bands, (direct, indirect), sides
    h = 0.05
    v0 = AD_KEYS[key]
    fd = (_tensor_at(_ad_scene(), key, v0 + h, 3) - _tensor_at(_ad_scene(), key, v0 - h, 3)) \
        / (2 * h)
    if key.startswith("sun"):
        # linear in the sun: the derivative is the tensor over the irradiance value
        base = _tensor_at(_ad_scene(), key, v0, 3)
        assert np.allclose(g, base / v0, rtol=1e-4, atol=1e-6 * base.max())
        assert np.all(g[:, :, 0, 0] > 0)
    else:
        assert np.all(g[:, :, 0] == 0)          # direct light does not depend on an albedo
        ind = g[:, :, 1]
        assert ind.sum() > 0
        assert np.allclose(ind, fd[:, :, 1], rtol=2e-3, atol=1e-4 * np.abs(ind).max())


def test_render_backward_through_mi_render_matches_forward_mode():
    """dr.backward through mi.render reaches the plugin's render_backward: the gradient of a
    loss on the wall's indirect light equals forward mode with the same paths."""
    key = "floor.bsdf.reflectance.value"
    s = _ad_scene()
    integ = s.integrator()
    weights = np.zeros((4, 2, 2, 2), np.float32)
    weights[2:, 0, 1, 0] = 1.0                   # the wall's front, PAR, indirect
    weights[2:, 1, 1, 1] = 0.5                   # its back, red, indirect
    p = mi.traverse(s)
    dr.enable_grad(p[key])
    p.update()
    integ.render_backward(s, p, mi.TensorXf(weights), seed=7)
    g_rev = float(dr.grad(p[key])[0])
    s2 = _ad_scene()
    p2 = mi.traverse(s2)
    dr.enable_grad(p2[key])
    p2.update()
    dr.set_grad(p2[key], 1.0)
    g_fwd = float((np.asarray(s2.integrator().render_forward(s2, p2, seed=7)) * weights).sum())
    assert g_rev > 0 and g_rev == pytest.approx(g_fwd, rel=1e-4)
    # through mi.render (its own gradient seed): the same derivative within Monte-Carlo noise
    s3 = _ad_scene()
    p3 = mi.traverse(s3)
    dr.enable_grad(p3[key])
    p3.update()
    img = mi.render(s3, p3, seed=1)
    dr.backward(dr.sum(img.array * mi.Float(weights.ravel())))
    assert float(dr.grad(p3[key])[0]) == pytest.approx(g_fwd, rel=0.05)


def test_render_derivatives_refuse_geometry_and_images():
    s = _ad_scene()
    p = mi.traverse(s)
    dr.enable_grad(p["floor.to_world"])
    with pytest.raises(ParameterError, match="floor.to_world"):
        s.integrator().render_forward(s, p)
    s = _ad_scene({"type": "veg_photon_irradiance", "photons": 1000, "output": "image"})
    p = mi.traverse(s)
    with pytest.raises(ParameterError, match="output"):
        s.integrator().render_backward(s, p, mi.TensorXf(np.zeros((4, 1, 2, 2), np.float32)))
