"""Render building blocks without a full scene render: spectra, tuft models, 1/f noise, tuft
placement, film calibration, EXR/PNG outputs, snapshots and run loading."""
import json

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.render import film, materials, noise, tufts
from mitsuba_veg.render.moss import MossSet, growth_scale, place_tufts


# ---- materials ---------------------------------------------------------------------------------
def test_measured_spectra_are_read_with_their_source():
    text = materials.MEASURED_FILE.read_text()
    assert "earthlib 1.1.0, MIT licence" in text
    for name in ("humus", "sand", "asphalt", "gravel", "concrete", "bark", "wood", "litter"):
        assert f"# {name}:" in text
        s = materials.SPECTRA[name]
        # a measured curve: not a constant, and the file's 660-nm value
        assert np.ptp(s) > 0.005
    # organic soil is darker and less red than the library's median soil would be
    r, g, b = materials.srgb("humus")
    assert r > g > b and r < 0.45
    # bark and litter rise towards the near infrared (no chlorophyll, cellulose and lignin)
    for name in ("bark", "litter"):
        assert materials.band_mean(name, 725, 735) > materials.band_mean(name, 450, 460)


def test_spectra_are_physical_reflectances():
    for name, s in materials.SPECTRA.items():
        assert s.shape == materials.WAVELENGTHS.shape, name
        assert np.all(s >= 0) and np.all(s <= 0.95), name


@pytest.mark.parametrize("sp", ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"])
def test_moss_spectra_have_a_red_edge_and_look_green(sp):
    red = materials.band_mean(sp, 655, 665)
    fr = materials.band_mean(sp, 725, 735)
    assert red < 0.1 and fr > 0.3 and fr / red > 4       # chlorophyll trough + red edge
    r, g, b = materials.srgb(sp)
    assert g > r and g > b                                # reads as green
    # within a few hundredths of the moss model's albedo (red 0.05, far-red 0.45)
    assert abs(red - 0.05) < 0.03 and abs(fr - 0.45) < 0.12


def test_geology_spectra_order_and_colour():
    # sand is brighter and yellower than humus; asphalt is dark and nearly grey
    assert materials.band_mean("sand", 400, 700) > 2 * materials.band_mean("humus", 400, 700)
    a = materials.SPECTRA["asphalt"]
    assert a.max() < 0.1 and np.ptp(a) < 0.05
    r, g, b = materials.srgb("asphalt")
    assert abs(r - b) < 0.08
    r, g, b = materials.srgb("sand")
    assert r > g > b


def test_spectrum_and_regular_dict():
    d = materials.regular("humus")
    assert d["type"] == "regular" and d["wavelength_min"] == 360 and d["wavelength_max"] == 830
    assert len(d["values"].split(",")) == len(materials.WAVELENGTHS)
    assert np.allclose(materials.spectrum(0.3), 0.3)
    with pytest.raises(ParameterError):
        materials.spectrum("no_such_material")
    with pytest.raises(ParameterError):
        materials.spectrum(np.ones(7))


def test_leaf_bsdf_dict():
    """A leaf's render BSDF carries the PROSPECT-D spectra of its autumn time (tau clipped to
    0..1): green leaves absorb red, red ones reflect it."""
    from mitsuba_veg.foliage import leaf_bsdf_dict, leaf_spectra
    d = materials.leaf_bsdf(0.0)
    assert d["type"] == "veg_leaf" and "transmittance" in d
    assert d == leaf_bsdf_dict(leaf_spectra(tau=0.0))
    assert materials.leaf_bsdf(1.7) == materials.leaf_bsdf(1.0) != d
    assert materials.leaf_bsdf(-0.5) == d

    def red(bsdf_d):     # reflectance at 660 nm of the regular spectrum (1 nm from its start)
        r = bsdf_d["reflectance"]
        v = np.array([float(x) for x in r["values"].split(",")])
        return v[int(round(660 - r["wavelength_min"]))]
    assert red(materials.leaf_bsdf(1.0)) > 3 * red(d)


# ---- tufts -------------------------------------------------------------------------------------
@pytest.mark.parametrize("sp", tufts.SPECIES_MODELS)
def test_tuft_models_are_about_one_centimetre(sp):
    models = tufts.tuft_models(sp)
    assert len(models) == tufts.VARIANTS
    for m in models:
        ext = m.extent
        assert 0.005 < max(ext[0], ext[2]) < 0.018          # footprint ~1 cm
        assert 0.001 < ext[1] < 0.016                      # height
        assert m.vertices[:, 1].min() >= -1e-6             # base at y = 0
        assert m.faces.max() < len(m.vertices)
        assert 0 <= m.tone.min() and m.tone.max() <= 1
        assert 30 <= len(m.faces) <= 200                   # cheap enough for 100,000 tufts


def test_shipped_tuft_files_match_the_generator(tmp_path):
    for sp in tufts.SPECIES_MODELS:
        for k in range(tufts.VARIANTS):
            p = tufts.DATA_DIR / f"{sp}_{k}.ply"
            assert p.exists(), f"{p} missing: run python -m mitsuba_veg.render.tufts"
            shipped, gen = tufts.read_ply(p), tufts.generate(sp, k)
            assert np.allclose(shipped.vertices, gen.vertices, atol=1e-7)
            assert np.array_equal(shipped.faces, gen.faces)
    t = tufts.generate("polytrichum", 1)
    tufts.write_ply(tmp_path / "t.ply", t)
    back = tufts.read_ply(tmp_path / "t.ply")
    assert np.array_equal(back.faces, t.faces) and np.allclose(back.tone, t.tone)


def test_unknown_species_use_the_feather_moss_models():
    assert tufts.model_key("my_moss") == "hypnum_plumaeforme"
    assert len(tufts.tuft_models("my_moss")) == tufts.VARIANTS


# ---- noise -------------------------------------------------------------------------------------
def test_pink_noise_is_deterministic_bounded_and_1_over_f():
    rng = np.random.default_rng(0)
    p = rng.random((2000, 3))
    a = noise.pink_noise(p, 0.2, seed=3)
    assert np.array_equal(a, noise.pink_noise(p, 0.2, seed=3))
    assert not np.array_equal(a, noise.pink_noise(p, 0.2, seed=4))
    assert 0.2 < a.std() < 0.5 and np.abs(a).max() < 2.0
    img = noise.pink_noise_image((256, 256), scale_px=64.0, octaves=6, seed=1)
    P = np.abs(np.fft.rfft2(img - img.mean())) ** 2
    fy = np.fft.fftfreq(256)[:, None]
    fx = np.fft.rfftfreq(256)[None, :]
    f = np.hypot(fx, fy)
    bands = [P[(f >= lo) & (f < 2 * lo)].mean() for lo in (1 / 128, 1 / 64, 1 / 32, 1 / 16)]
    assert all(b0 > b1 for b0, b1 in zip(bands, bands[1:]))   # power falls with frequency


# ---- placement ---------------------------------------------------------------------------------
def _moss(n=400, seed=0):
    rng = np.random.default_rng(seed)
    pos = np.c_[rng.uniform(-0.2, 0.2, n), np.zeros(n), rng.uniform(-0.2, 0.2, n)]
    nrm = np.tile([0.0, 1.0, 0.0], (n, 1))
    return MossSet(pos, nrm, rng.integers(0, 3, n), rng.uniform(0, 20, n),
                   ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"])


def test_growth_scale_is_monotonic_and_bounded():
    g = np.array([0.0, 1.0, 4.0, 100.0])
    s = growth_scale(g)
    assert np.all(np.diff(s) > 0) and s[0] == pytest.approx(0.45) and s[-1] < 1.46


def test_place_tufts_merges_one_mesh_per_species():
    m = _moss()
    meshes = place_tufts(m, size=0.01, seed=1)
    assert sorted(t.species for t in meshes) == sorted(set(m.species_names))
    assert sum(t.count for t in meshes) == len(m)
    for t in meshes:
        assert t.vertices.dtype == np.float32 and t.faces.dtype == np.uint32
        assert t.faces.max() < len(t.vertices) and len(t.tone) == len(t.vertices)
        # every vertex lies within ~2 cm of some moss, above the ground plane (y >= -1 mm)
        assert t.vertices[:, 1].min() > -0.002 and t.vertices[:, 1].max() < 0.03
    # deterministic, and keyed on positions: the same moss keeps its tuft in another frame
    again = place_tufts(m, size=0.01, seed=1)
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(meshes, again))
    sub = place_tufts(m.subset(m.species == 0), size=0.01, seed=1)
    first = [t for t in meshes if t.species == "bryum_argenteum"][0]
    assert np.array_equal(sub[0].vertices, first.vertices)


def test_place_tufts_follows_the_surface_normal():
    n = 50
    pos = np.c_[np.zeros(n), np.linspace(0, 1, n), np.full(n, -0.9)]
    nrm = np.tile([0.0, 0.0, 1.0], (n, 1))              # a wall facing +z
    m = MossSet(pos, nrm, np.zeros(n, int), np.full(n, 10.0), ["polytrichum"])
    t = place_tufts(m, size=0.01)[0]
    assert t.vertices[:, 2].min() > -0.9 - 0.002          # tufts stand out of the wall
    assert t.vertices[:, 2].max() > -0.9 + 0.006


def test_place_tufts_validates_size():
    with pytest.raises(ParameterError):
        place_tufts(_moss(5), size=0.0)
    assert place_tufts(_moss(0)) == []


# ---- film --------------------------------------------------------------------------------------
def test_band_response_integral_is_exact():
    r = film.band_response(655, 665, 8.0)
    assert np.trapezoid(r, film._WL) == pytest.approx(80.0)


def test_develop_calibration_on_synthetic_tensor():
    y_int = float(np.trapezoid(film._cmfs()[1], film._WL))
    x_int = float(np.trapezoid(film._cmfs()[0], film._WL))
    z_int = float(np.trapezoid(film._cmfs()[2], film._WL))
    # what the film records for a flat spectral radiance of 2 W m-2 sr-1 nm-1
    t = np.zeros((2, 3, 5))
    t[..., 0], t[..., 1], t[..., 2] = 2 * x_int, 2 * y_int, 2 * z_int
    t[..., 3] = 2 * film.BAND_WEIGHT * 10
    t[..., 4] = 2 * film.BAND_WEIGHT * 10
    im = film.develop(t)
    assert np.allclose(im["XYZ"][..., 1], 2.0)
    assert np.allclose(im["bands"]["red"], 2.0) and np.allclose(im["bands"]["far_red"], 2.0)
    assert np.allclose(im["r_fr"], 660.0 / 730.0)          # photon ratio of a flat spectrum
    # equal-energy white is slightly pink in sRGB (E is not D65) but nearly neutral
    rgb = im["rgb"][0, 0] / im["rgb"][0, 0].mean()
    assert np.all(np.abs(rgb - 1) < 0.2)
    with pytest.raises(ParameterError):
        film.develop(np.zeros((2, 2, 3)))


def test_exr_round_trip_and_png(tmp_path):
    rng = np.random.default_rng(0)
    im = {"XYZ": rng.random((6, 8, 3)), "rgb": rng.random((6, 8, 3)),
          "bands": {"red": rng.random((6, 8)), "far_red": rng.random((6, 8)) + 0.1}}
    im["r_fr"] = im["bands"]["red"] / im["bands"]["far_red"]
    p = film.write_exr(tmp_path / "a.exr", im, {"camera": "test"})
    ch = film.read_exr(p)
    assert {"R", "G", "B", "X", "Y", "Z", "red_655_665", "far_red_725_735", "R_FR"} <= set(ch)
    assert np.allclose(ch["G"], im["rgb"][..., 1], atol=1e-6)
    assert np.allclose(ch["far_red_725_735"], im["bands"]["far_red"], atol=1e-6)
    img8, e = film.to_srgb8(im["rgb"])
    assert img8.dtype == np.uint8 and img8.shape == (6, 8, 3) and e > 0
    assert film.write_png(tmp_path / "a.png", img8).exists()
    fc = film.rfr_false_colour(im["r_fr"], luminance=im["XYZ"][..., 1], title="t")
    assert fc.shape == (6 + 45, 8 + 125, 3) and fc.dtype == np.uint8


def test_rfr_picture_is_the_plasma_map_on_a_log_scale():
    """The shipped colour table is matplotlib's plasma; each pixel is the table's entry at the
    ratio's place on the log scale (lo, hi), NaN as lo, clipped outside; the bar runs lo..hi."""
    import matplotlib
    want = np.asarray(matplotlib.colormaps["plasma"](np.linspace(0, 1, 256)))[:, :3]
    assert np.abs(film._plasma() - want).max() <= 0.5 / 255 + 1e-9
    lo, hi = 0.05, 2.0
    r = np.array([[lo, hi, np.sqrt(lo * hi), 0.01, 50.0, np.nan]] * 4)
    fc = film.rfr_false_colour(r, lo, hi).astype(int)
    lut = (film._plasma() * 255 + 0.5).astype(int)
    img = fc[45:, :6]
    for col, k in ((0, 0), (1, 255), (2, 128), (3, 0), (4, 255), (5, 0)):
        assert np.abs(img[:, col] - lut[k]).max() <= 1, (col, img[0, col], lut[k])
    # the colour bar beside the image: hi at its top, lo at its bottom
    big = film.rfr_false_colour(np.full((200, 300), 1.0))
    bar = big[45:, 300 + 12 + 6]
    top, bottom = bar[int(0.1 * 200) + 1], bar[int(0.9 * 200) - 2]
    assert np.abs(top.astype(int) - lut[255]).max() <= 12
    assert np.abs(bottom.astype(int) - lut[0]).max() <= 12
    with pytest.raises(ValueError, match="lo"):
        film.rfr_false_colour(r, 2.0, 0.05)


def test_tone_map_keeps_highlights_below_white():
    x = np.array([0.0, 0.18, 1.0, 4.0, 100.0])
    y = film.tone_map(x)
    assert np.all(np.diff(y) > 0) and y[0] == 0 and y[-2] < 1.0 and y[-1] <= 1.0
    img8, _ = film.to_srgb8(np.full((4, 4, 3), np.nan))
    assert np.all(img8 == 0)


# ---- snapshots and runs ------------------------------------------------------------------------
def test_snapshot_round_trip_and_approximate_frames(tmp_path):
    from mitsuba_veg.outputs import write_snapshot
    from mitsuba_veg.render.history import load_run
    rng = np.random.default_rng(1)
    n = 50
    pop = {"state": np.r_[np.full(40, 2), np.full(10, 1)].astype(np.uint32),
           "species": rng.integers(0, 3, n).astype(np.uint32),
           "pos": rng.random((n, 3)).astype(np.float32),
           "nrm": np.tile([0, 1, 0], (n, 1)).astype(np.float32),
           "growth": rng.uniform(0, 10, n).astype(np.float32)}
    # a run folder as the simulation writes it (summary + checkpoint), no snapshots
    np.savez(tmp_path / "checkpoint.npz", day=np.array(20), **pop)
    names = ["Bryum argenteum", "Hypnum plumaeforme", "Polytrichum"]
    alive = lambda k: {nm: int(k) for nm in names}                               # noqa: E731
    summary = {"scenario": str(__import__("pathlib").Path(__file__).resolve().parents[1] /
                               "scenes/moss_garden/scenario.toml"),
               "species": names, "days_record": [{"day": d, "alive": alive(d // 4)}
                                                 for d in range(1, 21)],
               "settings": {"moss": {"size": 0.01}, "simulation": {"start_date": "2026-03-01"}}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    run = load_run(tmp_path)
    assert run.final_day == 20 and run.moss_size == 0.01
    assert len(run.final_moss()) == 40
    assert run.date(1).isoformat() == "2026-03-01"
    fr = run.frame(8)
    assert not fr.exact and len(fr.moss) <= 3 * 2
    assert run.frame_days(count=3) == [1, 10, 20]
    # with snapshots the frames are exact
    write_snapshot(tmp_path / "snapshots", 1, pop, "2026-03-01")
    write_snapshot(tmp_path / "snapshots", 20, pop, "2026-03-20")
    run = load_run(tmp_path)
    assert run.frame_days() == [1, 20]
    f1 = run.frame(1)
    assert f1.exact and len(f1.moss) == 40
    assert np.allclose(f1.moss.pos, pop["pos"][:40], atol=1e-6)


def test_load_run_errors(tmp_path):
    from mitsuba_veg.render.history import load_run
    with pytest.raises(ParameterError):
        load_run(tmp_path / "nope")


# ---- trees and seasons -------------------------------------------------------------------------
def test_simple_tree_and_make_tree():
    from mitsuba_veg.render.trees import make_tree, simple_tree
    t = simple_tree(2.0, seed=1)
    assert len(t.leaves) > 100 and 1.5 < t.metrics()["height"] < 3.0
    m = make_tree({"model": "simple", "position": [1.0, 0.0, 2.0], "height": 1.5})
    assert m.start[0].tolist() == [1.0, 0.0, 2.0]
    assert m.metrics()["height"] == pytest.approx(1.5, rel=1e-6)
    with pytest.raises(ParameterError):
        make_tree({"preset": "quaking_aspen", "colour": "red"})
    with pytest.raises(ParameterError):
        make_tree({"model": "simple", "height": -1})


def test_tree_seasons_leaf_out_autumn_and_fall():
    import datetime as dt
    from mitsuba_veg.render.seasons import TreeSeasons
    from mitsuba_veg.render.trees import simple_tree
    t = simple_tree(2.0, seed=1)
    s = TreeSeasons(t, 35.0, dt.date(2026, 3, 1), 305)
    a = t.leaves.attrs
    s.apply(dt.date(2026, 3, 10))
    assert a["leaf_scale"].max() == 0.0                      # bare in March
    s.apply(dt.date(2026, 7, 1))
    assert a["leaf_scale"].min() == 1.0 and a["autumn_tau"].max() == 0.0   # green summer
    s.apply(dt.date(2026, 10, 25))
    assert 0.2 < np.median(a["autumn_tau"]) <= 1.0            # colouring
    s.apply(dt.date(2026, 12, 30))
    assert a["fallen"].mean() > 0.5                           # mostly fallen by the year's end
    # sunnier (outer, higher) leaves colour first
    from mitsuba_veg.render.seasons import leaf_exposure
    e = leaf_exposure(t)
    s.apply(dt.date(2026, 10, 10))
    hi, lo = e > np.quantile(e, 0.8), e < np.quantile(e, 0.2)
    assert a["autumn_tau"][hi].mean() > a["autumn_tau"][lo].mean()


# ---- denoiser ----------------------------------------------------------------------------------
def test_denoise_removes_noise_and_keeps_scale_and_nans(tmp_path):
    from mitsuba_veg.render import denoise
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:96, 0:128] / 96.0
    clean = np.stack([0.02 + 0.03 * x, 0.03 + 0.02 * y, 0.025 + 0 * x], -1)   # W m-2 sr-1 nm-1
    noisy = clean * (1 + 0.4 * rng.standard_normal(clean.shape))
    noisy[5, 7] = np.nan
    out = denoise.denoise(noisy)
    err = lambda a: np.sqrt(np.nanmean((a - clean) ** 2)) / clean.mean()  # noqa: E731
    assert err(out) < 0.25 * err(noisy)
    assert np.nanmean(out) == pytest.approx(clean.mean(), rel=0.05)
    assert np.isnan(out[5, 7]).all() and np.isfinite(out[6, 7]).all()
    # the EXR keeps the rendered RGB and carries the display image beside it
    images = {"rgb": noisy, "XYZ": noisy, "display": out}
    p = film.write_exr(tmp_path / "a.exr", images)
    ch = film.read_exr(p)
    assert {"R", "display.R", "display.G", "display.B"} <= set(ch)
    assert np.allclose(ch["display.G"], out[..., 1].astype(np.float32), equal_nan=True)


def test_the_film_colour_science_is_colour_sciences():
    """The shipped CMF table, XYZ -> sRGB matrix and sRGB encoding equal colour-science's (the
    render does not import it: a second of start-up)."""
    import colour
    cmf = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    ref = np.stack([np.interp(film._WL, cmf.wavelengths, cmf.values[:, i]) for i in range(3)])
    assert np.allclose(film._cmfs(), ref, rtol=1e-7, atol=1e-12)
    xyz = np.random.default_rng(1).random((50, 3))
    assert np.allclose(xyz @ film.XYZ_TO_SRGB.T,
                       colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False), atol=1e-12)
    x = np.linspace(0, 1, 101)
    assert np.allclose(film.srgb_encode(x), colour.cctf_encoding(x, function="sRGB"),
                       atol=1e-12)
