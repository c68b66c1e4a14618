"""Hemispherical photographs: the fisheye sensor's map, gap fractions against analytic canopies,
the LAI formulas against hand values and a Poisson canopy, site factors, the true area index
in a view cone, the photon pass's shares against the photograph (docs/hemiphoto.md)."""
import datetime as dt
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (variant, plugins)
from mitsuba_veg.light import gap_fraction as G
from mitsuba_veg.light.fisheye import Lens, gap_image, sensor_dict
from mitsuba_veg.meshes import make_mesh
from mitsuba_veg.world.visible_canopy import LeafState, VisibleCanopy
from mitsuba_veg.world.trees import WorldTree


def _disc_scene(theta_d_deg=30.0, radius=1.0):
    """An opaque disc centred above the lens at the origin, seen under theta_d from it."""
    h = radius / math.tan(math.radians(theta_d_deg))
    return mi.load_dict({"type": "scene", "disc": {
        "type": "disk", "to_world": mi.ScalarTransform4f().translate([0, h, 0])
        .rotate([1, 0, 0], 90).scale(radius)}})


def _c(deg):
    return math.cos(math.radians(deg))


@pytest.mark.parametrize("projection", ["equidistant", "equisolid"])
@pytest.mark.parametrize("fov", [180.0, 150.0])
def test_the_sensor_and_the_pixel_map_are_one_projection(projection, fov):
    """Every pixel centre's ray of the plugin (what a render traces) has the zenith angle and
    azimuth of the NumPy map (north at the top, east on the left); the pixels' solid angles
    add up to the field of view's; a direction maps back to its pixel."""
    lens = Lens(64, projection, fov)
    s = mi.load_dict(sensor_dict([0.0, 0.0, 0.0], lens))
    n = lens.size
    idx = dr.arange(mi.UInt32, n * n)
    d, valid = s.direction_at(mi.Point2f(mi.Float(idx % n) + 0.5, mi.Float(idx // n) + 0.5))
    d = np.array(d).reshape(3, n, n).transpose(1, 2, 0)
    m = lens.pixel_map()
    th, az, ins = m["theta"], m["azimuth"], m["inside"]
    e = np.stack([np.sin(th) * np.sin(az), np.cos(th), -np.sin(th) * np.cos(az)], -1)
    assert np.array_equal(np.array(valid).reshape(n, n), ins)
    assert np.abs(d[ins] - e[ins]).max() < 1e-6
    assert m["solid_angle"].sum() == pytest.approx(2 * math.pi * (1 - _c(fov / 2)), rel=5e-3)
    r, c = lens.pixel_of(th[ins], az[ins])
    rr, cc = np.nonzero(ins)
    assert np.array_equal(r, rr) and np.array_equal(c, cc)
    # north (-z) at the top, east (+x) on the left
    assert e[1, n // 2, 2] < -0.9 and e[n // 2, 1, 0] > 0.9


def test_the_sensor_renders_with_the_path_integrator_and_the_spectral_film():
    """A Python mi.Sensor in Mitsuba's path integrator with the package's specfilm: a black disc
    under a uniform sky is black inside 30 degrees, the sky is 1 (its radiance) outside, the
    corners outside the image disc are 0 and nothing is NaN."""
    from types import SimpleNamespace
    from mitsuba_veg.render.film import develop, film_dict
    lens = Lens(48)
    d = {"type": "scene", "integrator": {"type": "path"},
         "sky": {"type": "constant", "radiance": {"type": "uniform", "value": 1.0}},
         "camera": sensor_dict([0, 0, 0], lens,
                               film=film_dict(SimpleNamespace(width=48, height=48)), spp=4)}
    h = 1.0 / math.tan(math.radians(30.0))
    d["disc"] = {"type": "disk", "to_world": mi.ScalarTransform4f().translate([0, h, 0])
                 .rotate([1, 0, 0], 90), "bsdf": {"type": "diffuse", "reflectance": {
                     "type": "uniform", "value": 0.0}}}
    y = develop(np.asarray(mi.render(mi.load_dict(d), spp=8)))["XYZ"][..., 1]
    m = lens.pixel_map()
    deg = np.degrees(m["theta"])
    assert np.isfinite(y).all()
    assert np.abs(y[m["inside"] & (deg < 18)]).max() < 1e-6       # (the film's 2-px filter)
    assert np.median(y[m["inside"] & (deg > 45) & (deg < 80)]) == pytest.approx(1.0, rel=0.02)
    assert y[0, 0] == 0.0


@pytest.mark.parametrize("projection", ["equidistant", "equisolid"])
def test_gap_fraction_openness_and_site_factor_of_a_disc(projection):
    """One opaque disc above the lens, seen under 30 degrees: the solid-angle gap fraction of a
    ring straddling its edge is (cos 30 - cos hi) / (cos lo - cos hi) within 0.01, rings inside
    and outside are 0 and 1 exactly; openness = cos 30; the uniform sky's diffuse site factor
    = 1 - sin^2 30 and the standard overcast sky's its own integral."""
    img = gap_image(_disc_scene(30.0), [0, 0, 0], Lens(1024, projection))
    m = img.pixel_map()
    rings = [(20.0, 40.0), (25.0, 35.0), (0.0, 13.0), (16.0, 28.0), (32.0, 43.0)]
    f, _ = G.ring_gap_fractions(img.gap, m["theta"], m["solid_angle"], rings)
    f = f[:, 0]
    assert f[0] == pytest.approx((_c(30) - _c(40)) / (_c(20) - _c(40)), abs=0.01)
    assert f[1] == pytest.approx((_c(30) - _c(35)) / (_c(25) - _c(35)), abs=0.01)
    assert f[2] == 0.0 and f[3] == 0.0 and f[4] == 1.0
    assert G.openness(img.gap, m["solid_angle"]) == pytest.approx(_c(30), abs=0.002)
    assert G.diffuse_site_factor(img.gap, m["theta"], m["solid_angle"]) == \
        pytest.approx(1 - math.sin(math.radians(30)) ** 2, abs=0.002)
    # SOC: L ∝ 1 + 2 cos θ; open share = ∫_30^90 (1+2c) c s dθ / ∫_0^90 (1+2c) c s dθ
    soc = (0.5 * _c(30) ** 2 + 2 / 3 * _c(30) ** 3) / (0.5 + 2 / 3)
    assert G.diffuse_site_factor(img.gap, m["theta"], m["solid_angle"], "soc") == \
        pytest.approx(soc, abs=0.002)


def test_lai2000_formula_against_hand_values():
    """L_e = 2 sum W_i (-ln P_i) / S_i with the published W and S: all rings at P = e^-1 give
    2 sum W_i/S_i = 1.13566 (by hand: 2 (0.034/1.008 + 0.104/1.087 + 0.160/1.270 + 0.218/1.662
    + 0.484/2.670)); a Poisson canopy of spherical leaves (G = 1/2) at the ring centres,
    P_i = exp(-L/(2 cos θ_i)), returns L to the published S's rounding; Miller on contiguous
    thin rings returns L for horizontal leaves over the whole hemisphere."""
    v, sat = G.lai2000_lai([math.exp(-1.0)] * 5)
    assert v == pytest.approx(1.13566, abs=2e-5) and sat == 0
    for L in (0.5, 2.0, 5.0):
        p = [math.exp(-0.5 * L / math.cos(math.radians(t))) for t in G.LAI2000_CENTRES]
        assert G.lai2000_lai(p)[0] == pytest.approx(L, rel=2e-3)
        rings = G.rings_of_width(0.5, 90.0)
        assert G.miller_lai([math.exp(-L)] * len(rings), rings)[0] == pytest.approx(L, rel=1e-3)
    # a ring without a gap: half its smallest pixel, counted
    v0, sat = G.lai2000_lai([0.0, 0.5, 0.5, 0.5, 0.5], smallest=[1e-3, 0, 0, 0, 0])
    assert sat == 1 and v0 > G.lai2000_lai([0.5] * 5)[0]


def test_lang_xiang_is_jensens_correction():
    """Equal sectors: L_LX = L_e; sectors of unequal gaps (a clumped canopy): L_LX > L_e by the
    mean of the logarithms, by hand."""
    eq = np.full((5, 8), 0.3)
    small = np.full((5, 8), 1e-4)
    le = G.lai2000_lai(np.full(5, 0.3))[0]
    assert G.lang_xiang_lai(eq, small)[0] == pytest.approx(le, rel=1e-12)
    uneq = np.tile(np.array([0.05, 0.55] * 4), (5, 1))          # mean 0.3 in every ring
    lx, _ = G.lang_xiang_lai(uneq, small)
    hand = 2 * sum(w / s * -(math.log(0.05) + math.log(0.55)) / 2
                   for w, s in zip(G.LAI2000_WEIGHTS, G.LAI2000_PATHS))
    assert lx == pytest.approx(hand, rel=1e-12) and lx > 1.2 * le


def _poisson_leaves(lai, half, y0, y1, side, seed):
    """Square opaque leaves of side ``side``, centres uniform in a slab, normals uniform on the
    sphere (G = 1/2): a Poisson (Boolean) canopy of known LAI."""
    rng = np.random.default_rng(seed)
    n = int(round(lai * (2 * half) ** 2 / side ** 2))
    c = np.column_stack([rng.uniform(-half, half, n), rng.uniform(y0, y1, n),
                         rng.uniform(-half, half, n)])
    nr = rng.normal(size=(n, 3))
    nr /= np.linalg.norm(nr, axis=1, keepdims=True)
    a = np.where(np.abs(nr[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 0, 1.0]])
    t = np.cross(nr, a)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(nr, t)
    ang = rng.uniform(0, 2 * np.pi, n)[:, None]
    u = (np.cos(ang) * t + np.sin(ang) * b) * side / 2
    v = (-np.sin(ang) * t + np.cos(ang) * b) * side / 2
    q = np.stack([c - u - v, c + u - v, c + u + v, c - u + v], 1)
    return q, n * side * side / (2 * half) ** 2


def test_effective_lai_of_a_poisson_canopy_within_10_percent():
    """Small opaque leaves of spherical orientation placed at random in a slab 1-2 m above the
    lens, 15 m wide (3.75x its top's height each way: the 74-degree ring sees 7 m out): the
    LAI-2000 formula and Miller's integral return the true LAI within 10 % (measured for L = 3:
    2.95 and 3.03; seeds 1 and 2: 2.92 / 2.96 and 2.91 / 2.98), and Lang & Xiang's clumping
    index is 1 within 3 % (measured 0.993: no clumping)."""
    q, lai = _poisson_leaves(3.0, 7.5, 1.0, 2.0, 0.1, seed=0)
    f = np.arange(len(q))[:, None, None] * 4 + np.array([[0, 1, 2], [0, 2, 3]])[None]
    scene = mi.load_dict({"type": "scene", "leaves": make_mesh("leaves", q.reshape(-1, 3),
                                                               f.reshape(-1, 3))})
    a = G.analyse(gap_image(scene, [0, 0, 0], Lens(1024)))
    assert lai == pytest.approx(3.0, rel=1e-3)
    assert a.values["lai_lai2000"] == pytest.approx(lai, rel=0.10)
    assert a.values["lai_miller"] == pytest.approx(lai, rel=0.10)
    assert a.values["clumping_index"] == pytest.approx(1.0, abs=0.03)
    # the cone truth of the same leaves (each leaf's area over the cone's section at its
    # height): the canopy's LAI within its sampling noise
    wt = WorldTree("slab", "mesh", np.zeros(3), (np.zeros((0, 3)), np.zeros((0, 3), int)), q,
                   np.full(len(q), 0.01))
    vc = VisibleCanopy([wt])
    t = vc.cone_area_index([0, 0, 0], LeafState.green(len(q)), 74.0)
    assert t["lai_true"] == pytest.approx(lai, rel=0.05)
    # dividing the cone's leaf area by the section at its leaves' mean height understates it:
    # (∫h²)³ / ((∫h³)² (h2 - h1)) = (7/3)³ / (15/4)² = 0.903 for leaves from 1 to 2 m
    assert t["lai_mean_height"] / t["lai_true"] == pytest.approx((7 / 3) ** 3 / 3.75 ** 2,
                                                                 rel=0.02)


def test_direct_site_factor_of_a_disc_against_the_sun_positions():
    """The direct site factor over sun positions: 1 in the open, the beam share of the suns
    outside the disc's 30 degrees under it, by the weights directly."""
    lens = Lens(512)
    open_ = gap_image(mi.load_dict({"type": "scene"}), [0, 0, 0], lens)
    disc = gap_image(_disc_scene(30.0), [0, 0, 0], lens)
    az, el, w, beam, diffuse = G.year_sun(35.0, 139.0, 2026, step_minutes=30.0)
    assert beam > 0 and diffuse > 0
    assert G.direct_site_factor(open_.gap, lens, az, el, w) == 1.0
    se = np.sin(np.radians(el))
    expect = np.sum(w * se * (el < 59.7)) / np.sum(w * se)
    got = G.direct_site_factor(disc.gap, lens, az, el, w)
    assert got == pytest.approx(expect, abs=0.01) and 0.2 < got < 0.9
    assert G.total_site_factor(got, 0.75, beam, diffuse) == \
        pytest.approx((got * beam + 0.75 * diffuse) / (beam + diffuse))


def _tree_with_leaves(q, area, bark=None):
    bark = bark or (np.zeros((0, 3)), np.zeros((0, 3), int))
    return WorldTree("t", "mesh", np.zeros(3), bark, q, np.asarray(area, float))


def test_visible_canopy_shows_the_days_leaves_at_their_size():
    """Leaves not out, fallen, or with a blade that rounds to 0 are not in the camera's meshes;
    a half-grown blade is half the size about its centre; the stage bin picks the mesh."""
    q = np.array([[[x - .1, 1, -.1], [x + .1, 1, -.1], [x + .1, 1, .1], [x - .1, 1, .1]]
                  for x in range(5)], float)
    vc = VisibleCanopy([_tree_with_leaves(q, np.full(5, 0.04))], bins=2)
    st = LeafState(np.array([0, 0, 0, 0.9, 0]), np.array([1, 0.5, 1, 1, 0.04]),
                   np.array([True, True, False, True, True]))
    shown, scale, b = vc.blades(st)
    assert shown.tolist() == [True, True, False, True, False]
    assert scale.tolist() == [1.0, 0.5, 0.0, 1.0, 0.0] and b.tolist() == [0, 0, 0, 1, 0]
    sh = vc.shapes(st, optics=False)
    assert sorted(sh) == ["trees_leaves_0", "trees_leaves_1"]
    v = np.array(mi.traverse(sh["trees_leaves_0"])["vertex_positions"]).reshape(-1, 3)
    assert len(v) == 12                                           # two leaves, 2 triangles
    assert np.ptp(v[6:, 0]) == pytest.approx(0.1, abs=1e-6)       # the half-size blade
    # lens 0.5 m below the leaves at x = 2: the 74-degree cone's section there has a radius
    # of 1.74 m: leaves 1 (half-grown: a quarter of its area) and 3
    t = vc.cone_area_index([2.0, 0.5, 0.0], st, 74.0)
    assert t["leaves"] == 2
    tan2 = math.tan(math.radians(74.0)) ** 2
    assert t["lai_true"] == pytest.approx((0.01 + 0.04) / (math.pi * 0.25 * tan2), rel=1e-9)
    with pytest.raises(mv.errors.ParameterError, match="leaf state"):
        vc.blades(LeafState.green(4))


def test_photon_pass_direct_sky_share_equals_the_photographs_site_factor():
    """Under the disc (opaque, black) the pass's unscattered sky light at a small sensor is the
    photograph's diffuse site factor, 0.75, within 3 standard errors (measured 0.738 +- 0.024),
    the open sensor reads 1, and a grey disc adds scattered light the photograph does not
    see."""
    from mitsuba_veg.canopy_photo.light_truth import light_truth

    class Flat:            # the canopy interface light_truth uses, around fixed shapes
        def __init__(self, shapes):
            self.sh = shapes

        def scene(self, base, state, optics=True, emitters=None, extra=None):
            d = {"type": "scene", **{s.id(): s for s in base}, **self.sh,
                 **(emitters or {}), **(extra or {})}
            return mi.load_dict(d, optimize=False)

    h = 1.0 / math.tan(math.radians(30.0))
    disc = np.array([[math.cos(a), h + 1.0, math.sin(a)]
                     for a in np.linspace(0, 2 * np.pi, 64, endpoint=False)])
    v = np.vstack([[0.0, h + 1.0, 0.0], disc])
    f = np.array([[0, 1 + (k + 1) % 64, 1 + k] for k in range(64)])
    ground = make_mesh("ground", [[-3, 0, -3], [3, 0, -3], [3, 0, 3], [-3, 0, 3]],
                       [[0, 2, 1], [0, 3, 2]], albedo=0.2)
    res = {}
    for albedo in (0.0, 0.5):
        can = Flat({"disc": make_mesh("disc", v, f, {"type": "twosided", "bsdf": {
            "type": "diffuse", "reflectance": {"type": "uniform", "value": albedo}}})})
        res[albedo] = light_truth(can, [ground], None, [[0.0, 1.0, 0.0]], dt.date(2026, 7, 1),
                                  35.0, 139.0, photons=2_000_000, sun_photons=0, size=0.3)[0]
    r = res[0.0]
    assert r["sky_direct_share"] == pytest.approx(0.75, abs=max(3 * r["sky_direct_share_se"],
                                                               0.02))
    assert r["open_sky_share"] == pytest.approx(1.0, abs=0.08)
    assert r["sky_scattered_share"] < 0.02
    # the grey disc's underside, lit by the ground (albedo 0.2), adds about 0.5 x 0.2 x 0.75
    # x 0.25 = 0.02 of the open's sky light (measured 0.016)
    assert res[0.5]["sky_scattered_share"] > max(0.008, 3 * r["sky_scattered_share"])
