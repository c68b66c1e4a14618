"""Leaf litter: the day a leaf fell (phenology, checkpoints, snapshots), and the fallen leaves
the render lays on the ground, darkening and vanishing."""
import datetime as dt
from pathlib import Path
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.render import litter as LT
from mitsuba_veg.render import materials as mat
from mitsuba_veg.render.leaves import LEAF_AREA, triangle_areas
from mitsuba_veg.world import Phenology, PhenologyParams

ROOT = Path(__file__).resolve().parents[1]


# ---- the fall day ---------------------------------------------------------------------------
def test_phenology_keeps_the_day_each_leaf_fell_through_the_next_leaf_out():
    p = PhenologyParams(autumn_onset_doy=250, leaf_out_doy=95, insolation_full=10.0,
                        days_full=100.0)
    ph = Phenology(4, p, seed=1)
    assert np.all(np.asarray(ph.fall_day) == -1)
    ph.start_of_day(dt.date(2026, 7, 1))                      # full leaves
    light = np.array([4.0, 2.0, 0.0, 0.0])                    # MJ m-2 a day
    fell_on = {}
    for k in range(60):
        d = dt.date(2026, 9, 7) + dt.timedelta(days=k)        # from day of year 250
        ph.start_of_day(d)
        ph.end_of_day(d, light)
        for i, f in enumerate(np.asarray(ph.fallen)):
            if f and i not in fell_on:
                fell_on[i] = d
    fd = np.asarray(ph.fall_day)
    assert set(fell_on) >= {0, 1}                             # the sunny leaves fell
    for i, d in fell_on.items():
        assert fd[i] == d.toordinal()
    assert fell_on[0] < fell_on[1]
    # a leaf still hanging at the next leaf-out is shed that day; the others keep their day
    hanging = [i for i in range(4) if i not in fell_on]
    ph.start_of_day(dt.date(2027, 4, 5))                      # day of year 95
    fd2 = np.asarray(ph.fall_day)
    for i in fell_on:
        assert fd2[i] == fell_on[i].toordinal()
    for i in hanging:
        assert fd2[i] == dt.date(2027, 4, 5).toordinal()
    # checkpoints keep it; a checkpoint written before it existed restores -1
    d = ph.to_numpy()
    q = Phenology(4, p, seed=1)
    q.load_numpy(d)
    assert np.array_equal(np.asarray(q.fall_day), fd2)
    del d["phen_fall_day"]
    q.load_numpy(d)
    assert np.all(np.asarray(q.fall_day) == -1)


def test_leaves_unfolding_early_are_not_shed_at_leaf_out():
    """New leaves that unfold a few days before the leaf-out day (their clock runs until it)
    are not last year's hanging leaves."""
    ph = Phenology(3, PhenologyParams(leaf_out_doy=100), leaf_out_shift=np.array([-4.0, -2, 0]))
    for k in range(12):                     # leaves unfolding a few days early
        d = dt.date(2026, 4, 1) + dt.timedelta(days=k)
        ph.start_of_day(d)
        ph.end_of_day(d, np.full(3, 5.0))
    assert np.asarray(ph.grown).min() > 0 and np.asarray(ph.t).max() == 0   # reset on doy 100
    assert np.all(np.asarray(ph.fall_day) == -1)


def test_snapshots_carry_fall_days_and_old_snapshots_still_read(tmp_path):
    from mitsuba_veg.outputs import SnapshotWriter, _is_31_december, write_snapshot
    from mitsuba_veg.render.history import Run
    pop = {"state": np.array([2, 0]), "pos": np.zeros((2, 3)), "nrm": np.zeros((2, 3)),
           "species": np.zeros(2), "growth": np.ones(2)}
    snaps = tmp_path / "snapshots"
    write_snapshot(snaps, 5, pop, extra={"leaf_tau": np.zeros(3, np.float16),
                                         "leaf_grown": np.ones(3, np.float16),
                                         "leaf_on": np.ones(3, bool)})          # an old run
    write_snapshot(snaps, 9, pop, extra={"leaf_tau": np.ones(3, np.float16),
                                         "leaf_grown": np.zeros(3, np.float16),
                                         "leaf_on": np.zeros(3, bool),
                                         "leaf_fall_day": np.array([-1, 739900, 739901],
                                                                   np.int32)})
    run = Run(tmp_path, {}, None, [], 0.01, dt.date(2026, 1, 1), 9, None,
              [(5, snaps / "day_0005.npz"), (9, snaps / "day_0009.npz")])
    old = run.leaf_state(7)
    assert not old["fall_day_known"] and np.all(old["leaf_fall_day"] == -1)
    new = run.leaf_state(9)
    assert new["fall_day_known"] and new["leaf_fall_day"].tolist() == [-1, 739900, 739901]
    assert _is_31_december("2026-12-31") and not _is_31_december("2026-12-30")
    assert not _is_31_december(None)
    # the writer: a world's snapshot on 31 December even between frame days
    ph = Phenology(3, PhenologyParams())
    sim = SimpleNamespace(day=17, days=100, frame_every=30, out=tmp_path / "w", phen=ph,
                          site=SimpleNamespace(n_terrain=1), counts=lambda: np.zeros(1),
                          pop=SimpleNamespace(to_numpy=lambda: pop))
    SnapshotWriter()(sim, {"date": "2026-12-30"})
    assert not (tmp_path / "w" / "snapshots").exists()
    SnapshotWriter()(sim, {"date": "2026-12-31"})
    with np.load(tmp_path / "w" / "snapshots" / "day_0017.npz") as z:
        assert z["leaf_fall_day"].tolist() == [-1, -1, -1]


# ---- the litter's model ---------------------------------------------------------------------
def test_stage_life_and_size_by_age():
    assert LT.stage([0.0, 22.5, 45.0, 112.5, 180.0, 400.0]).tolist() == \
        pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0, 1.0])
    life = LT.lifetime(np.arange(1000), salt=3)
    assert life.min() >= 270 and life.max() <= 330 and abs(life.mean() - 300) < 3
    assert np.array_equal(life, LT.lifetime(np.arange(1000), salt=3))
    assert not np.array_equal(life, LT.lifetime(np.arange(1000), salt=4))
    f = LT.size_factor([np.nan, -1.0, 0.0, 240.0, 270.0, 300.0, 310.0], 300.0)
    assert f.tolist() == pytest.approx([0.0, 0.0, 1.0, 1.0, 0.5, 0.0, 0.0])


def test_stage_spectra_go_from_the_red_leaf_to_dark_litter():
    from mitsuba_veg.foliage import leaf_spectra
    ls = leaf_spectra(tau=1.0)
    fresh = np.interp(mat.WAVELENGTHS, ls.wavelength, ls.reflectance)
    assert np.allclose(LT.stage_spectrum(0.0), fresh)
    assert np.allclose(LT.stage_spectrum(0.5), mat.SPECTRA["litter"])
    assert np.allclose(LT.stage_spectrum(1.0), mat.SPECTRA["litter_dark"])
    assert np.allclose(LT.stage_spectrum(0.25), 0.5 * fresh + 0.5 * mat.SPECTRA["litter"])
    # darker with age in the visible; no red edge left in litter
    vis = [mat.band_mean(LT.stage_spectrum(s), 500, 600) for s in (0.5, 0.75, 1.0)]
    assert vis[0] > vis[1] > vis[2]
    assert mat.band_mean("litter_dark", 725, 735) < 1.5 * mat.band_mean("litter_dark", 655, 665)


@pytest.fixture(scope="module")
def ground():
    """A terrain stand-in: a plane at y = 0.2 tilted 10 deg about x, 40 m across."""
    a = np.radians(10.0)
    v = np.array([[-20, 0, -20], [20, 0, -20], [20, 0, 20], [-20, 0, 20]], float)
    v[:, 1] = 0.2 + np.tan(a) * v[:, 2]
    from mitsuba_veg.meshes import make_mesh
    scene = mi.load_dict({"type": "scene",
                          "g": make_mesh("g", v, np.array([[0, 2, 1], [0, 3, 2]]), 0.5)})
    return SimpleNamespace(base_scene=scene, bbox=lambda: (v.min(0), v.max(0)),
                           y=lambda x, z: 0.2 + np.tan(a) * z, slope=a)


def test_fallen_leaves_lie_on_the_terrain_drifting_with_their_height(ground):
    m = 4000
    rng = np.random.default_rng(0)
    pos = np.c_[rng.uniform(-3, 3, m), np.r_[np.full(m // 2, 0.2), np.full(m // 2, 10.2)],
                rng.uniform(-3, 3, m)]
    pl = LT.place(ground, pos, 0.2, salt=1)
    assert pl["hit"].all()
    p = pl["pos"].astype(float)
    n_g = np.array([0.0, np.cos(ground.slope), -np.sin(ground.slope)])
    # on the surface, LIFT above it
    assert np.allclose((p[:, 1] - ground.y(p[:, 0], p[:, 2])) * np.cos(ground.slope), LT.LIFT,
                       atol=2e-5)
    q = p - LT.LIFT * n_g                                      # the point on the surface
    drift = np.hypot(q[:, 0] - pos[:, 0], q[:, 2] - pos[:, 2])
    assert np.all(drift[: m // 2] < 1e-5)                     # from the ground: no drift
    # from 10 m: DRIFT x 10 x a Rayleigh variate (mean sqrt(pi / 2))
    assert drift[m // 2:].mean() == pytest.approx(LT.DRIFT * 10 * np.sqrt(np.pi / 2), rel=0.05)
    # flat-ish on the surface: within TILT of its normal, either face up
    c = np.abs(pl["normal"].astype(float) @ n_g)
    assert c.min() >= np.cos(LT.TILT) - 1e-5 and c.mean() < 0.99
    assert np.allclose((pl["up"] * pl["normal"]).sum(1), 0.0, atol=1e-5)
    # deterministic
    assert np.array_equal(LT.place(ground, pos, 0.2, salt=1)["pos"], pl["pos"])
    off = LT.place(ground, pos + [100.0, 0, 0], 0.2, salt=1)   # off the terrain: not drawn
    assert not off["hit"].any()


def test_litter_meshes_by_stage_with_the_leaves_area(ground):
    from mitsuba_veg.render.trees import simple_tree
    t = simple_tree(2.0, seed=1).translated([0.0, 0.2, 0.0])
    n = len(t.leaves)
    life = LT.lifetime(np.arange(n), 0)
    age = np.full(n, np.nan)
    age[: n // 2] = np.linspace(0, 200, n // 2)               # fell over 200 days
    age[n // 2: n // 2 + 10] = life[n // 2: n // 2 + 10] + 1.0   # gone
    t.leaves.attrs["litter_age"] = age
    cache = {}
    out = LT.litter_arrays([t], ground, None, cache)
    count = out.pop("count")
    assert count == n // 2
    assert sorted(out) == [f"litter_{b:02d}" for b in range(LT.BINS)]
    # every bin holds the leaves of its stage; areas: 0.6 size^2 each (none shrinking yet)
    b = np.minimum((LT.stage(age[: n // 2]) * LT.BINS).astype(int), LT.BINS - 1)
    for k in range(LT.BINS):
        v, f = out[f"litter_{k:02d}"]
        sel = np.nonzero(b == k)[0]
        if not len(sel):
            assert len(f) == 1 and v[0, 0] == -1e4
            continue
        assert triangle_areas(v, f).sum() == pytest.approx(
            LEAF_AREA * np.sum(t.leaves.size[sel] ** 2), rel=1e-4)
    assert any(k[0] == "litter" for k in cache)
    # the earlier version's litter comes as attrs["litter_extra"]
    t.leaves.attrs["litter_age"] = np.full(n, np.nan)
    t.attrs["litter_extra"] = LT.LitterLeaves(t.leaves.position, t.leaves.normal, t.leaves.up,
                                              t.leaves.size, np.full(n, 100.0), 0.2, "ovate",
                                              ("previous", 366, 0))
    out = LT.litter_arrays([t], ground, None, cache)
    assert out.pop("count") == n
    assert len(out["litter_04"][1]) == n * 12        # 100 days: stage 0.70, bin 4 of 6
    shapes, info = LT.litter_shapes([t], ground, None, cache)
    assert info["litter"] == n and set(shapes) == set(out)


def test_tree_seasons_and_world_leaves_give_litter_ages():
    from mitsuba_veg.render.seasons import TreeSeasons
    from mitsuba_veg.render.trees import simple_tree
    t = simple_tree(2.0, seed=1)
    s = TreeSeasons(t, 35.0, dt.date(2026, 3, 1), 305)
    s.apply(dt.date(2026, 12, 30))
    a = t.leaves.attrs
    assert np.array_equal(np.isfinite(a["litter_age"]), a["fallen"])
    i = np.nonzero(a["fallen"])[0][0]
    fall = dt.date(2026, 3, 1) + dt.timedelta(days=int(s.fall_index[i]))
    assert a["litter_age"][i] == (dt.date(2026, 12, 30) - fall).days
    s.apply(dt.date(2026, 7, 1))
    assert np.all(np.isnan(a["litter_age"]))


def test_render_scene_has_fixed_litter_meshes_and_a_switch():
    from mitsuba_veg.render import RenderOptions, Terrain, build_scene
    from mitsuba_veg.render.trees import simple_tree
    from mitsuba_veg.scenario import load_scenario
    scn = load_scenario(ROOT / "scenes" / "moss_garden" / "scenario.toml")
    terrain = Terrain.from_scenario(scn)
    t = simple_tree(1.0, seed=2).translated([0.3, 0.0, 0.4])
    n = len(t.leaves)
    t.leaves.attrs["fallen"] = np.arange(n) % 2 == 0
    t.leaves.attrs["litter_age"] = np.where(np.arange(n) % 2 == 0, 10.0, np.nan)
    o = RenderOptions(width=32, height=24, spp=1, leaf_bins=2)
    rs = build_scene(scn, None, trees=[t], options=o, terrain=terrain, tree_cache={})
    ids = {s.id(): s for s in rs.scene.shapes()}
    assert {f"litter_{b:02d}" for b in range(LT.BINS)} <= set(ids)
    assert rs.info["litter"] > 0.8 * (n // 2 + n % 2)
    before = ids["litter_00"].face_count()
    t.leaves.attrs["litter_age"] = np.where(np.arange(n) % 2 == 0, 200.0, np.nan)
    rs.update(None, [t])
    ids2 = {s.id(): s for s in rs.scene.shapes()}
    assert ids2["litter_00"] is ids["litter_00"]               # the same objects
    assert ids2["litter_00"].face_count() == 1 and before > 1  # moved on to a later stage
    assert ids2["litter_05"].face_count() > 1
    off = build_scene(scn, None, trees=[t], options=RenderOptions(width=32, height=24, spp=1,
                                                                  litter=False),
                      terrain=terrain)
    assert not any(s.id().startswith("litter") for s in off.scene.shapes())
    dr.sync_thread()
