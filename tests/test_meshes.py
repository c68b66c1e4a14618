"""Triangle geometry (mitsuba_veg.meshes.triangle_geometry): hand values and the vector
formulas it spells out component by component."""
import numpy as np

from mitsuba_veg.meshes import triangle_geometry


def test_triangle_geometry_by_hand():
    """A right triangle of legs 2 and 3 in the x-z plane, counter-clockwise seen from +y,
    and a degenerate one (zero area, zero normal)."""
    v = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 3.0], [2.0, 1.0, 0.0], [5.0, 5.0, 5.0]])
    f = np.array([[0, 1, 2], [3, 3, 3]])
    a, n, c = triangle_geometry(v, f)
    np.testing.assert_allclose(a, [3.0, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(n, [[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(c, [[2.0 / 3.0, 1.0, 1.0], [5.0, 5.0, 5.0]], rtol=1e-15)


def test_triangle_geometry_equals_the_vector_formulas_bit_for_bit():
    """Areas, normals and centroids equal 0.5 |(p1 - p0) x (p2 - p0)|, the cross product over
    its norm and (p0 + p1 + p2) / 3 from NumPy's own vector functions, to the last bit."""
    rng = np.random.default_rng(4)
    v = rng.normal(size=(5000, 3)).astype(np.float32)
    f = rng.integers(0, len(v), size=(20000, 3))
    p0, p1, p2 = (v.astype(np.float64)[f[:, k]] for k in range(3))
    cross = np.cross(p1 - p0, p2 - p0)
    norm = np.linalg.norm(cross, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = cross / norm[:, None]
    unit[norm <= 0.0] = 0.0                   # degenerate (a repeated corner): zero normal
    assert (norm == 0.0).sum() > 0
    a, n, c = triangle_geometry(v, f)
    assert np.array_equal(a, 0.5 * norm)
    assert np.array_equal(n, unit)
    assert np.array_equal(c, (p0 + p1 + p2) / 3.0)


def test_triangle_soup_and_out_arrays_give_the_indexed_values():
    """A triangle soup (faces None: triangle i is vertices 3i..3i+2) gives the values of the
    same triangles indexed by faces, bit for bit, also written into given arrays across
    several blocks; out arrays of the wrong size and a soup of 3k+1 vertices are refused."""
    import pytest

    import mitsuba_veg.meshes as meshes
    rng = np.random.default_rng(7)
    m = meshes._BLOCK + 1234                      # more than one block
    v = rng.normal(size=(3 * m, 3)).astype(np.float32)
    v[3:6] = v[3]                                 # a degenerate triangle
    ref = triangle_geometry(v, np.arange(3 * m).reshape(-1, 3))
    soup = triangle_geometry(v, None)
    out = (np.full(m + 10, -1.0)[5:5 + m], np.empty((m, 3)), np.empty((m, 3)))
    got = triangle_geometry(v, None, out=out)
    for r, s, g, o in zip(ref, soup, got, out):
        assert np.array_equal(r, s) and np.array_equal(r, g) and g is o
    assert soup[0][1] == 0.0 and np.all(soup[1][1] == 0.0)
    with pytest.raises(ValueError, match="out arrays"):
        triangle_geometry(v, None, out=(np.empty(m - 1), np.empty((m, 3)), np.empty((m, 3))))
    with pytest.raises(ValueError, match="soup"):
        triangle_geometry(v[:-2], None)


def test_blades_taken_out_by_nan_corners_are_out_of_the_ray_tracer():
    """The world's leaf mesh takes hidden blades out by NaN corners (Canopy._set_blades): a
    vertex update doing so gives the hits of a scene built with those vertices (same rays, same
    hit triangles and distances), and no ray meets a blade taken out; the mesh's box leaves
    them out."""
    import drjit as dr
    import mitsuba as mi

    from mitsuba_veg.meshes import make_mesh
    rng = np.random.default_rng(3)
    F = 50_000
    cent = rng.uniform(-5, 5, (F, 3)).astype(np.float32)
    tri = (cent[:, None, :] + rng.normal(0, 0.05, (F, 3, 3)).astype(np.float32)).reshape(-1, 3)
    keep = rng.random(F) < 0.5
    half = np.where(np.repeat(keep, 3)[:, None], tri, np.nan).astype(np.float32)
    ground = make_mesh("g", [[-6, -6, -6], [6, -6, -6], [6, -6, 6], [-6, -6, 6]],
                       [[0, 2, 1], [0, 3, 2]])

    def scene(v):
        leaves = make_mesh("leaves", v, dr.arange(mi.UInt32, 3 * F))
        return mi.load_dict({"type": "scene", "g": ground, "leaves": leaves}, optimize=False)
    updated = scene(tri)
    p = mi.traverse(updated)
    p["leaves.vertex_positions"] = mi.Float(half.ravel())
    p.update()
    fresh = scene(half)
    n = 200_000
    o = mi.Point3f(mi.Float(rng.uniform(-5, 5, n)), 7.0, mi.Float(rng.uniform(-5, 5, n)))
    d = mi.Vector3f(mi.Float(rng.normal(0, 0.3, n)), -1.0, mi.Float(rng.normal(0, 0.3, n)))
    ray = mi.Ray3f(o, dr.normalize(d))
    a, b = updated.ray_intersect_preliminary(ray), fresh.ray_intersect_preliminary(ray)
    va, vb = np.asarray(a.is_valid()), np.asarray(b.is_valid())
    assert np.array_equal(va, vb) and va.sum() > 0.5 * n       # (134,121)
    assert np.array_equal(np.asarray(a.t)[va], np.asarray(b.t)[va])
    assert np.array_equal(np.asarray(a.prim_index)[va], np.asarray(b.prim_index)[va])
    leaf = [s for s in updated.shapes() if s.id() == "leaves"][0]
    on_leaf = va & np.asarray(a.shape == mi.ShapePtr(leaf))
    prim = np.asarray(a.prim_index)
    assert on_leaf.sum() > 0.2 * n                       # the blades kept are hit (63,380)
    assert not np.any(on_leaf & ~keep[np.minimum(prim, F - 1)])
    box = leaf.bbox()
    assert np.all(np.isfinite([box.min[k] for k in range(3)] + [box.max[k] for k in range(3)]))
