"""Voxel-space light of paper 002: the 36 sky rays, the 3D-DDA kernel against a brute-force
reference, opaque obstacles, the finite-difference gradient."""
import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.trees.environment import Environment
from mitsuba_veg.trees.voxel import OPAQUE_TAU, VoxelSpace, gradient_sampler, sky_rays


def test_sky_rays_are_the_papers_36():
    d, w = sky_rays()
    assert d.shape == (36, 3) and w.sum() == pytest.approx(1.0)
    el = np.degrees(np.arcsin(d[:, 1]))
    assert sorted(set(np.round(el, 6))) == pytest.approx([15.0, 45.0, 75.0])
    # solid-angle weights of the three 30-degree bands
    band = [w[np.isclose(el, e)].sum() for e in (15, 45, 75)]
    assert band == pytest.approx([0.5, math.sqrt(3) / 2 - 0.5, 1 - math.sqrt(3) / 2])


def _space(tau, size=0.5, origin=(0.0, 0.0, 0.0)):
    return VoxelSpace(np.asarray(origin, float), size, np.asarray(tau, float),
                      np.zeros(np.shape(tau), bool))


def test_empty_space_is_open_sky():
    vs = _space(np.zeros((8, 5, 7)))
    assert np.allclose(vs.light(np.random.default_rng(0).uniform(0.1, 2.4, (20, 3))), 1.0)


def test_dda_matches_fine_sampling():
    rng = np.random.default_rng(1)
    tau = rng.exponential(0.5, (9, 7, 8))
    vs = _space(tau, size=0.4, origin=(-1.0, 0.2, 0.5))
    pts = vs.origin + rng.uniform(0.05, 0.95, (30, 3)) * np.array(tau.shape) * vs.size
    dirs = rng.normal(size=(7, 3))
    dirs[:, 1] = np.abs(dirs[:, 1])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    got = vs.optical_depth(pts, dirs)
    # exact reference: every crossing of a voxel plane along the ray, in NumPy
    lo = vs.origin
    hi = vs.origin + np.array(tau.shape) * vs.size
    for i, p in enumerate(pts):
        for j, d in enumerate(dirs):
            with np.errstate(divide="ignore", invalid="ignore"):
                t_exit = np.min(np.where(d > 0, (hi - p) / d, np.where(d < 0, (lo - p) / d,
                                                                        np.inf)))
                ts = [0.0, t_exit]
                for a in range(3):
                    if abs(d[a]) > 1e-12:
                        planes = lo[a] + np.arange(tau.shape[a] + 1) * vs.size
                        t = (planes - p[a]) / d[a]
                        ts += list(t[(t > 0) & (t < t_exit)])
            ts = np.unique(ts)
            mid = p + 0.5 * (ts[1:] + ts[:-1])[:, None] * d
            q = np.clip(np.floor((mid - lo) / vs.size).astype(int), 0, np.array(tau.shape) - 1)
            ref = (tau[q[:, 0], q[:, 1], q[:, 2]] * np.diff(ts)).sum() / vs.size
            assert got[i, j] == pytest.approx(ref, rel=1e-4, abs=1e-5)


def test_leaf_counts_and_per_voxel_transmission():
    pts = np.array([[0.25, 0.25, 0.25], [0.3, 0.2, 0.3], [1.2, 0.3, 0.3]])
    vs = VoxelSpace.build(pts, size=0.5, shading=0.3, margin=0)
    assert vs.tau.sum() == pytest.approx(-3 * math.log(0.7))
    assert vs.tau.max() == pytest.approx(-2 * math.log(0.7))
    # a ray along +x through one full voxel holding n leaves keeps (1 - s)^n
    one = _space(np.array([[[0.0]], [[-2 * math.log(0.7)]], [[0.0]]]), size=1.0)
    assert math.exp(-one.optical_depth([[0.5, 0.5, 0.5]], [[1.0, 0.0, 0.0]])[0, 0]) == \
        pytest.approx(0.49)
    with pytest.raises(ParameterError):
        VoxelSpace.build(pts, size=0.5, shading=1.0)


def test_opaque_obstacles_block_the_sky():
    env = Environment().add_box((-20, 2.0, -20), (20, 3.0, 20))       # a wide roof
    vs = VoxelSpace.build(np.array([[0.0, 0.5, 0.0]]), size=0.5, env=env,
                          bounds=(np.array([-20, 0, -20]), np.array([20, 3, 20])))
    assert vs.opaque.any() and vs.tau.max() == OPAQUE_TAU
    light = vs.light([[0.0, 0.5, 0.0], [0.0, 2.5, 0.0], [0.0, 3.6, 0.0]])
    assert light[0] < 1e-6            # under the roof
    assert light[1] == 0.0            # inside it
    assert light[2] == pytest.approx(1.0)


def test_gradient_sampler_on_a_linear_field():
    shape = (6, 5, 4)
    ix, iy, iz = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    size = 0.5
    origin = np.array([1.0, 0.0, -1.0])
    cx = origin[0] + (ix + 0.5) * size
    cz = origin[2] + (iz + 0.5) * size
    field = 0.3 * cx - 0.2 * cz
    g = gradient_sampler(field, origin, size)
    pts = origin + np.array([[1.1, 1.0, 0.9], [2.0, 1.7, 1.3]])
    assert np.allclose(g(pts), [[0.3, 0.0, -0.2]] * 2)
    assert np.allclose(g([[50.0, 0.0, 0.0]]), 0.0)
