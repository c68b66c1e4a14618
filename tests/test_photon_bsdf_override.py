"""Per-triangle BSDF choice of the photon pass (``trace(..., bsdf_override=...)``).

A triangle given a BSDF by the table must scatter exactly as if the shape had that BSDF, -1
must keep the shape's own, and a new table (a leaf's new autumn stage) must not recompile the
kernel."""
import math

import drjit as dr
import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers plugins)
import mitsuba as mi

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.foliage import leaf_bsdf_dict
from mitsuba_veg.light import BANDS
from mitsuba_veg.light import validation as V
from mitsuba_veg.light.photon import integrator

NM = BANDS["total"][1] - BANDS["total"][0]
ELEV = 50.0


def _leaf(r, t):
    return mi.load_dict(leaf_bsdf_dict(reflectance=r, transmittance=t))


def _scene(panel_bsdf=None):
    gv, gf = V.grid_mesh(4, 4, x=(-2.0, 2.0), z=(-2.0, 2.0))
    sv, sf = V.grid_mesh(2, 2, x=(-0.5, 0.5), z=(-0.5, 0.5), y=0.5)
    sun = V.sun_vector(ELEV)
    panel = V.make_mesh("panel", sv, sf, 0.0)
    if panel_bsdf is not None:
        panel = V.make_mesh("panel", sv, sf, bsdf=panel_bsdf)
    return mi.load_dict({
        "type": "scene", "ground": V.make_mesh("ground", gv, gf, 0.2), "panel": panel,
        "sun": {"type": "directional", "direction": (-sun).tolist(),
                "irradiance": {"type": "uniform", "value": 1.0}}}, optimize=False)


def _trace(scene, **kw):
    return integrator(photons=200_000, seed=3, bands=("total", "red")).trace(scene, **kw)


def test_override_scatters_as_the_shapes_own_bsdf_would():
    """A black panel given a transmitting leaf BSDF by the table lights the ground as a panel
    built with that BSDF does (same seed); -1 keeps the panel's own (black) BSDF."""
    leaf, other = _leaf(0.1, 0.6), _leaf(0.3, 0.3)
    n = 8                                                     # panel triangles
    plain = _scene()
    native = _trace(_scene(leaf))
    over = _trace(plain, bsdf_override={"panel": ([other, leaf], np.ones(n, int))})
    own = _trace(plain, bsdf_override={"panel": ([other, leaf], np.full(n, -1))})
    black = _trace(plain)
    g = lambda r, c="total": r.flux_of("ground", component=c).sum()  # noqa: E731  [W]
    np.testing.assert_allclose(over.flux_of("ground", component="indirect"),
                               native.flux_of("ground", component="indirect"), rtol=1e-5)
    np.testing.assert_allclose(over.absorbed, native.absorbed, rtol=1e-5)
    assert np.array_equal(own.flux, black.flux)
    # light through the panel: the ground gets indirect light from it (transmittance 0.6 of
    # the panel's ~1/16 share of the sun) that the black panel does not give
    e = NM * math.sin(math.radians(ELEV))
    assert g(over, "indirect") - g(black, "indirect") > 0.6 * 0.7 * e * 1.0 * 0.5
    for r in (over, own, black):
        left = r.escaped.sum() + r.absorbed.sum() + r.truncated.sum()
        assert abs(left / r.emitted.sum() - 1) < 1e-4


def test_per_triangle_choice():
    """Half the panel reflects (R 0.8), half is black: only the reflective half sends light
    back up (its triangles absorb less)."""
    plain = _scene()
    n = 8
    choice = np.where(np.arange(n) < 4, 0, -1)
    r = _trace(plain, bsdf_override={"panel": ([_leaf(0.8, 0.0)], choice)})
    a = r.absorbed.sum()
    black = _trace(plain)
    full = _trace(plain, bsdf_override={"panel": ([_leaf(0.8, 0.0)], np.zeros(n, int))})
    assert a < black.absorbed.sum()
    # the escaped power is the reflective half's 0.8 x its direct flux, plus the ground's light
    # that its underside sends back down and up again (a few %): half of the whole panel's
    panel_direct = r.flux_of("panel", component="direct")
    assert panel_direct[:4].sum() == pytest.approx(panel_direct[4:].sum(), rel=0.02)
    up = r.escaped.sum() - black.escaped.sum()
    assert 0.8 * panel_direct[:4].sum() < up < 1.1 * 0.8 * panel_direct[:4].sum()
    assert up == pytest.approx(0.5 * (full.escaped.sum() - black.escaped.sum()), rel=0.03)


def test_a_new_table_does_not_recompile():
    """Days 2..N of a world change the table only: every kernel of the pass comes from the
    in-memory kernel cache (Dr.Jit's kernel history), as for the same table again."""
    plain = _scene()
    bsdfs = [_leaf(0.1, 0.6), _leaf(0.4, 0.4), _leaf(0.05, 0.02)]
    rng = np.random.default_rng(0)
    n = 8

    def hits(choice):
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
            _trace(plain, bsdf_override={"panel": (bsdfs, choice)},
                   modes={"panel": np.where(choice == 2, 2, 0)})
            hist = dr.kernel_history([dr.KernelType.JIT])
        return [h["cache_hit"] for h in hist]

    hits(rng.integers(0, 3, n))                               # compiles (or loads) once
    again = hits(rng.integers(0, 3, n))
    other = hits(rng.integers(0, 3, n))
    assert again and all(again)
    assert other and all(other)


def test_refusals():
    plain = _scene()
    leaf = _leaf(0.1, 0.5)
    for bad in ({"panel": ([leaf], np.zeros(3, int))},          # wrong length
                {"panel": ([leaf], np.full(8, 1))},             # index out of range
                {"panel": ([leaf], np.full(8, 0.5))},           # not integers
                {"panel": (["veg_leaf"], np.zeros(8, int))},    # not a BSDF object
                {"panel": leaf}):                                # not a pair
        with pytest.raises(ParameterError, match="bsdf_override"):
            _trace(plain, bsdf_override=bad)
