"""glTF export (mitsuba_veg.export_gltf): written, loaded back with trimesh, counts and colours."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.export_gltf import (MOSS_RGB, SOIL_RGB, GltfWorld, add_stand, cover_colours,
                                     face_to_vertex_colours, stage_colours, vertex_mean)
from mitsuba_veg.foliage import leaf_spectra, spectrum_to_srgb
from mitsuba_veg.foliage.colour_dr import srgb_decode_np
from mitsuba_veg.forest_floor import rolling_ground
from mitsuba_veg.trees.instancing import build_variants, tree_transforms
from mitsuba_veg.trees.stand import StandSpec, layout


def _u8(rgb):
    return np.round(np.clip(np.asarray(rgb, float), 0, 1) * 255).astype(np.uint8)


def _colours(mesh):
    return np.asarray(mesh.visual.vertex_attributes["color"])[:, :3]


def _quads(k, y0=1.0):
    """k separate unit-ish leaf quads (4 own vertices, 2 triangles each), stacked in y."""
    base = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0.15, 0], [0, 0.15, 0]], float)
    v = np.concatenate([base + [0, y0 + 0.5 * i, 0] for i in range(k)])
    f = np.concatenate([4 * i + np.array([[0, 1, 2], [0, 2, 3]]) for i in range(k)])
    return v, f


def test_stage_colours_come_from_the_leaf_spectra():
    for stage in (1.0, 4.0, 6.5):           # on the table's grid: exact
        s = leaf_spectra(stage=stage)
        ref = srgb_decode_np(spectrum_to_srgb(s.wavelength, s.reflectance))
        np.testing.assert_allclose(stage_colours(stage), ref, atol=1e-12)
    c = stage_colours([1.0, 7.0, 1.02])
    assert c[0, 1] > c[0, 0] and c[0, 1] > c[0, 2]       # green
    assert c[1, 0] > 2 * c[1, 1]                         # red
    np.testing.assert_allclose(c[2], 0.6 * c[0] + 0.4 * stage_colours(1.05), atol=1e-12)
    with pytest.raises(ParameterError):
        stage_colours([np.nan])


def test_cover_blends_soil_and_moss_linearly():
    c = cover_colours([0.0, 1.0, 0.25, 2.0])
    np.testing.assert_allclose(c[0], SOIL_RGB)
    np.testing.assert_allclose(c[1], MOSS_RGB)
    np.testing.assert_allclose(c[2], 0.75 * np.array(SOIL_RGB) + 0.25 * np.array(MOSS_RGB))
    np.testing.assert_allclose(c[3], MOSS_RGB)           # clipped


def test_face_colours_split_vertices_only_where_needed():
    v, f = _quads(2)
    fc = np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]], float)
    v2, f2, vc = face_to_vertex_colours(v, f, fc)       # one colour per quad: kept as is
    assert len(v2) == 8 and np.array_equal(f2, f)
    np.testing.assert_array_equal(vc[f2[:, 0]], fc)
    fc[1] = [0, 0, 1]                                   # two colours on one quad: split
    v3, f3, vc3 = face_to_vertex_colours(v, f, fc)
    assert len(v3) == 12
    np.testing.assert_array_equal(vc3[f3].reshape(4, 3, 3), np.repeat(fc[:, None], 3, 1))
    np.testing.assert_allclose(v3[f3], v[f])


def test_vertex_mean_weights_by_area():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [3, 0, 0], [0, 0, 3.0]])
    F = np.array([[0, 2, 1], [0, 4, 3]])        # areas 0.5 and 4.5, both at vertex 0
    m = vertex_mean(V, F, [1.0, 0.0])
    assert m[0] == pytest.approx(0.5 / 5.0) and m[1] == 1.0 and m[3] == 0.0


def test_export_loads_back_with_counts_names_instances_and_colours(tmp_path):
    g = rolling_ground((0, 0, 4, 4), slope_deg=10, resolution=1.0)
    V, F = g.mesh()                                     # 25 vertices, 32 triangles
    cover = np.zeros(len(F))
    cover[:16] = 1.0
    lv, lf = _quads(3)
    stages = np.array([1.0, 4.0, 7.0])
    bv, bf = _quads(1, 0.0)
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 0, 3] = [0.0, 5.0, 10.0, 15.0]
    w = GltfWorld()
    w.add_terrain("ground", V, F, cover, per_face=True)
    w.add_terrain("ground_smooth", V, F, cover)
    w.add_leaves("leaves", lv, lf, stages, face_leaf=[0, 0, 1, 1, 2, 2])
    nodes = w.add_instances("bark", bv, bf, T)
    w.add_mesh("rock", bv, bf, colour=(0.2, 0.2, 0.2))
    p = w.export(tmp_path / "out" / "world.glb")
    s = trimesh.load(p)
    assert sorted(s.geometry) == ["bark", "ground", "ground_smooth", "leaves", "rock"]
    # every face of the per-face ground has its colour: split where cover changes
    gm = s.geometry["ground"]
    assert len(gm.faces) == 32
    want = _u8(cover_colours(cover))
    got = _colours(gm)[np.asarray(gm.faces)]            # (32, 3 corners, RGB)
    np.testing.assert_array_equal(got, np.repeat(want[:, None], 3, 1))
    gs = s.geometry["ground_smooth"]
    assert len(gs.vertices) == 25 and len(gs.faces) == 32     # per vertex: not split
    np.testing.assert_array_equal(_colours(gs), _u8(cover_colours(vertex_mean(V, F, cover))))
    lm = s.geometry["leaves"]
    assert len(lm.vertices) == 12 and len(lm.faces) == 6      # own corners: not split
    np.testing.assert_array_equal(_colours(lm)[::4], _u8(stage_colours(stages)))
    # instancing: one mesh, four nodes with their transforms
    inst = [n for n in s.graph.nodes_geometry if s.graph[n][1] == "bark"]
    assert sorted(inst) == sorted(nodes) and len(inst) == 4
    xs = sorted(float(s.graph[n][0][0, 3]) for n in inst)
    assert xs == [0.0, 5.0, 10.0, 15.0]
    assert len(s.geometry["bark"].faces) == 2
    np.testing.assert_array_equal(_colours(s.geometry["rock"]), np.full((4, 3), _u8(0.2)))
    # the file holds the bark once: adding 4 more instances grows it by node records only
    w2 = GltfWorld()
    w2.add_instances("bark", bv, bf, np.tile(np.eye(4), (8, 1, 1)))
    w3 = GltfWorld()
    w3.add_instances("bark", bv, bf, np.tile(np.eye(4), (4, 1, 1)))
    a, b = w2.export(tmp_path / "a.glb"), w3.export(tmp_path / "b.glb")
    assert 0 < (tmp_path / "a.glb").stat().st_size - (tmp_path / "b.glb").stat().st_size < 600
    assert a and b


def test_bad_input_is_refused(tmp_path):
    v, f = _quads(1)
    w = GltfWorld()
    w.add_mesh("a", v, f)
    for call in (lambda: w.add_mesh("a", v, f),                       # name twice
                 lambda: w.add_terrain("t", v, f, [0.5]),             # one cover for 2 faces
                 lambda: w.add_leaves("l", v, f, [1, 2, 3]),
                 lambda: w.add_mesh("b", v, f + 10),
                 lambda: w.add_mesh("c", v, f, colour=(1, 0, 0), face_colours=np.ones((2, 3))),
                 lambda: w.add_instances("d", v, f, np.eye(4)),
                 lambda: w.export(tmp_path / "x.gltf"),
                 lambda: GltfWorld().export(tmp_path / "y.glb")):
        with pytest.raises(ParameterError):
            call()


def test_a_stand_exports_as_instances_with_per_tree_leaf_colours(tmp_path):
    st = layout(StandSpec(plot=[0, 0, 20, 20], density=75, min_spacing=3.0, variants=1,
                          mix={"quaking_aspen": 1}, seed=1))
    var = build_variants(st)
    (key, vm), = var.items()
    M = tree_transforms(st, var)
    stages = {i: np.linspace(1, 7, vm.n_leaves) for i in range(len(st))}
    w = GltfWorld()
    names = add_stand(w, st, var, stages=stages)
    p = w.export(tmp_path / "stand.glb")
    s = trimesh.load(p)
    assert len(st) == 3 and names["bark"] == ["bark_quaking_aspen_0"]
    assert sorted(names["leaves"]) == ["leaves_tree_0", "leaves_tree_1", "leaves_tree_2"]
    bark_nodes = [n for n in s.graph.nodes_geometry if s.graph[n][1] == "bark_quaking_aspen_0"]
    assert len(bark_nodes) == 3
    assert len(s.geometry["bark_quaking_aspen_0"].faces) == len(vm.bark[1])
    leaf = s.geometry["leaves_tree_1"]
    assert len(leaf.faces) == 2 * vm.n_leaves and len(leaf.vertices) == 4 * vm.n_leaves
    np.testing.assert_allclose(leaf.vertices[:4], vm.leaves[0][:4] @ M[1, :3, :3].T + M[1, :3, 3],
                               atol=1e-4)
    np.testing.assert_array_equal(_colours(leaf)[::4], _u8(stage_colours(stages[1])))
    # without stages: leaves instanced too, all green
    w2 = GltfWorld()
    n2 = add_stand(w2, st, var)
    assert n2["leaves"] == ["leaves_quaking_aspen_0"]
