"""Physical anchors of the spectral light studies: open daylight red:far-red, Beer–Lambert for a
random leaf cloud, and the light under a dense canopy of PROSPECT-D leaves (veg_leaf BSDF)."""
import json

import numpy as np
import pytest

import mitsuba as mi

import mitsuba_veg as mv
from mitsuba_veg.foliage.canopy import random_leaf_cloud
from mitsuba_veg.foliage.light_study import (leaf_values, open_reference, run_light_study,
                                             tree_scene)
from mitsuba_veg.light.clear_sky import daylight_from_angles
from mitsuba_veg.light.validation import grid_mesh, make_mesh, sun_vector


def test_open_daylight_red_far_red_is_1_1_to_1_2():
    gv, gf = grid_mesh(4, 4)
    sc = mi.load_dict({"type": "scene", **daylight_from_angles(180.0, 45.0),
                       "ground": make_mesh("ground", gv, gf, 0.2)}, optimize=False)
    res = mv.light.photon_irradiance(sc, photons=1_000_000, bands=("total", "par", "red",
                                                                   "far_red"))
    r = res.photon_flux_density("ground", "red").mean()
    f = res.photon_flux_density("ground", "far_red").mean()
    assert 1.1 <= r / f <= 1.2
    ref = open_reference(180.0, 45.0)
    assert 1.1 <= ref["rfr"] <= 1.2
    assert res.photon_flux_density("ground", "par").mean() == pytest.approx(ref["ppfd"], rel=0.02)


@pytest.mark.parametrize("lai, zenith", [(1.0, 30.0), (3.0, 0.0), (2.0, 50.0)])
def test_beer_lambert_for_a_random_leaf_cloud(lai, zenith):
    """Direct beam through leaves with spherical angles (G = 0.5): exp(-G LAI / cos θ) ± 5 %."""
    leaves = random_leaf_cloud(lai, (-3, 0.5, -3), (3, 1.5, 3), leaf_size=0.05, seed=1)
    s = sun_vector(90.0 - zenith, 180.0)
    em = {"sun": {"type": "directional", "direction": (-s).tolist(),
                  "irradiance": {"type": "uniform", "value": 1.0}}}
    sc, _ = tree_scene(leaves, emitters=em, ground_extent=6.0, ground_resolution=30)
    res = mv.light.photon_irradiance(sc, photons=2_000_000, indirect=False, seed=1)
    c = res.index.centroids[res.index.shape_slice("ground")]
    # ground whose beams cross the whole layer inside the cloud (sun in the south, +z)
    m = (np.abs(c[:, 0]) < 1.5) & (np.abs(c[:, 2] + np.tan(np.radians(zenith))) < 1.5)
    transmitted = res.irradiance("ground", "total")[m].mean() / (470.0 * np.cos(np.radians(zenith)))
    expected = np.exp(-0.5 * lai / np.cos(np.radians(zenith)))
    assert transmitted == pytest.approx(expected, rel=0.05)


@pytest.fixture(scope="module")
def dense_canopy():
    lai = 5.0
    leaves = random_leaf_cloud(lai, (-3, 0.3, -3), (3, 1.5, 3), leaf_size=0.08, seed=2)
    sc, leaf_map = tree_scene(leaves, emitters=daylight_from_angles(180.0, 60.0),
                              ground_extent=6.0, ground_resolution=30)
    res = mv.light.photon_irradiance(sc, photons=4_000_000, seed=1)
    c = res.index.centroids[res.index.shape_slice("ground")]
    m = (np.abs(c[:, 0]) < 1.0) & (np.abs(c[:, 2]) < 1.0)
    return res, m, leaf_map, open_reference(180.0, 60.0), leaves


def test_dense_canopy_red_far_red_well_below_half(dense_canopy):
    res, m, _, ref, _ = dense_canopy
    pf = res.photon_flux_density
    rfr_all = pf("ground", "red")[m].sum() / pf("ground", "far_red")[m].sum()
    # shade light: everything but the sunflecks (direct beam through gaps)
    red = pf("ground", "red", emitter="sky")[m].sum() + pf("ground", "red", emitter="sun",
                                                          component="indirect")[m].sum()
    fr = pf("ground", "far_red", emitter="sky")[m].sum() + pf("ground", "far_red", emitter="sun",
                                                             component="indirect")[m].sum()
    assert rfr_all < 0.5 < ref["rfr"]
    assert red / fr < 0.25


def test_dense_canopy_par_is_a_small_fraction_of_open(dense_canopy):
    res, m, leaf_map, ref, leaves = dense_canopy
    frac = res.photon_flux_density("ground", "par")[m].mean() / ref["ppfd"]
    assert frac < 0.1
    lv = leaf_values(res, leaf_map, n_leaves=len(leaves))
    assert np.isfinite(lv["ppfd"]).all()
    y = leaves.position[:, 1]
    top, bottom = y > np.quantile(y, 0.9), y < np.quantile(y, 0.1)
    # top leaves: near open light; bottom leaves: shade with a low red:far-red
    assert lv["ppfd"][top].mean() > 5 * lv["ppfd"][bottom].mean()
    rt, rb = np.nanmean(lv["rfr"][top]), np.nanmean(lv["rfr"][bottom])
    assert rt > 1.5 * rb and rb < 0.4, (rt, rb)


def test_run_light_study_writes_maps_npz_leaves_and_summary(tmp_path):
    s = run_light_study("sphere-tree", tmp_path, photons=300_000, tree_leaves=400)
    for f in ("light_study.npz", "light_maps.png", "leaves.csv", "summary.json"):
        assert (tmp_path / f).stat().st_size > 0
    d = json.loads((tmp_path / "summary.json").read_text())
    assert d["ground"]["ppfd_fraction_of_open"] < 1.0
    assert 1.0 < d["open"]["rfr"] < 1.2
    z = np.load(tmp_path / "light_study.npz")
    assert z["leaves/ppfd"].shape == (400,) and z["ground/rfr"].shape == z["ground/ppfd"].shape
    lines = (tmp_path / "leaves.csv").read_text().splitlines()
    assert len(lines) == 401 and lines[0].startswith("leaf,x_m")
    assert s["leaves"]["rfr_mean"] < d["open"]["rfr"]


def test_cli_parser_helper():
    import argparse

    from mitsuba_veg.cli.light_study import add_parser
    ap = argparse.ArgumentParser()
    add_parser(ap.add_subparsers(dest="cmd"))
    a = ap.parse_args(["light-study", "sphere-tree", "--photons", "1000", "--out", "x"])
    assert a.photons == 1000 and callable(a.func)
