"""The forest floor (mitsuba_veg.forest_floor): sloped rolling ground, logs and rocks."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.forest_floor import (Heightfield, log_mesh, place_log, place_rock, relief,
                                      rock_mesh, rolling_ground, scatter_floor, write_ply)
from mitsuba_veg.meshes import triangle_geometry


@pytest.mark.parametrize("slope, aspect", [(0.0, 180.0), (20.0, 135.0), (35.0, 0.0)])
def test_a_plane_has_its_area_normal_and_heights(slope, aspect):
    g = rolling_ground((-20, 10, 40, 50), slope_deg=slope, aspect_deg=aspect, resolution=2.5,
                       y0=3.0)
    V, F = g.mesh()
    a, n, _ = triangle_geometry(V, F)
    t = math.tan(math.radians(slope))
    # a plane over 60 m x 40 m of map: area / cos(slope)
    assert a.sum() == pytest.approx(2400.0 / math.cos(math.radians(slope)), rel=1e-12)
    # downhill (sin aspect, -cos aspect) in (x, z): the normal leans that way
    d = (math.sin(math.radians(aspect)), -math.cos(math.radians(aspect)))
    expect = np.array([t * d[0], 1.0, t * d[1]]) / math.sqrt(1 + t * t)
    np.testing.assert_allclose(n, np.broadcast_to(expect, n.shape), atol=1e-12)
    rng = np.random.default_rng(0)
    x, z = rng.uniform(-20, 40, 50), rng.uniform(10, 50, 50)
    np.testing.assert_allclose(g.height(x, z), 3.0 - t * ((x - 10) * d[0] + (z - 30) * d[1]),
                               atol=1e-9)
    assert g.nx == 24 and g.nz == 16 and len(F) == 2 * 24 * 16


def test_rolling_ground_is_linear_on_its_triangles():
    g = rolling_ground((0, 0, 50, 50), slope_deg=10, roughness=0.4, roughness_scale=8.0,
                       seed=3, resolution=1.0)
    V, F = g.mesh()
    # the nodes hold the plane plus the relief
    X, Z = V[:, 0], V[:, 2]
    plane = -math.tan(math.radians(10)) * (0 * (X - 25) + 1 * (Z - 25))   # aspect 180: +z
    np.testing.assert_allclose(V[:, 1], plane + relief(X, Z, 0.4, 8.0, 3), atol=1e-12)
    # inside cell (i, j) = (7, 12) at u = 0.25, v = 0.5 (lower triangle, u + v <= 1):
    H = g.heights
    h00, h10, h01 = H[12, 7], H[12, 8], H[13, 7]
    assert g.height(7.25, 12.5) == pytest.approx(h00 + 0.25 * (h10 - h00) + 0.5 * (h01 - h00))
    # upper triangle at u = 0.75, v = 0.5
    h11 = H[13, 8]
    assert g.height(7.75, 12.5) == pytest.approx(h11 + 0.25 * (h01 - h11) + 0.5 * (h10 - h11))
    # each triangle's centroid lies on it, in it
    _, _, c = triangle_geometry(V, F)
    np.testing.assert_array_equal(g.face_index(c[:, 0], c[:, 2]), np.arange(len(F)))
    np.testing.assert_allclose(g.height(c[:, 0], c[:, 2]), c[:, 1], atol=1e-12)
    np.testing.assert_allclose(g.normal(c[:5, 0], c[:5, 2]), triangle_geometry(V, F)[1][:5])
    with pytest.raises(ParameterError):
        g.height(51.0, 10.0)


def test_relief_has_the_asked_rms():
    rng = np.random.default_rng(1)
    X, Z = rng.uniform(0, 2000, 40000), rng.uniform(0, 2000, 40000)
    rms = [np.sqrt(np.mean(relief(X, Z, 0.5, 10.0, s) ** 2)) for s in range(5)]
    assert np.mean(rms) == pytest.approx(0.5, rel=0.1)


def test_heightfield_writes_a_ply_and_makes_a_terrain(tmp_path):
    g = rolling_ground((0, 0, 10, 10), slope_deg=15, resolution=1.0)
    p = g.write_ply(tmp_path / "ground.ply")
    m = trimesh.load(p, process=False)
    V, F = g.mesh()
    assert len(m.vertices) == len(V) and len(m.faces) == len(F)
    np.testing.assert_allclose(np.asarray(m.vertices), V, atol=1e-6)
    t = g.terrain("ground")
    assert t.total_area == pytest.approx(100 / math.cos(math.radians(15)))
    hf = Heightfield.from_function((0, 0, 4, 2), 1.0, lambda X, Z: X + 2 * Z)
    assert hf.heights.shape == (3, 5) and hf.height(1.5, 0.5) == pytest.approx(2.5)


def test_a_log_is_a_closed_prism_with_outward_normals():
    n, r, L = 12, 0.3, 4.0
    V, F = log_mesh([1, 0.3, 2], [1 + L, 0.3, 2], r, n)
    m = trimesh.Trimesh(V, F, process=False)
    assert m.is_watertight and m.is_winding_consistent
    cap = 0.5 * n * r * r * math.sin(2 * math.pi / n)
    assert m.area == pytest.approx(L * n * 2 * r * math.sin(math.pi / n) + 2 * cap)
    assert m.volume == pytest.approx(cap * L)            # positive: normals point out
    a, nrm, c = triangle_geometry(V, F)
    mantle = slice(0, 2 * n)
    radial = c[mantle] - [0.0, 0.3, 2.0]          # from the axis (along x, y = 0.3, z = 2)
    radial[:, 0] = 0.0
    assert np.all((nrm[mantle] * radial).sum(1) > 0)
    with pytest.raises(ParameterError):
        log_mesh([0, 0, 0], [0, 0, 0], 0.2)


def test_logs_and_rocks_rest_on_the_slope():
    g = rolling_ground((0, 0, 40, 40), slope_deg=20, aspect_deg=90, resolution=1.0)
    log = place_log(g, 20, 20, length=6, radius=0.25, azimuth_deg=90)   # along the fall line
    a, b = log.vertices[-2], log.vertices[-1]                         # axis ends
    assert a[1] == pytest.approx(float(g.height(a[0], a[2])) + 0.25)
    assert b[1] == pytest.approx(float(g.height(b[0], b[2])) + 0.25)
    assert abs(b[0] - a[0]) == pytest.approx(6.0) and a[1] > b[1]     # it goes downhill east
    rock = place_rock(g, 10, 30, radius=0.5, embed=0.3, flatten=0.6, roughness=0.0, seed=2)
    h = float(g.height(10, 30))
    assert rock.centre[1] == pytest.approx(h + 0.6 * (0.5 - 0.3))
    assert rock.vertices[:, 1].min() == pytest.approx(rock.centre[1] - 0.3, abs=1e-9)
    m = trimesh.Trimesh(rock.vertices, rock.faces, process=False)
    assert m.is_watertight and m.volume > 0
    V, F = rock_mesh([0, 0, 0], 1.0, roughness=0.3, flatten=1.0, seed=4)
    rad = np.linalg.norm(V, axis=1)
    assert rad.min() >= 0.2 - 1e-12 and rad.std() > 0.05
    assert rock.terrain().total_area == pytest.approx(m.area)


def test_scatter_keeps_clear_of_trees_and_of_each_other():
    g = rolling_ground((0, 0, 60, 60), slope_deg=5, roughness=0.2, resolution=2.0)
    trees = np.random.default_rng(0).uniform(5, 55, (40, 2))
    objs = scatter_floor(g, logs=6, rocks=12, seed=7, avoid=trees, clearance=1.0)
    assert [o.kind for o in objs] == ["log"] * 6 + ["rock"] * 12
    assert [o.name for o in objs][:2] == ["log_0", "log_1"]
    c = np.array([o.centre[[0, 2]] for o in objs])
    reach = np.array([o.radius for o in objs])
    d_tree = np.hypot(c[:, None, 0] - trees[None, :, 0], c[:, None, 1] - trees[None, :, 1])
    assert np.all(d_tree - reach[:, None] >= 1.0 - 1e-9)
    d = np.hypot(c[:, None, 0] - c[None, :, 0], c[:, None, 1] - c[None, :, 1])
    gap = d - reach[:, None] - reach[None, :]
    np.fill_diagonal(gap, np.inf)
    assert gap.min() >= 1.0 - 1e-9
    again = scatter_floor(g, logs=6, rocks=12, seed=7, avoid=trees, clearance=1.0)
    np.testing.assert_array_equal(objs[3].vertices, again[3].vertices)
    with pytest.raises(ParameterError):
        scatter_floor(g, logs=0, rocks=500, seed=0, rock_radius=(2.0, 2.5))


def test_write_ply_round_trip(tmp_path):
    V, F = log_mesh([0, 0, 0], [0, 0, 2], 0.2, 8)
    p = write_ply(tmp_path / "sub" / "log.ply", V, F)
    m = trimesh.load(p, process=False)
    assert len(m.faces) == len(F) == 32 and m.is_watertight
