"""The assembled render scene: tiny renders (64x48, a few spp) of the moss garden with moss and
a tree, film calibration against a flat environment, in-place updates, the CLI functions."""
import json
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
import mitsuba as mi
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.render import (MossSet, RenderOptions, Terrain, build_scene, develop, render,
                                simple_tree)
from mitsuba_veg.render.film import film_dict
from mitsuba_veg.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SPECIES = ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"]


@pytest.fixture(scope="module")
def scn():
    s = load_scenario(SCENARIO)
    s.data.setdefault("render", {})["cameras"] = {
        # looking straight down on a patch of the back floor, under the roof
        "patch": {"origin": [0.0, 0.55, -0.62], "target": [0.0, 0.0, -0.621], "fov": 30,
                  "up": [0, 0, -1]}}
    return s


@pytest.fixture(scope="module")
def terrain(scn):
    return Terrain.from_scenario(scn)


def carpet(n_side=30, x0=-0.15, z0=-0.77):
    """A dense moss carpet (1 cm grid) on the back floor (y ~ 0 there)."""
    g = np.arange(n_side) * 0.01
    X, Z = np.meshgrid(x0 + g, z0 + g)
    n = X.size
    pos = np.c_[X.ravel(), np.zeros(n), Z.ravel()]
    return MossSet(pos, np.tile([0.0, 1.0, 0.0], (n, 1)), np.arange(n) % 3, np.full(n, 12.0),
                   SPECIES)


def test_flat_environment_calibrates_the_film():
    """A camera inside a uniform environment of 1 W m-2 sr-1 nm-1 reads Y = 1, band means 1 and
    the photon R:FR of a flat spectrum (660/730)."""
    o = RenderOptions(width=16, height=12, spp=16)
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
         "env": {"type": "constant", "radiance": {"type": "uniform", "value": 1.0}},
         "cam": {"type": "perspective", "fov": 40, "sampler": {"type": "independent",
                                                               "sample_count": 16},
                 "film": film_dict(o)}}
    im = develop(mi.render(mi.load_dict(d)))
    assert np.nanmean(im["XYZ"][..., 1]) == pytest.approx(1.0, rel=0.02)
    assert np.nanmean(im["bands"]["red"]) == pytest.approx(1.0, rel=0.05)
    assert np.nanmean(im["bands"]["far_red"]) == pytest.approx(1.0, rel=0.05)
    assert np.nanmedian(im["r_fr"]) == pytest.approx(660 / 730, rel=0.08)


@pytest.mark.slow
def test_moss_carpet_render_is_green_and_low_rfr_and_updates_in_place(scn, terrain):
    o = RenderOptions(width=64, height=48, spp=8, camera="patch", when="2026-06-21T12:00+09:00")
    rs = build_scene(scn, carpet(), moss_size=0.01, options=o, terrain=terrain,
                     species=SPECIES)
    assert rs.info["tufts"] == 900 and rs.info["moss_triangles"] > 900 * 30
    ids = {s.id() for s in rs.scene.shapes()}
    assert {"ground", "roof", "wall", "surround", "moss_bryum_argenteum"} <= ids
    a = render(rs)
    # the same scene without moss (update in place: same kernel, no recompilation)
    rs.update(None)
    faces = {s.id(): s.face_count() for s in rs.scene.shapes()}
    assert faces["moss_polytrichum"] == 1            # an empty mesh keeps the structure
    bare = render(rs)
    for im in (a, bare):
        assert np.all(np.isfinite(im["rgb"]))
        assert im["XYZ"][..., 1].mean() > 1e-4     # not black: skylight reaches under the roof
    # moss reflects far-red strongly and absorbs red: lower R:FR than bare humus
    assert np.nanmedian(a["r_fr"]) < 0.6 * np.nanmedian(bare["r_fr"])
    r, g, b = np.nanmean(a["rgb"].reshape(-1, 3), 0)
    assert g > r and g > b                          # green
    rb, gb, bb = np.nanmean(bare["rgb"].reshape(-1, 3), 0)
    assert rb > bb                                  # bare humus is brown, not green
    # moss of two species only: the third species' mesh becomes empty
    two = carpet(20)
    two = two.subset(two.species < 2)
    info = rs.update(two)
    assert info["tufts"] == len(two)
    faces = {s.id(): s.face_count() for s in rs.scene.shapes()}
    assert faces["moss_bryum_argenteum"] > 100 and faces["moss_polytrichum"] == 1


def test_tree_with_autumn_leaves(scn, terrain):
    t = simple_tree(height=1.0, seed=2)
    t = t.translated([0.3, 0.0, 0.4])
    n = len(t.leaves)
    t.leaves.attrs["autumn_tau"] = np.linspace(0, 1, n)
    t.leaves.attrs["fallen"] = np.arange(n) % 5 == 0
    o = RenderOptions(width=48, height=32, spp=2, leaf_bins=4, camera="overview")
    rs = build_scene(scn, None, trees=[t], options=o, terrain=terrain)
    ids = {s.id() for s in rs.scene.shapes()}
    assert {"bark", "leaves_00", "leaves_03"} <= ids
    assert rs.info["leaves"] == n - len(range(0, n, 5))
    assert np.all(np.isfinite(render(rs)["rgb"]))


def test_options_and_cameras_are_validated(scn, terrain):
    with pytest.raises(ParameterError):
        RenderOptions(spp=0).validate()
    with pytest.raises(ParameterError):
        RenderOptions(surround="lava").validate()
    with pytest.raises(ParameterError):
        build_scene(scn, None, options=RenderOptions(camera="nope", width=8, height=8, spp=1),
                    terrain=terrain)
    with pytest.raises(ParameterError):      # night: no daylight
        build_scene(scn, None, options=RenderOptions(when="2026-06-21T01:00+09:00", width=8,
                                                     height=8, spp=1), terrain=terrain)


@pytest.mark.slow
def test_set_light_moves_the_daylight_in_place_without_a_recompile(scn, terrain):
    """An animation's daily light: a scene built for one time and given another time's daylight
    with set_light renders as a scene built for that time (same seed: same image), and the
    second render reuses the compiled kernel."""
    import drjit as dr
    from mitsuba_veg.render.scene import sky_emitters

    o = RenderOptions(width=32, height=24, spp=4, camera="overview",
                      when="2026-06-21T12:00+09:00")
    rs = build_scene(scn, None, options=o, terrain=terrain)
    render(rs, seed=1)                                # compiles (or loads) the kernel
    autumn = "2026-09-21T10:00+09:00"                 # set_light's own small kernels, once
    rs.set_light(sky_emitters(scn, autumn), autumn)
    render(rs, seed=1)
    winter = "2026-12-21T10:00+09:00"
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        rs.set_light(sky_emitters(scn, winter), winter)
        moved = render(rs, seed=1)
        hist = dr.kernel_history([dr.KernelType.JIT])
    assert hist and all(h["cache_hit"] for h in hist)
    assert rs.info["when"] == winter
    fresh = render(build_scene(scn, None, options=o, terrain=terrain,
                               emitters=sky_emitters(scn, winter)), seed=1)
    a, b = moved["XYZ"][..., 1], fresh["XYZ"][..., 1]
    assert abs(a.mean() / b.mean() - 1) < 1e-4
    assert np.max(np.abs(a - b)) <= 1e-4 * b.max()
    summer = render(build_scene(scn, None, options=o, terrain=terrain), seed=1)
    # a December morning lights the garden's floor less (the image's lower half: 0.66 of
    # midsummer noon; its upper half holds the sky, brighter towards the low sun)
    h = a.shape[0] // 2
    assert a[h:].mean() < 0.8 * summer["XYZ"][h:, :, 1].mean()
    with pytest.raises(ParameterError, match="emitters"):
        rs.set_light({"lamp": {"type": "point"}})


# ---- what the render draws around and of the run ------------------------------------------------
def test_cameras_look_at_what_grew(scn, terrain):
    """The floor view looks across the densest moss at eye height, the overview keeps the horizon
    in its frame, the canopy view looks up into the trees."""
    from mitsuba_veg.render import cameras
    moss = carpet(20, x0=0.45, z0=-0.6)                      # moss east of the middle
    t = simple_tree(height=1.0, seed=2).translated([0.3, 0.0, 0.4])
    p = cameras.presets(scn, terrain, moss=moss, trees=[t])
    focus = cameras.moss_focus(moss, *terrain.ground_bbox())
    assert focus[0] == pytest.approx(moss.pos[:, 0].mean(), abs=0.06)
    fl = p["floor"]
    o, tg = np.array(fl["origin"]), np.array(fl["target"])
    to_focus = (focus - o) / np.linalg.norm(focus - o)
    look = (tg - o) / np.linalg.norm(tg - o)
    assert np.degrees(np.arccos(np.clip(look @ to_focus, -1, 1))) < 25.0
    W = max(np.ptp(terrain.meshes["ground"][0][:, [0, 2]], axis=0))
    assert o[1] == pytest.approx(min(cameras.EYE_HEIGHT, 0.35 * W), abs=0.05)
    ov = p["overview"]
    d = np.array(ov["target"]) - np.array(ov["origin"])
    pitch = np.degrees(np.arctan2(-d[1], np.hypot(d[0], d[2])))
    half_v = np.degrees(np.arctan(np.tan(np.radians(ov["fov"] / 2)) * 9 / 16))
    assert 0 < pitch < half_v - 1.0                       # the horizon is in a 16:9 frame
    cv = p["canopy"]
    d = np.array(cv["target"]) - np.array(cv["origin"])
    assert np.degrees(np.arctan2(d[1], np.hypot(d[0], d[2]))) >= 49.0
    no = cameras.presets(scn, terrain)                     # nothing grown: the overview stands in
    assert no["floor"] == no["overview"] and no["canopy"] == no["overview"]
    # a render computes only its own preset, the same as among all
    for name in cameras.BUILTIN:
        one = cameras.presets(scn, terrain, moss=moss, trees=[t], only=name)
        assert json.dumps(one[name]) == json.dumps(p[name]), name


class _Scn:
    def __init__(self, data, xml):
        self.data, self.xml, self.path = data, xml, "test.toml"

    def get(self, key, default=None):
        d = self.data
        for k in key.split("."):
            if not isinstance(d, dict) or k not in d:
                return default
            d = d[k]
        return d

    def file(self, key):
        return self.xml


def test_materials_in_their_order(tmp_path):
    """[render.materials] (ids or patterns), else the scene file's own BSDF, else the mesh's
    name, else its geology class; a key matching no mesh is refused."""
    import mitsuba as mi
    from mitsuba_veg.render.scene import resolve_materials
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0">'
                   '<shape type="rectangle" id="ground"/>'
                   '<shape type="rectangle" id="rock_1"/>'
                   '<shape type="rectangle" id="log_2"><bsdf type="diffuse">'
                   '<spectrum name="reflectance" value="0.2"/></bsdf></shape>'
                   '<shape type="rectangle" id="shed"/>'
                   '<shape type="rectangle" id="bed"/></scene>')
    base = mi.load_file(str(xml), optimize=False)
    meshes = {s.id(): None for s in base.shapes()}
    data = {"scene": {"file": "s.xml"}, "render": {"materials": {"sh*": "wood"}},
            "terrain": {"geology": {"bed": "sand"}}}
    m = resolve_materials(_Scn(data, xml), meshes, "ground", base)
    assert m["shed"] == "wood"                       # the scenario's pattern
    assert not isinstance(m["log_2"], str)           # the scene file's own BSDF
    assert m["rock_1"] == "stone"                    # the name
    assert m["bed"] == "sand" and m["ground"] == "humus"   # the geology class
    data["render"]["materials"] = {"log_*": "bark"}
    assert resolve_materials(_Scn(data, xml), meshes, "ground", base)["log_2"] == "bark"
    data["render"]["materials"] = {"tree_*": "bark"}
    with pytest.raises(ParameterError, match="render.materials"):
        resolve_materials(_Scn(data, xml), meshes, "ground", base)
    data["render"]["materials"] = {"shed": "lava"}
    with pytest.raises(ParameterError, match="lava"):
        resolve_materials(_Scn(data, xml), meshes, "ground", base)


def test_surround_continues_the_ground_to_the_horizon(terrain):
    from mitsuba_veg.render.scene import SURROUND_RADIUS, _outer_boundary
    (vn, fn), (vf, ff) = terrain.surround()
    v, f = terrain.meshes["ground"][:2]
    loop = _outer_boundary(v, f)
    assert np.allclose(vn[:len(loop)], v[loop])      # it starts on the ground's rim: no gap
    r = np.hypot(vf[:, 0], vf[:, 2])
    assert r.max() >= 0.99 * SURROUND_RADIUS
    # all faces up (two-sided anyway, but the normals are consistent)
    p = vn[fn]
    assert (np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 1] >= 0).all()


def test_distant_trees_are_drawn_at_their_level_of_detail():
    """A tree whose leaves span a pixel or two is drawn with the light pass's quads (the same leaf
    area, 2 triangles a leaf); near trees keep their shaped blades."""
    from mitsuba_veg.render.trees import far_trees, tree_geometry
    near = simple_tree(height=3.0, seed=1)
    far = simple_tree(height=3.0, seed=1).translated([0.0, 0.0, -400.0])
    cam = {"origin": [0.0, 1.5, 8.0], "fov": 50.0}
    f = far_trees([near, far], cam, 1920, 3.0)
    assert list(f) == [False, True]
    assert not far_trees([near, far], cam, 1920, 0.0).any()
    _, full = tree_geometry([far])
    _, quads = tree_geometry([far], far=[True])
    assert len(quads["f"]) == 2 * len(far.leaves) < len(full["f"])

    def area(g):
        p = g["v"].astype(float)[g["f"].astype(int)]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert area(quads) == pytest.approx(area(full), rel=1e-3)
