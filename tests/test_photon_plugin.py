"""The veg_photon_irradiance plugin as Mitsuba users drive it: ``mi.render`` from a dict or XML,
instances, analytic shapes, and the overflow guard of the fixed-point accumulator."""
import math

import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers plugins)
import mitsuba as mi

from mitsuba_veg.errors import ParameterError, SceneError
from mitsuba_veg.integrators.photon_irradiance import fixed_point_scale, scene_index
from mitsuba_veg.light import photon_irradiance, BANDS
from mitsuba_veg.meshes import make_mesh
from mitsuba_veg.light import validation as V

NM_TOTAL = BANDS["total"][1] - BANDS["total"][0]
CAMERA = {"type": "perspective", "fov": 60,
          "to_world": mi.ScalarTransform4f().look_at([0, 3, 3], [0, 0, 0], [0, 1, 0]),
          "film": {"type": "hdrfilm", "width": 8, "height": 8}}


def test_mi_render_runs_the_pass_from_a_scene_dict():
    d = V.roof_wall_scene(n=4)
    d["integrator"] = {"type": "veg_photon_irradiance", "photons": 200_000, "seed": 5,
                       "max_depth": 6, "bands": "total,par,red,far_red"}
    d["camera"] = CAMERA
    scene = mi.load_dict(d, optimize=False)
    img = mi.render(scene)
    arr = np.asarray(img)
    res = photon_irradiance(scene, photons=200_000, seed=5, max_depth=6)
    # layout: element x band x component (direct, indirect) x side (front, back)
    assert arr.shape == (res.index.n_elements, 4, 2, 2)
    assert arr.max() > 0 and (arr[:, :, 1] > 0).any()
    np.testing.assert_array_equal(arr, res.tensor().astype(np.float32))
    sl = res.shape_slice("roof")
    np.testing.assert_allclose(arr[sl, 1, 1, 0], res.irradiance("roof", "par", "indirect"),
                               rtol=1e-6)
    # the plugin's own render() needs no sensor; mi.render's seed is added to the property's
    integ = scene.integrator()
    np.testing.assert_array_equal(np.asarray(integ.render(scene)), arr)
    assert integ.result.settings["seed"] == 5
    other = np.asarray(mi.render(scene, seed=1))
    np.testing.assert_array_equal(
        other, photon_irradiance(scene, photons=200_000, seed=6, max_depth=6).tensor()
        .astype(np.float32))
    # samples per pixel mean nothing to the element output: refused, the fix named (mi.render
    # wraps the plugin's error in its own; the plugin's is the cause)
    with pytest.raises(ParameterError, match=r"spp = 64 is invalid.*photons"):
        integ.render(scene, spp=64)
    with pytest.raises(Exception) as e:
        mi.render(scene, spp=64)
    causes = []
    c = e.value
    while c is not None:
        causes.append(c)
        c = c.__cause__ or c.__context__
    assert any(isinstance(c, ParameterError) and "spp = 64" in str(c) for c in causes)


XML = """<scene version="3.0.0">
    <integrator type="veg_photon_irradiance">
        <integer name="photons" value="100000"/>
        <integer name="max_depth" value="3"/>
        <integer name="seed" value="2"/>
        <boolean name="indirect" value="true"/>
        <string name="bands" value="par,500-510"/>
    </integrator>
    <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
        <integer name="height" value="4"/></film></sensor>
    <emitter type="directional" id="sun">
        <vector name="direction" x="0.2" y="-1" z="0.1"/>
        <spectrum name="irradiance" type="uniform"><float name="value" value="1"/></spectrum>
    </emitter>
    <shape type="rectangle" id="floor">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="2"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" type="uniform">
            <float name="value" value="0.5"/></spectrum></bsdf>
    </shape>
    <shape type="cube" id="box">
        <transform name="to_world"><scale value="0.3"/><translate y="0.3"/></transform>
    </shape>
</scene>"""


def test_mi_render_runs_the_pass_from_xml():
    scene = mi.load_string(XML, optimize=False)
    arr = np.asarray(mi.render(scene))
    res = photon_irradiance(scene, photons=100_000, seed=2, max_depth=3,
                            bands=("par", (500.0, 510.0)))
    np.testing.assert_array_equal(arr, res.tensor().astype(np.float32))
    assert arr.shape == (2 + 12, 2, 2, 2)  # rectangle and cube load as meshes
    assert res.single_element_shapes == {}
    # every sun photon over the 4 m x 4 m floor hits the floor or the box: E sin(e) x 16 m2
    e = math.asin(1 / math.sqrt(1.05))
    direct = sum(res.flux_of(s, "par", "direct").sum() for s in ("floor", "box"))
    assert direct == pytest.approx(300 * math.sin(e) * 16, rel=0.01)
    assert res.irradiance("box", (500.0, 510.0), "indirect").max() > 0


def test_plugin_properties_are_checked():
    with pytest.raises(Exception, match="bands"):
        mi.load_dict({"type": "veg_photon_irradiance", "bands": "par,ultraviolet_x"})
    with pytest.raises(Exception, match="output"):
        mi.load_dict({"type": "veg_photon_irradiance", "output": "picture"})
    with pytest.raises(ParameterError, match="photons"):
        photon_irradiance(mi.load_dict(V.roof_wall_scene(n=2)), photons=0)


def test_sphere_is_one_element_lit_by_its_cross_section():
    """An analytic sphere is one element (stated in the result); under a sun of irradiance E it
    intercepts E pi r^2 on its front, and shades the plane under it."""
    r = 0.3
    gv, gf = V.grid_mesh(8, 8)
    scene = mi.load_dict({
        "type": "scene", "ground": V.make_mesh("ground", gv, gf, 0.0),
        "ball": {"type": "sphere", "radius": r, "center": [0.0, 0.5, 0.0],
                 "bsdf": {"type": "diffuse",
                          "reflectance": {"type": "uniform", "value": 0.0}}},
        "sun": {"type": "directional", "direction": [0.0, -1.0, 0.0],
                "irradiance": {"type": "uniform", "value": 1.0}}}, optimize=False)
    res = photon_irradiance(scene, photons=1_000_000, seed=1, bands=("total",))
    assert res.single_element_shapes == {"ball": "Sphere"}
    assert res.irradiance("ball").shape == (1,)
    assert res.flux_of("ball").sum() == pytest.approx(NM_TOTAL * math.pi * r * r, rel=0.01)
    assert res.flux_of("ball", side="back").sum() == 0
    assert res.flux_of("ground").sum() == pytest.approx(NM_TOTAL * (4 - math.pi * r * r),
                                                        rel=0.01)


def test_fixed_point_cap_never_wraps():
    for photons in (1, 1024, 1 << 22, 1 << 26, 10**9):
        for hits in (1, 8, 1000):
            scale, cap = fixed_point_scale(photons, hits, 3.0e7)
            assert 0 < cap and int(cap) * photons * hits <= 2**64 - 1
            assert scale * 3.0e7 <= cap / 16 * (1 + 1e-12)


def test_huge_flux_and_many_hits_do_not_wrap():
    """A point light inside a closed white sphere (one element): every photon hits it
    ``max_depth`` times with its full power, so the recorded flux is emitted x max_depth. With
    2^15 photons x 1000 hits in one batch, the former 2^40-per-photon scale would have summed
    past 2^64; a huge emitter power changes nothing."""
    for intensity in (1.0, 1e20):
        scene = mi.load_dict({
            "type": "scene",
            "shell": {"type": "sphere", "radius": 1.0, "bsdf": {"type": "diffuse"}},
            "lamp": {"type": "point", "position": [0.0, 0.1, 0.0],
                     "intensity": {"type": "uniform", "value": intensity}}}, optimize=False)
        integ = mi.load_dict({"type": "veg_photon_irradiance", "photons": 1 << 15,
                              "max_depth": 1000, "bands": "total", "batch": 1 << 15})
        res = integ.trace(scene, reflectance={"shell": np.ones(1)})
        emitted = res.emitted.sum()
        assert emitted == pytest.approx(4 * math.pi * intensity * NM_TOTAL, rel=1e-3)
        assert res.flux_of("shell", side="both").sum() == pytest.approx(1000 * emitted,
                                                                        rel=1e-4)
        # every photon is still travelling after its 1000 hits, but for the few (0-4 of
        # 32,768 at seeds 0-2) that leak through the sphere by float rounding of a spawned
        # ray: the bookkeeping closes exactly, and no sum wrapped
        assert res.truncated.sum() + res.escaped.sum() == pytest.approx(emitted, rel=1e-6)
        assert res.escaped.sum() < 2e-4 * emitted


@pytest.fixture(scope="module")
def plants():
    inst = mi.load_dict(V.plant_scene(1000, instanced=True), optimize=False)
    plain = mi.load_dict(V.plant_scene(1000, instanced=False), optimize=False)
    kw = dict(photons=1_000_000, seed=3, max_depth=100, bands=("total", "par"))
    return photon_irradiance(inst, **kw), photon_irradiance(plain, **kw)


def test_thousand_instanced_plants_per_instance_and_triangle(plants):
    res, _ = plants
    assert len(res.instances) == 1000
    assert set(res.instances.values()) == {"plant0", "plant1", "plant2"}
    # plant k: 4 + k leaf quads (8 + 2k triangles) and a 12-triangle stem
    assert res.irradiance("p0004").shape == (8 + 2 + 12,)
    assert res.irradiance("p0004/leaves1").shape == (10,)
    assert res.irradiance("p0004/stem1").shape == (12,)
    assert res.index.n_elements == 800 + sum(8 + 2 * (i % 3) + 12 for i in range(1000))
    # energy: emitted = absorbed + escaped (+ still travelling at max_depth), and absorption
    # re-estimated from the recorded flux: (1 - albedo) of the front-face flux and all of the
    # back-face flux (Mitsuba's one-sided ``diffuse`` absorbs what hits its back)
    for b in range(2):
        emitted, escaped = res.emitted[:, b].sum(), res.escaped[:, b].sum()
        assert res.absorbed[:, b].sum() + escaped + res.truncated[:, b].sum() == \
            pytest.approx(emitted, rel=1e-4)
        band = res.bands[b]

        def absorbed_by(sid, albedo):
            return ((1 - albedo) * res.flux_of(sid, band, side="front").sum()
                    + res.flux_of(sid, band, side="back").sum())
        absorbed, back = absorbed_by("ground", 0.2), 0.0
        for i in range(1000):
            k = i % 3
            absorbed += absorbed_by(f"p{i:04d}/leaves{k}", 0.4)
            absorbed += absorbed_by(f"p{i:04d}/stem{k}", 0.1)
            back += res.flux_of(f"p{i:04d}/leaves{k}", band, side="back").sum()
        assert back > 0.05 * emitted     # the leaves' backs are lit: the test can tell
        assert absorbed + escaped == pytest.approx(emitted, rel=0.005)


def test_npz_has_every_instances_mean_irradiance(plants, tmp_path):
    """Past 100 instances the npz has no per-instance per-triangle keys, but one value per
    instance for all of them (area-weighted mean front irradiance) besides the element rows."""
    res, _ = plants
    res.to_npz(tmp_path / "r.npz")
    data = np.load(tmp_path / "r.npz")
    ids = list(data["instances/ids"])
    assert len(ids) == 1000 and "p0517/total/total" not in data
    for i in (0, 517, 999):
        sid = f"p{i:04d}"
        a = res.index.areas[res.shape_slice(sid)]
        assert data["instances/area_m2"][i] == pytest.approx(a.sum(), rel=1e-12)
        for b, c in (("total", "total"), ("par", "indirect")):
            mean = (res.irradiance(sid, b, c) * a).sum() / a.sum()
            assert data[f"instances/{b}/{c}"][i] == pytest.approx(mean, rel=1e-9)
        sl = slice(data["instances/first_element"][i],
                   data["instances/first_element"][i] + data["instances/element_count"][i])
        np.testing.assert_allclose(data["elements/total/total"][sl],
                                   res.irradiance(sid, "total", "total"), rtol=1e-12)


def test_instances_agree_with_the_same_plants_as_plain_meshes(plants):
    inst, plain = plants
    assert inst.rays_traced == pytest.approx(plain.rays_traced, rel=1e-3)
    for i in (0, 1, 2, 517, 999):
        for part in ("leaves", "stem"):
            a = inst.irradiance(f"p{i:04d}/{part}{i % 3}", "total", side="both")
            b = plain.irradiance(f"p{i:04d}_{part}", "total", side="both")
            np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-3 * b.max())
    ids = [f"p{i:04d}" for i in range(1000)]
    fi = np.array([inst.flux_of(p, side="both").sum() for p in ids])
    fp = np.array([plain.flux_of(f"{p}_leaves", side="both").sum()
                   + plain.flux_of(f"{p}_stem", side="both").sum() for p in ids])
    # same random numbers, same paths, up to the few that float rounding in the instance
    # transforms sends elsewhere
    rel = np.abs(fi / fp - 1)
    assert np.median(rel) < 1e-5 and np.mean(rel < 1e-3) > 0.98 and rel.max() < 0.03
    assert fi.sum() == pytest.approx(fp.sum(), rel=1e-3)
    assert inst.flux_of("ground").sum() == pytest.approx(plain.flux_of("ground").sum(),
                                                         rel=1e-4)


def _tilted_quad_scene(instanced: bool) -> mi.Scene:
    """A 1 m quad (albedo 0.8) 0.5 m up whose vertex normals lean 60 deg towards +x, between
    two black walls at x = +-1.5 m, under a sun from straight above: with the shading normal
    the quad reflects towards the east wall only, about its triangles' normal to both."""
    qv = np.array([[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5]], float)
    qf = np.array([[0, 2, 1], [0, 3, 2]])
    qn = np.tile([np.sin(np.radians(60)), np.cos(np.radians(60)), 0.0], (4, 1))
    wv = np.array([[0, 0, -1], [0, 2, -1], [0, 2, 1], [0, 0, 1]], float)
    d = {"type": "scene",
         "east": make_mesh("east", wv + [1.5, 0, 0], [[0, 1, 2], [0, 2, 3]], 0.0),
         "west": make_mesh("west", wv - [1.5, 0, 0], [[0, 2, 1], [0, 3, 2]], 0.0),
         "sun": {"type": "directional", "direction": [0, -1, 0],
                 "irradiance": {"type": "uniform", "value": 1.0}}}
    if instanced:
        d["g"] = {"type": "shapegroup", "quad": make_mesh("quad", qv, qf, 0.8, normals=qn)}
        d["q1"] = {"type": "instance", "id": "q1", "shapegroup": {"type": "ref", "id": "g"},
                   "to_world": mi.ScalarTransform4f().translate([0, 0.5, 0])}
    else:
        d["quad"] = make_mesh("quad", qv + [0, 0.5, 0], qf, 0.8, normals=qn)
    return mi.load_dict(d, optimize=False)


def test_instanced_meshes_with_vertex_normals_shade_as_mitsuba():
    """Vertex normals shade instanced meshes as Mitsuba does (the kernel interpolates them
    from a table instead of Mitsuba's surface interaction, a virtual call over every
    instance): the same reflected light on the walls as the plain mesh, which Mitsuba's own
    interaction shades; without the tables the quad reflects about its triangles (both walls
    alike)."""
    kw = dict(photons=1_000_000, seed=1, max_depth=8, bands=("total",))
    inst_s = _tilted_quad_scene(True)
    inst = photon_irradiance(inst_s, **kw)
    plain = photon_irradiance(_tilted_quad_scene(False), **kw)
    assert inst.index.vn_table is not None and plain.index.vn_table is None
    east = [r.flux_of("east", side="both").sum() for r in (inst, plain)]
    assert east[0] == pytest.approx(east[1], rel=0.02)
    for r in (inst, plain):
        assert r.flux_of("west", side="both").sum() == 0.0
    idx = scene_index(inst_s)   # the pass reads the scene's cached index: drop its tables
    idx.vn_table, idx.vn_base, idx.vn_matrix = None, None, None
    flat = photon_irradiance(inst_s, **kw)
    e_f, w_f = flat.flux_of("east", side="both").sum(), flat.flux_of("west", side="both").sum()
    assert e_f == pytest.approx(w_f, rel=0.1) and east[0] > 3 * e_f


def test_emitters_without_ids_are_named_by_class_and_place():
    """Hand-written XML (and Mitsuba's XML writer) leaves emitters without ids: results name
    them by Mitsuba class and place in ``scene.emitters()``, an id where there is one."""
    xml = """<scene version="3.0.0">
        <emitter type="directional"><vector name="direction" value="0, -1, 0"/></emitter>
        <emitter type="constant"><rgb name="radiance" value="0.1"/></emitter>
        <emitter type="point" id="lamp"><point name="position" value="0, 1, 0"/></emitter>
    </scene>"""
    scene = mi.load_string(xml.replace("</scene>", "") + """
        <shape type="rectangle" id="ground"><transform name="to_world">
            <rotate x="1" angle="-90"/></transform></shape></scene>""")
    assert [e.id() for e in scene.emitters()] == ["", "", "lamp"]
    res = photon_irradiance(scene, photons=20_000)
    assert list(res.emitters) == ["DirectionalEmitter_0", "ConstantBackgroundEmitter_1", "lamp"]
    assert res.flux_of("ground", emitter="DirectionalEmitter_0").sum() > 0


def test_unresolvable_instances_are_refused_by_name():
    gv, gf = V.grid_mesh(1, 1, x=(-0.1, 0.1), z=(-0.1, 0.1))
    base = {"type": "scene", "sun": {"type": "directional", "direction": [0, -1, 0]}}
    ball = dict(base, grp={"type": "shapegroup", "ball": {"type": "sphere", "radius": 0.1}},
                i1={"type": "instance", "shapegroup": {"type": "ref", "id": "grp"}})
    with pytest.raises(SceneError, match="'ball'.*shapegroup 'grp'"):
        photon_irradiance(mi.load_dict(ball, optimize=False), photons=1000)
    twins = dict(base, g1={"type": "shapegroup", "a": V.make_mesh("a", gv, gf, 0.5)},
                 g2={"type": "shapegroup", "b": V.make_mesh("b", gv, gf[:, ::-1], 0.5)},
                 i1={"type": "instance", "shapegroup": {"type": "ref", "id": "g1"}},
                 i2={"type": "instance", "shapegroup": {"type": "ref", "id": "g2"}})
    with pytest.raises(SceneError, match="instance 'i1'"):
        photon_irradiance(mi.load_dict(twins, optimize=False), photons=1000)
