"""The differentiable photon pass (mitsuba_veg.tune.photon_ad): same light as the integrator,
gradients w.r.t. per-triangle reflectance and emitter strength against finite differences."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex
from mitsuba_veg.light.validation import roof_wall_scene
from mitsuba_veg.tune import photon_ad

F64 = dr.float64_array_t(mi.Float)
ALBEDO = {"ground": 0.3, "roof": 0.5, "wall": 0.5}


@pytest.fixture(scope="module")
def scene():
    s = mi.load_dict(roof_wall_scene(n=12), optimize=False)
    return s, SceneIndex.build(s)


@pytest.fixture(scope="module")
def paths(scene):
    s, idx = scene
    return {e: photon_ad.trace_paths(s, e, 400_000, idx, max_depth=8, seed=5)
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
    ours = sum(np.asarray(photon_ad.irradiance(paths[e], a)) for e in ("sun", "sky"))
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
    f1 = np.asarray(photon_ad.replay(paths["sun"], a))
    f2 = np.asarray(photon_ad.replay(paths["sun"], a))
    f3 = np.asarray(photon_ad.replay(paths["sun"], a, strength=2.5))
    assert np.allclose(f1, f2, rtol=1e-12, atol=0)  # float atomics: only the summation order varies
    assert np.allclose(f3, 2.5 * f1, rtol=1e-12)
    both = np.asarray(photon_ad.replay(paths["sun"], a, side="both"))
    back = np.asarray(photon_ad.replay(paths["sun"], a, side="back"))
    assert np.allclose(both, f1 + back)
    # black surfaces: only the direct light remains (first hits)
    direct = np.asarray(photon_ad.replay(paths["sun"], F64(np.zeros(idx.n_elements))))
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
        return dr.sum((photon_ad.irradiance(paths["sun"], a, s_sun)
                       + photon_ad.irradiance(paths["sky"], a, s_sky)) * w)

    a = F64(a0)
    s_sun, s_sky = F64(1.0), F64(1.0)
    dr.enable_grad(a, s_sun, s_sky)
    L = dr.sum((photon_ad.irradiance(paths["sun"], a, s_sun)
                + photon_ad.irradiance(paths["sky"], a, s_sky)) * w)
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
        photon_ad.replay(paths["sun"], F64(np.zeros(3)))
    with pytest.raises(ParameterError, match="emitter"):
        photon_ad.trace_paths(s, "moon", 1000, idx)
