"""The moss carpet draws each moss's spot-grid cell: isolated patches keep their area, closed
populations close into a carpet without gaps or overlaps, and a render's geometric cover of the
ground equals the simulated cover min(n size² / area, 1)."""
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.render import RenderOptions, Terrain, build_scene, carpet, fidelity
from mitsuba_veg.render.moss import MossSet, cell_centres, place_tufts
from mitsuba_veg.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
SPECIES = ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"]
SIZE = 0.02
ORIGIN = np.array([-1.0, -0.5, -1.0])


def _flat(cells, y=0.0, seed=0, species=0):
    """Moss at random points of the given (ia, ib) cells of a flat ground at height y."""
    rng = np.random.default_rng(seed)
    cells = np.asarray(cells, float).reshape(-1, 2)
    n = len(cells)
    # the dominant axis d = y (1): a = (d + 1) % 3 = z, b = (d + 2) % 3 = x
    x = ORIGIN[0] + (cells[:, 1] + rng.uniform(0.05, 0.95, n)) * SIZE
    z = ORIGIN[2] + (cells[:, 0] + rng.uniform(0.05, 0.95, n)) * SIZE
    pos = np.c_[x, np.full(n, y), z]
    return MossSet(pos, np.tile([0.0, 1.0, 0.0], (n, 1)), np.full(n, species),
                   rng.uniform(0, 20, n), SPECIES)


def _area(meshes):
    return sum(carpet.patch_area(m).sum() for m in meshes)


def test_cell_keys_follow_the_dominant_axis():
    m = _flat([(3, 5), (4, 5)])
    d, ia, ib = carpet.cell_keys(m.pos, m.nrm, ORIGIN, SIZE)
    assert list(d) == [1, 1] and list(ia) == [3, 4] and list(ib) == [5, 5]
    wall = MossSet([[0.013, 0.31, -0.21]], [[1.0, 0.1, 0.0]], [0], [1.0], SPECIES)
    d, ia, ib = carpet.cell_keys(wall.pos, wall.nrm, ORIGIN, SIZE)
    # a wall facing +x: cells counted along y (a: 0.81 / 0.02) and z (b: 0.79 / 0.02)
    assert d[0] == 0 and ia[0] == 40 and ib[0] == 39


def test_an_isolated_moss_covers_its_cell_area():
    rng = np.random.default_rng(1)
    cells = rng.choice(10_000, 300, replace=False)
    cells = np.c_[cells // 100 * 3, cells % 100 * 3]          # 3 cells apart: all isolated
    m = _flat(cells)
    meshes = carpet.carpet_patches(m, SIZE, ORIGIN)
    a = np.concatenate([carpet.patch_area(x) for x in meshes])
    # rounded corners and pushed edges keep the area: (1 + m)(1 - k) = 1; jitter is zero-mean
    assert a.mean() == pytest.approx(SIZE ** 2, rel=0.03)
    assert np.all(a > 0.6 * SIZE ** 2) and np.all(a < 1.5 * SIZE ** 2)
    square = carpet.carpet_patches(m, SIZE, ORIGIN, jitter=0.0, rounding=0.0, wobble_edges=0.0,
                                   lift=0.0,
                                   cushion=0.0)
    assert np.allclose(carpet.patch_area(square[0]), SIZE ** 2, rtol=1e-4)


def test_every_patch_faces_the_way_its_moss_does():
    """Moss facing each of the six axis directions (a rock's top, flanks and underside): every
    carpet triangle's geometric normal agrees with its shading normals and with its moss's
    normal. A bump map turns its frame to the geometric normal, so a patch wound against its
    moss rendered black (the west, north and under sides of rocks and logs)."""
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    rng = np.random.default_rng(3)
    nrm = np.repeat(dirs + rng.normal(0, 0.15, (6, 3)), 20, 0)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pos = rng.uniform(-0.4, 0.4, (len(nrm), 3))
    m = MossSet(pos, nrm, np.arange(len(nrm)) % 3, rng.uniform(0, 20, len(nrm)), SPECIES)
    for cm in carpet.carpet_patches(m, SIZE, ORIGIN):
        v = cm.vertices.astype(float)[cm.faces.astype(np.int64)]
        geo = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        shade = cm.normals.astype(float)[cm.faces.astype(np.int64)].sum(1)
        assert np.all(np.einsum("ij,ij->i", geo, shade) > 0), cm.species
        sel = m.species == SPECIES.index(cm.species)
        moss_n = np.repeat(m.nrm[sel], len(carpet.PATCH_FACES), 0)
        assert np.all(np.einsum("ij,ij->i", geo, moss_n) > 0), cm.species


def test_a_closed_population_is_a_carpet_without_gaps_or_overlaps():
    n = 12
    cells = [(i, j) for i in range(n) for j in range(n)]
    m = _flat(cells, seed=3)
    meshes = carpet.carpet_patches(m, SIZE, ORIGIN)
    # shared edges are the same points in both patches: the areas add up to the block's
    assert _area(meshes) == pytest.approx((n * SIZE) ** 2, rel=0.02)
    # and rays straight down inside the block (away from its rim) all meet the carpet
    v = np.concatenate([x.vertices for x in meshes])
    f = np.concatenate([x.faces + sum(len(y.vertices) for y in meshes[:k])
                        for k, x in enumerate(meshes)])
    scene = mi.load_dict({"type": "scene", "c": _mesh(v, f)})
    g = np.linspace(0.4, n - 0.4, 60) * SIZE
    X, Z = np.meshgrid(ORIGIN[0] + g, ORIGIN[2] + g)
    k = X.size
    f32 = lambda a: mi.Float(np.ascontiguousarray(a, np.float32))  # noqa: E731
    ray = mi.Ray3f(mi.Point3f(f32(X.ravel()), f32(np.ones(k)), f32(Z.ravel())),
                   mi.Vector3f(0.0, -1.0, 0.0))
    assert np.asarray(scene.ray_test(ray)).all()


def _mesh(v, f):
    from mitsuba_veg.meshes import make_mesh
    return make_mesh("c", v, f)


def test_patches_lie_on_the_terrain_and_tufts_stand_in_their_cell():
    m = _flat([(i, j) for i in range(5) for j in range(5)], y=0.1)
    meshes = carpet.carpet_patches(m, SIZE, ORIGIN)
    y = np.concatenate([x.vertices[:, 1] for x in meshes])
    assert y.min() > 0.1 and y.max() < 0.1 + 0.2 * SIZE          # lifted, a thin cushion
    t = place_tufts(m, size=SIZE, origin=ORIGIN, jitter=0.0)[0]
    c = cell_centres(m.pos, m.nrm, ORIGIN, SIZE)
    # each tuft's footprint stays within its cell: the vertices lie within ~0.6 cells of the
    # cell centres (the tuft models are ~1 cell across at full growth)
    from scipy.spatial import cKDTree
    dist, _ = cKDTree(c[:, [0, 2]]).query(t.vertices[:, [0, 2]].astype(float))
    assert dist.max() < 0.75 * SIZE


def test_carpet_validates_its_settings():
    m = _flat([(0, 0)])
    with pytest.raises(ParameterError):
        carpet.carpet_patches(m, 0.0, ORIGIN)
    with pytest.raises(ParameterError):
        carpet.carpet_patches(m, SIZE, ORIGIN, jitter=0.5)
    assert carpet.carpet_patches(m.subset(np.zeros(1, bool)), SIZE, ORIGIN) == []


def test_moss_texture_tiles_and_is_bounded():
    t = carpet.moss_texture(128, seed=2, shoot_px=3.0, density=0.05)
    assert t.shape == (128, 128) and t.min() >= 0 and t.max() <= 1 and 0.1 < t.mean() < 0.7
    # periodic: the wrap-around step is like any other neighbouring step
    assert np.abs(t[0] - t[-1]).mean() < 2.5 * np.abs(np.diff(t, axis=0)).mean()


@pytest.fixture(scope="module")
def garden():
    s = load_scenario(ROOT / "scenes" / "moss_garden" / "scenario.toml")
    s.data.setdefault("render", {})["cameras"] = {
        # straight down from under the roof (y 0.75 m) on the back floor
        "plan": {"origin": [0.0, 0.7, -0.62], "target": [0.0, 0.0, -0.621], "fov": 26,
                 "up": [0, 0, -1]}}
    return s, Terrain.from_scenario(s)


def test_rendered_cover_equals_simulated_cover(garden):
    """Moss on the moss garden's back floor in a known pattern: per ground triangle, the share of
    pixels whose ray meets moss equals min(n size² / area, 1)."""
    scn, terrain = garden
    size = 0.01
    o = terrain.grid_origin(size)
    rng = np.random.default_rng(5)
    # cells of the back floor (y = 0 there) around x in [-0.12, 0.12], z in [-0.74, -0.5]
    ia = np.arange(int((-0.74 - o[2]) / size), int((-0.5 - o[2]) / size))
    ib = np.arange(int((-0.12 - o[0]) / size), int((0.12 - o[0]) / size))
    A, B = np.meshgrid(ia, ib, indexing="ij")
    keep = rng.random(A.size) < 0.45
    a, b = A.ravel()[keep], B.ravel()[keep]
    n = len(a)
    pos = np.c_[o[0] + (b + rng.uniform(0.1, 0.9, n)) * size, np.full(n, 0.5),
                o[2] + (a + rng.uniform(0.1, 0.9, n)) * size]
    # on the floor: a ray down from 0.5 m (under the roof)
    f32 = lambda x: mi.Float(np.ascontiguousarray(x, np.float32))  # noqa: E731
    ray = mi.Ray3f(mi.Point3f(f32(pos[:, 0]), f32(pos[:, 1]), f32(pos[:, 2])),
                   mi.Vector3f(0.0, -1.0, 0.0))
    pos[:, 1] -= np.asarray(terrain.base_scene.ray_intersect_preliminary(ray).t)
    moss = MossSet(pos, np.tile([0.0, 1.0, 0.0], (n, 1)), rng.integers(0, 3, n),
                   rng.uniform(0, 20, n), SPECIES)
    opts = RenderOptions(width=160, height=160, spp=1, camera="plan", denoise=False)
    rs = build_scene(scn, moss, moss_size=size, options=opts, terrain=terrain)
    tri, clear, on_moss = fidelity.pixel_triangles(rs)
    sim = fidelity.simulated_cover(terrain, moss, size)
    v, f = terrain.meshes["ground"][:2]
    assert (sim * fidelity.triangle_areas(v, f)).sum() == pytest.approx(n * size ** 2, rel=1e-6)
    assert sim.max() > 0.2
    sel = (tri >= 0) & clear
    px = np.bincount(tri[sel], minlength=len(f))
    mg = np.bincount(tri[sel], weights=on_moss[sel].astype(float), minlength=len(f))
    use = px >= 40
    geo = mg[use] / px[use]
    area = fidelity.triangle_areas(v, f)[use]
    assert (geo * area).sum() / (sim[use] * area).sum() == pytest.approx(1.0, abs=0.05)
    # per triangle: cells that straddle a triangle's edge count for the triangle their moss is on
    # and cover both (the triangles here are only 5 cells across): the bound, 0.1
    assert np.abs(geo - sim[use])[sim[use] > 0].mean() < 0.1
    # the counts of cover_counts, pooled over views by cover_summary: a view's NDVI pixels where
    # the bands say chlorophyll (here exactly the moss pixels), two identical views sum to the
    # same comparison
    fake = {"bands": {"red": np.where(on_moss, 0.1, 1.0), "far_red": np.ones(on_moss.shape)}}
    c = fidelity.cover_counts(rs, fake)
    np.testing.assert_array_equal(c["pixels"], px)
    np.testing.assert_array_equal(c["ndvi"], mg)
    np.testing.assert_array_equal(c["geometric"], mg)
    one = fidelity.cover_summary(c, sim, fidelity.triangle_areas(v, f), min_pixels=40)
    two = fidelity.cover_summary({k: 2 * x for k, x in c.items()}, sim,
                                 fidelity.triangle_areas(v, f), min_pixels=80)
    assert one["area_ratio"] == pytest.approx((geo * area).sum() / (sim[use] * area).sum())
    assert one["area_ratio"] == pytest.approx(one["geometric_area_ratio"])
    assert two["area_ratio"] == pytest.approx(one["area_ratio"]) and \
        two["compared"] == one["compared"] == int(use.sum())


def _flat_patch_radiance(bsdf: dict, elevation_deg: float) -> np.ndarray:
    """Mean RGB radiance of a 1 m square with ``bsdf`` seen from straight above under a sun at
    ``elevation_deg`` (irradiance 1 normal to the sun) and a dim sky; the square's texture
    coordinates run over it as the carpet's do (metres / TEXTURE_TILE)."""
    el = np.radians(elevation_deg)

    def tiled(x):
        if isinstance(x, dict):
            if x.get("type") == "mesh_attribute":       # the rectangle has no vertex tone
                return {"type": "uniform", "value": 0.5}
            x = {k: tiled(v) for k, v in x.items()}
            if x.get("type") == "bitmap":
                x["to_uv"] = mi.ScalarTransform4f().scale([1 / carpet.TEXTURE_TILE] * 2 + [1])
        return x

    d = {"type": "scene",
         "square": {"type": "rectangle", "bsdf": tiled(bsdf),
                    "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(0.5)},
         "sun": {"type": "directional", "direction": [-np.cos(el), -np.sin(el), 0.0],
                 "irradiance": {"type": "uniform", "value": 1.0}},
         "sky": {"type": "constant", "radiance": {"type": "uniform", "value": 0.1}},
         "integrator": {"type": "path", "max_depth": 3},
         "sensor": {"type": "orthographic",
                    "to_world": mi.ScalarTransform4f().look_at(origin=[0, 2, 0], target=[0, 0, 0],
                                                               up=[0, 0, -1]).scale([0.4, 0.4, 1]),
                    "sampler": {"type": "independent", "sample_count": 32},
                    "film": {"type": "hdrfilm", "width": 96, "height": 96, "pixel_format": "rgb",
                             "rfilter": {"type": "box"}}}}
    return np.asarray(mi.render(mi.load_dict(d))).reshape(-1, 3).mean(0)


@pytest.mark.parametrize("elevation", [20.0, 45.0, 70.0])
def test_the_carpet_relief_keeps_the_moss_as_bright_as_its_spectra(elevation):
    """The bump map's relief moves shading, not the carpet's brightness: a sunlit carpet seen
    from above reflects 0.95-1.2 times its smooth blend of the same spectra (the shoot tips'
    light spectrum lifts it; 0.97-1.04 measured). A bump height of centimetres (the old
    BUMP_SCALE of 0.35 m) tilted the normals flat and drew sunlit moss at a third of its
    reflectance, 4x darker than the soil in the far-red."""
    from mitsuba_veg.render import materials as mat
    from mitsuba_veg.render.scene import _moss_bsdf
    sp = "hypnum_plumaeforme"
    smooth = {"type": "twosided", "bsdf": mat.blend(
        mat.diffuse(sp), mat.diffuse(sp + "_light"), {"type": "mesh_attribute",
                                                      "name": "vertex_tone"})}
    ratio = _flat_patch_radiance(_moss_bsdf(sp, carpet=True), elevation) / \
        _flat_patch_radiance(smooth, elevation)
    assert np.all((ratio > 0.95) & (ratio < 1.2)), ratio
