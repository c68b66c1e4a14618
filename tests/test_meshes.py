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
