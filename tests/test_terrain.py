"""Terrain: per-triangle geometry, geology from texture colour, soil depth; the moss_garden scene."""
from __future__ import annotations

import importlib
import importlib.util
import math
import re
import sys
import tomllib
import types
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENE_DIR = ROOT / "scenes" / "moss_garden"


def _import_terrain():
    """``mitsuba_veg.terrain``; if the package's __init__ cannot import (a module being edited
    elsewhere), load errors.py and terrain.py by path under a bare package."""
    try:
        return importlib.import_module("mitsuba_veg.terrain")
    except Exception:  # pragma: no cover - only while other modules are half-written
        import mitsuba as mi

        if mi.variant() is None:
            mi.set_variant("llvm_ad_spectral")
        for k in [k for k in sys.modules if k == "mitsuba_veg" or k.startswith("mitsuba_veg.")]:
            del sys.modules[k]
        pkg = types.ModuleType("mitsuba_veg")
        pkg.__path__ = [str(ROOT / "mitsuba_veg")]
        sys.modules["mitsuba_veg"] = pkg
        importlib.import_module("mitsuba_veg.errors")
        return importlib.import_module("mitsuba_veg.terrain")


terrain = _import_terrain()
import mitsuba as mi  # noqa: E402  (variant chosen by the import above)
import drjit as dr  # noqa: E402

from mitsuba_veg.errors import ParameterError, SceneError  # noqa: E402

Terrain = terrain.Terrain


# ------------------------------------------------------------------------------------------
# Geometry of a hand-made mesh
# ------------------------------------------------------------------------------------------

def _hand_mesh():
    v = np.array([
        [0, 0, 0], [0, 0, 1], [2, 0, 0],          # horizontal, normal +y, area 1
        [0, 0, 0], [1, 0, 0], [0, 1, 0],          # vertical, normal +z, area 0.5
        [1, 0, 0], [0, 1, 0], [0, 0, 1],          # oblique, normal (1,1,1)/sqrt3, area sqrt3/2
        [0, 0, 0], [1, 1, 1], [2, 2, 2],          # degenerate (collinear)
    ], float)
    f = np.arange(12).reshape(4, 3)
    uv = np.array([[0, 0], [0, 1], [1, 0]] * 4, float)
    return v, f, uv


def test_areas_normals_centroids_of_hand_mesh():
    v, f, uv = _hand_mesh()
    t = Terrain.from_arrays(v, f, uv, name="hand")
    assert t.n_triangles == 4
    np.testing.assert_allclose(t.areas, [1.0, 0.5, math.sqrt(3) / 2, 0.0], atol=1e-12)
    s = 1 / math.sqrt(3)
    np.testing.assert_allclose(t.normals, [[0, 1, 0], [0, 0, 1], [s, s, s], [0, 0, 0]],
                               atol=1e-12)
    np.testing.assert_allclose(t.centroids[0], [2 / 3, 0, 1 / 3])
    np.testing.assert_allclose(t.centroids[2], [1 / 3, 1 / 3, 1 / 3])
    np.testing.assert_allclose(t.uv, np.tile([1 / 3, 1 / 3], (4, 1)))
    assert t.total_area == pytest.approx(1.5 + math.sqrt(3) / 2)


def test_from_trimesh_keeps_uv_and_matches_arrays():
    import trimesh

    v, f, uv = _hand_mesh()
    tm = trimesh.Trimesh(v[:9], f[:3], process=False,
                         visual=trimesh.visual.TextureVisuals(uv=uv[:9]))
    t = Terrain.from_trimesh(tm, name="tm")
    ref = Terrain.from_arrays(v[:9], f[:3], uv[:9])
    np.testing.assert_allclose(t.areas, ref.areas)
    np.testing.assert_allclose(t.uv, ref.uv)


def test_bad_arrays_are_rejected():
    v, f, _ = _hand_mesh()
    with pytest.raises(ParameterError, match="faces"):
        Terrain.from_arrays(v, f + 100)
    with pytest.raises(ParameterError, match="vertex_uv"):
        Terrain.from_arrays(v, f, np.zeros((3, 2)))
    with pytest.raises(SceneError, match="no texture coordinates"):
        Terrain.from_arrays(v, f).geology_from_texture(SCENE_DIR / "geology.png")


def test_in_box():
    v, f, _ = _hand_mesh()
    t = Terrain.from_arrays(v, f)
    np.testing.assert_array_equal(t.in_box([0, -0.1, 0], [1, 0.1, 1]), [True, False, False, False])


# ------------------------------------------------------------------------------------------
# Geology
# ------------------------------------------------------------------------------------------

def test_classify_reference_and_noisy_colours():
    rgb = np.array([[70, 50, 35], [200, 160, 80], [110, 110, 110], [90, 70, 50], [185, 150, 95],
                    [100, 104, 115]], np.uint8)
    np.testing.assert_array_equal(terrain.classify_geology(rgb), [0, 1, 2, 0, 1, 2])
    np.testing.assert_array_equal(terrain.classify_geology(rgb.astype(float) / 255),
                                  [0, 1, 2, 0, 1, 2])
    assert terrain.GEOLOGY[terrain.classify_geology((200, 160, 80))] == "sand"


def test_bad_colour_gives_clear_error():
    with pytest.raises(ParameterError) as e:
        terrain.classify_geology(np.array([[70, 50, 35], [0, 255, 0]]))
    msg = str(e.value)
    assert "(0, 255, 0)" in msg and "humus" in msg and "index (1,)" in msg
    img = np.zeros((8, 8, 3), np.uint8)
    img[...] = terrain.GEOLOGY_COLOURS["sand"]
    img[2, 5] = (255, 255, 255)
    t = Terrain.from_arrays([[0, 0, 0], [0, 0, 1], [1, 0, 0]], [[0, 1, 2]],
                            uv=[[0.7, 0.3], [0.7, 0.3], [0.7, 0.3]], name="g")
    with pytest.raises(ParameterError, match=r"pixel \(row 2, column 5\).*\(255, 255, 255\)"):
        t.geology_from_texture(img)


def _triangles_at(uvs, size=1e-3):
    """Tiny triangles whose centroid UV is each of ``uvs``."""
    uvs = np.asarray(uvs, float)
    off = np.array([[-size, -size], [2 * size, -size], [-size, 2 * size]])
    vuv = (uvs[:, None, :] + off[None]).reshape(-1, 2)
    v = np.column_stack([vuv[:, 0], np.zeros(len(vuv)), vuv[:, 1]])
    return Terrain.from_arrays(v, np.arange(len(v)).reshape(-1, 3), vuv)


def test_shipped_texture_at_known_uv():
    # uv = ((x + 1) / 2, (z + 1) / 2); v = 0 is the image's top row = the north (back) edge
    points = {  # (x, z) [m] -> class
        (0.5, -0.8): "humus",     # back, under the roof
        (-0.8, 0.5): "humus",     # west strip
        (0.55, 0.5): "sand",      # front-east patch (the mound)
        (0.9, 0.9): "sand",
        (-0.25, 0.5): "asphalt",  # path
        (-0.25, -0.6): "asphalt",  # path end under the roof
        (-0.25, -0.8): "humus",   # beyond the path's end
    }
    uvs = [((x + 1) / 2, (z + 1) / 2) for x, z in points]
    t = _triangles_at(uvs)
    codes = t.geology_from_texture(SCENE_DIR / "geology.png")
    assert [terrain.GEOLOGY[c] for c in codes] == list(points.values())


def _ground_only_scene():
    return mi.load_dict({"type": "scene", "ground": {
        "type": "ply", "filename": str(SCENE_DIR / "ground.ply")}})


def test_geology_matches_mitsuba_texture_lookup():
    """Per triangle, the class equals that of the texel Mitsuba's own bitmap lookup returns at
    the hit point above the centroid (so UV interpolation and the v axis agree with Mitsuba)."""
    scene = _ground_only_scene()
    g = Terrain.from_mitsuba(scene.shapes()[0])
    codes = g.geology_from_texture(SCENE_DIR / "geology.png")
    c = g.centroids
    ray = mi.Ray3f(mi.Point3f(mi.Float(c[:, 0]), mi.Float(np.full(len(c), 2.0)), mi.Float(c[:, 2])),
                   mi.Vector3f(0, -1, 0))
    si = scene.ray_intersect(ray)
    assert bool(dr.all(si.is_valid()))
    np.testing.assert_allclose(np.array(si.uv).T, g.uv, atol=1e-4)
    tex = mi.load_dict({"type": "bitmap", "filename": str(SCENE_DIR / "geology.png"),
                        "filter_type": "nearest", "raw": True})
    rgb = np.round(np.array(tex.eval_3(si)).T * 255.0).astype(np.uint8)
    np.testing.assert_array_equal(terrain.classify_geology(rgb), codes)
    assert set(np.unique(codes)) == {0, 1, 2}


# ------------------------------------------------------------------------------------------
# Soil depth
# ------------------------------------------------------------------------------------------

def _quad(p0, p1, p2, p3):
    return [p0, p1, p2, p3], [[0, 1, 2], [0, 2, 3]]


def test_soil_depth_rule_flat_wall_roof():
    # flat ground at y = 0.2 facing up (quad a, c, b order: +y), a vertical wall facing +z,
    # a roof slab underside at y = 0.75 facing down, a roof top at y = 2.5 facing up, a 45 deg
    # slope and a 70 deg slope
    gv, gf = _quad([0, 0.2, 0], [0, 0.2, 1], [1, 0.2, 1], [1, 0.2, 0])
    wv, wf = _quad([0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0])
    uv_, uf = _quad([0, 0.75, 0], [1, 0.75, 0], [1, 0.75, 1], [0, 0.75, 1])
    tv, tf = _quad([0, 2.5, 0], [0, 2.5, 1], [1, 2.5, 1], [1, 2.5, 0])
    s45v, s45f = _quad([0, 0, 0], [0, 0, 1], [1, 1, 1], [1, 1, 0])
    a = math.tan(math.radians(70))
    s70v, s70f = _quad([0, 0, 0], [0, 0, 1], [1, a, 1], [1, a, 0])
    parts = [(gv, gf), (wv, wf), (uv_, uf), (tv, tf), (s45v, s45f), (s70v, s70f)]
    verts, faces = [], []
    for v, f in parts:
        faces.append(np.asarray(f) + sum(len(p[0]) for p in parts[:len(verts)]))
        verts.append(np.asarray(v, float))
    t = Terrain.from_arrays(np.concatenate(verts), np.concatenate(faces))
    ny = t.normals[:, 1]
    np.testing.assert_allclose(ny, [1, 1, 0, 0, -1, -1, 1, 1, *[math.cos(math.radians(45))] * 2,
                                    *[math.cos(math.radians(70))] * 2], atol=1e-12)
    h = t.soil_depth_mm(base_y=0.0)
    cy = t.centroids[:, 1]
    expected = [200, 200, 1, 1, 1, 1, 1000, 1000, 1000 * cy[8], 1000 * cy[9], 1, 1]
    np.testing.assert_allclose(h, expected)
    # default base: the lowest vertex (y = 0 here) -> same
    np.testing.assert_allclose(t.soil_depth_mm(), expected)
    # base above the centroid -> at least 1 mm; explicit override
    assert t.soil_depth_mm(base_y=0.5)[0] == 1.0
    np.testing.assert_array_equal(t.soil_depth_mm(override_mm=1.0), np.ones(12))
    with pytest.raises(ParameterError):
        t.soil_depth_mm(override_mm=0.0)


def test_soil_depths_per_shape():
    g = Terrain.from_arrays(*_quad([0, 0.1, 0], [0, 0.1, 1], [1, 0.1, 1], [1, 0.1, 0]))
    r = Terrain.from_arrays(*_quad([0, 2, 0], [0, 2, 1], [1, 2, 1], [1, 2, 0]))
    w = Terrain.from_arrays(*_quad([0, 0, 0], [0, 0, 1], [1, 0.3, 1], [1, 0.3, 0]))
    h = terrain.soil_depths_mm({"ground": g, "roof": r, "wall": w}, base_y=-0.2,
                               overrides={"wall": 5.0})
    np.testing.assert_allclose(h["ground"], [300, 300])
    np.testing.assert_allclose(h["roof"], [1, 1])      # not a soil shape: no soil below
    np.testing.assert_allclose(h["wall"], [5, 5])      # explicit override
    with pytest.raises(SceneError, match="'rock'"):
        terrain.soil_depths_mm({"ground": g}, overrides={"rock": 1.0})


# ------------------------------------------------------------------------------------------
# The moss_garden scene
# ------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def garden():
    scene = mi.load_file(str(SCENE_DIR / "scene.xml"), optimize=False)
    with open(SCENE_DIR / "scenario.toml", "rb") as fh:
        cfg = tomllib.load(fh)
    return scene, terrain.terrains_from_scene(scene), cfg


def test_scene_keeps_ids_and_ground_uv(garden):
    scene, ter, cfg = garden
    assert sorted(s.id() for s in scene.shapes()) == ["ground", "roof", "wall"]
    g = ter[cfg["terrain"]["ground"]]
    assert g.uv is not None and g.n_triangles == 3200
    assert g.uv.min() > 0 and g.uv.max() < 1
    assert np.all(g.normals[:, 1] > 0.9)                       # gentle relief, facing up
    lo, hi = g.vertices.min(0), g.vertices.max(0)
    np.testing.assert_allclose([lo[0], lo[2], hi[0], hi[2]], [-1, -1, 1, 1])
    assert -0.1 < lo[1] < 0 < hi[1] < 0.2
    # explicit uniform spectra (a plain float would be D65-shaped for emitters)
    for e in scene.emitters():
        assert "UniformSpectrum" in str(e)


def test_boxes_closed_with_outward_normals(garden):
    import trimesh

    _, ter, _ = garden
    for name in ("roof", "wall"):
        t = ter[name]
        tm = trimesh.Trimesh(t.vertices, t.faces, process=True)
        assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0, name
    roof = ter["roof"]
    down = roof.normals[:, 1] < -0.999
    assert roof.areas[down].sum() == pytest.approx(2.0 * 1.1, rel=1e-5)   # the whole underside
    np.testing.assert_allclose(roof.centroids[down, 1], 0.75, atol=1e-6)


def _region_mask(ter, region, shape):
    return ter[shape].in_box(region["min"], region["max"]) if shape in region["shapes"] else None


def test_regions(garden):
    scene, ter, cfg = garden
    under, open_ = cfg["regions"]["under_roof"], cfg["regions"]["open"]
    g_under = _region_mask(ter, under, "ground")
    r_under = _region_mask(ter, under, "roof")
    assert g_under.sum() > 500 and r_under.sum() > 100
    assert np.all(ter["roof"].normals[r_under, 1] < -0.999)      # only the underside
    assert _region_mask(ter, open_, "ground").sum() > 500
    assert not np.any(g_under & _region_mask(ter, open_, "ground"))
    geo = ter["ground"].geology_from_texture(SCENE_DIR / cfg["terrain"]["geology_texture"])
    assert np.any(geo[g_under] == terrain.HUMUS)


def test_under_roof_is_shaded_and_open_is_sunlit(garden):
    scene, ter, cfg = garden
    xml = (SCENE_DIR / "scene.xml").read_text()
    d = np.array([float(x) for x in re.search(
        r'name="direction" x="([-\d.e]+)" y="([-\d.e]+)" z="([-\d.e]+)"', xml).groups()])
    to_sun = -d / np.linalg.norm(d)
    assert math.degrees(math.asin(to_sun[1])) == pytest.approx(55.0, abs=0.01)
    for name, want_lit in (("under_roof", False), ("open", True)):
        region = cfg["regions"][name]
        for shape in region["shapes"]:
            t = ter[shape]
            m = t.in_box(region["min"], region["max"])
            c = t.centroids[m] + 1e-4 * t.normals[m]
            ray = mi.Ray3f(mi.Point3f(*(mi.Float(c[:, i]) for i in range(3))),
                           mi.Vector3f(*(float(x) for x in to_sun)))
            lit = ~np.array(scene.ray_test(ray)) & (t.normals[m] @ to_sun > 0)
            assert np.all(lit == want_lit), (name, shape, lit.mean())


def test_generator_reproduces_shipped_files(tmp_path):
    spec = importlib.util.spec_from_file_location("make_scene", SCENE_DIR / "make_scene.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    for name in ("ground.ply", "roof.ply", "wall.ply", "scene.xml"):
        assert (tmp_path / name).read_bytes() == (SCENE_DIR / name).read_bytes(), name
    from PIL import Image

    a = np.asarray(Image.open(tmp_path / "geology.png"))
    b = np.asarray(Image.open(SCENE_DIR / "geology.png"))
    np.testing.assert_array_equal(a, b)
