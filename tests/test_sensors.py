"""Virtual sensors (mitsuba_veg.light.sensors) and their time series (light-study --year).

Analytic references:
- directional sun of normal irradiance E at elevation e over open (black) ground: a cosine
  sensor facing up reads E sin e (= the flat ground's irradiance), a spherical sensor E, a dome
  facing up E (1 + sin e) / 2, so cosine / spherical = sin e;
- uniform sky of radiance L above the horizon, nothing below: cosine (up) pi L, spherical
  (scalar irradiance) 2 pi L, dome (up) 1.5 pi L;
- direct beam under a random leaf cloud: exp(-G LAI / sin e), G = 0.5 for spherical leaf
  angles (and the exact G of the leaves generated).
"""
import datetime as dt
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (variant, plugins)
import mitsuba as mi

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.light import sensors as S
from mitsuba_veg.light import sensor_study as SS
from mitsuba_veg.light import validation as V
from mitsuba_veg.light.photon import BANDS

ROOT = Path(__file__).resolve().parent.parent
PAR_NM = BANDS["par"][1] - BANDS["par"][0]


def _sun_scene(elevation, ground_albedo=0.0, half=2.0):
    gv, gf = V.grid_mesh(4, 4, x=(-half, half), z=(-half, half))
    sun = V.sun_vector(elevation)
    return mi.load_dict({
        "type": "scene", "ground": V.make_mesh("ground", gv, gf, ground_albedo),
        "sun": {"type": "directional", "direction": (-sun).tolist(),
                "irradiance": {"type": "uniform", "value": 1.0}}}, optimize=False)


def _trio(y=0.5, size=0.5):
    return (S.point("cos", (-0.8, y, 0), size=size)
            + S.point("sph", (0.0, y, 0), kind="spherical", size=size)
            + S.point("dome", (0.8, y, 0), kind="hemispherical", size=size))


def test_templates_have_the_ideal_angular_response():
    """Geometry only: projected area / normalising area vs cos θ, (1 + cos θ)/2, 1 over 300
    random directions and tilted axes. The UV sphere's faceting (10 x 20) costs < 1 % of the
    on-axis response."""
    rng = np.random.default_rng(7)
    dirs = rng.normal(size=(300, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    axis = np.array([0.3, 0.9, -0.2]) / np.linalg.norm([0.3, 0.9, -0.2])
    worst = {}
    for kind in S.KINDS:
        for s in dirs:
            c = float(s @ axis)
            ideal = {"cosine": max(c, 0.0), "hemispherical": (1 + c) / 2, "spherical": 1.0}[kind]
            p, a = S.projected_area(kind, s, size=0.3, normal=axis)
            worst[kind] = max(worst.get(kind, 0.0), abs(p / a - ideal))
    assert worst["cosine"] < 1e-9
    assert worst["hemispherical"] < 0.01 and worst["spherical"] < 0.01, worst
    assert worst["spherical"] > 1e-4        # the faceting is real: the check can fail
    # a sensor facing down sees nothing of a sun above
    assert S.projected_area("cosine", V.sun_vector(40.0), normal=(0, -1, 0))[0] == 0


def test_sensor_meshes_use_the_one_triangle_helper():
    """meshes.triangle_geometry, the triangle helper of the sensors and the photon pass: a
    known triangle, a degenerate one (zero normal); the sphere template's faces point outwards
    and its area is the 1 m sphere's pi m2 less the faceting."""
    from mitsuba_veg.meshes import triangle_geometry
    a, n, c = triangle_geometry([[0, 0, 0], [2, 0, 0], [0, 0, -1], [1, 0, 0]],
                                [[0, 1, 2], [0, 1, 3]])
    np.testing.assert_allclose(a, [1.0, 0.0])
    np.testing.assert_allclose(n, [[0, 1, 0], [0, 0, 0]])
    np.testing.assert_allclose(c[0], [2 / 3, 0, -1 / 3])
    v, f, _ = S._sphere_template()
    area, nrm, cen = triangle_geometry(v, f)
    assert np.all(np.einsum("ij,ij->i", nrm, cen) > 0)
    assert 0.97 * math.pi < area.sum() < math.pi
    assert S._template(2)[2] == pytest.approx(area.sum() / 4.0, rel=1e-12)


@pytest.mark.parametrize("elevation", [20.0, 45.0, 70.0])
def test_open_sensors_match_flat_ground_and_cosine_spherical_ratio(elevation):
    """Open sky, directional sun (1 W m-2 nm-1 normal): cosine = flat-ground irradiance =
    E sin e, spherical = E, dome = E (1 + sin e)/2, cosine / spherical = sin e. 0.5 m sensors
    get ~20,000 photons of 1,000,000 on 16 m2 (jittered-grid origins): 2 % tolerance."""
    scene = _sun_scene(elevation)
    r = S.read(scene, _trio(), photons=1_000_000, seed=4)
    E = PAR_NM                                    # PAR band of a 1 W m-2 nm-1 flat sun [W m-2]
    s = math.sin(math.radians(elevation))
    ground = r.result.irradiance("ground", "par", "direct").mean()
    assert ground == pytest.approx(E * s, rel=0.005)
    w = r.watts[:, 0, 0]                          # direct PAR [W m-2]
    assert w[0] == pytest.approx(ground, rel=0.02)
    assert w[1] == pytest.approx(E, rel=0.02)
    assert w[2] == pytest.approx(E * (1 + s) / 2, rel=0.02)
    assert w[0] / w[1] == pytest.approx(s, rel=0.03)
    assert np.all(r.watts[:, 1] == 0)            # black ground, no sky: nothing diffuse
    # the photon units: PPFD = W x (550 nm photons per joule) of the one source
    from mitsuba_veg.units import umol_per_joule
    assert r.value("cos", "par", "direct") == pytest.approx(w[0] * umol_per_joule(400, 700))
    assert r.value("cos", "rfr") == pytest.approx(660.0 / 730.0, rel=0.02)  # flat in energy


def test_sensors_cast_no_shadow_and_see_the_ground_below():
    """A grey ground (albedo 0.3) under the sensors: the ground's own light is unchanged by
    them, and a sensor facing down reads about rho E sin e (diffuse)."""
    scene = _sun_scene(50.0, ground_albedo=0.3, half=6.0)
    down = S.point("down", (0, 0.3, 0), normal=(0, -1, 0), size=0.5)
    r = S.read(scene, _trio(y=0.3) + down, photons=1_000_000, seed=2)
    bare = mv.light.photon_irradiance(scene, photons=1_000_000, seed=2, bands=S.PASS_BANDS)
    g1 = r.result.irradiance("ground", "par", "direct").mean()
    assert g1 == pytest.approx(bare.irradiance("ground", "par", "direct").mean(), rel=1e-3)
    e = PAR_NM * math.sin(math.radians(50.0))      # the ground's direct PAR [W m-2]
    # view factor of the 12 m x 12 m ground from 0.3 m above its centre: 0.998
    down_w = r.watts[r.sensors.index("down"), 1, 0]  # diffuse PAR [W m-2]
    assert down_w == pytest.approx(0.3 * e * 0.998, rel=0.05)
    assert r.value("down", "par", "diffuse") / r.value("cos", "par", "direct") == \
        pytest.approx(0.3, rel=0.05)
    assert r.watts[r.sensors.index("down"), 0, 0] == 0


def test_uniform_sky_spherical_reads_twice_cosine():
    """Uniform sky (horizontal 1 W m-2 nm-1, nothing below the horizon): cosine pi L, dome
    1.5 pi L, spherical 2 pi L. 0.5 m sensors alone in the scene get all 1,000,000 photons."""
    scene = mi.load_dict({"type": "scene", "sky": {
        "type": "veg_sky", "distribution": "uniform",
        "radiance": {"type": "uniform", "value": 1.0 / math.pi}}})
    r = S.read(scene, _trio(), photons=1_000_000, seed=1)
    w = r.watts[:, 1, 0]                          # diffuse PAR [W m-2]
    assert w[0] == pytest.approx(PAR_NM, rel=0.02)
    assert w[2] / w[0] == pytest.approx(1.5, rel=0.02)
    assert w[1] / w[0] == pytest.approx(2.0, rel=0.02)
    assert np.all(r.watts[:, 0] == 0)            # a sky is not a beam


@pytest.mark.parametrize("elevation", [90.0, 55.0])
def test_beer_lambert_under_a_leaf_cloud(elevation):
    """Cosine sensors 0.5 m under a 4 m x 4 m slab of random green leaves (LAI 2,
    spherical angles): mean direct reading / open = exp(-G LAI / sin e), within 5 % of G = 0.5
    and of the exact G of the generated leaves."""
    from mitsuba_veg.foliage.canopy import random_leaf_cloud
    from mitsuba_veg.foliage.light_study import tree_scene

    lai = 2.0
    leaves = random_leaf_cloud(lai, (-2, 1.0, -2), (2, 1.5, 2), leaf_size=0.05, seed=3)
    sun = V.sun_vector(elevation)
    em = {"sun": {"type": "directional", "direction": (-sun).tolist(),
                  "irradiance": {"type": "uniform", "value": 1.0}}}
    scene, _ = tree_scene(leaves, emitters=em, ground=False)
    sensors = S.grid("under", (-1, 0.5, -1), (0, 0, 2), (2, 0, 0), 0.25, size=0.2)
    assert len(sensors) == 64 and np.allclose(sensors.normal, [0, 1, 0])
    r = S.read(scene, sensors, photons=1_000_000, seed=5)
    s = math.sin(math.radians(elevation))
    transmitted = r.watts[:, 0, 0].mean() / (PAR_NM * s)
    # exact G of these leaves: mean projection of their areas on the sun direction
    n = leaves.normal / np.linalg.norm(leaves.normal, axis=1, keepdims=True)
    G = float(np.mean(np.abs(n @ sun)))
    assert G == pytest.approx(0.5, abs=0.01)
    assert transmitted == pytest.approx(math.exp(-G * lai / s), rel=0.05)
    assert transmitted == pytest.approx(math.exp(-0.5 * lai / s), rel=0.05)


# --------------------------------------------------------------------------------------------
# scenario fields
# --------------------------------------------------------------------------------------------
def _scenario(tmp_path, sensors_toml, name="s.toml"):
    gv, gf = V.grid_mesh(4, 4, x=(-1, 1), z=(-1, 1))
    lines = ["v %g %g %g" % tuple(p) for p in gv] + ["f %d %d %d" % tuple(f + 1) for f in gf]
    (tmp_path / "ground.obj").write_text("\n".join(lines) + "\n")
    bv, bf = V.box_mesh((-1.0, 0.0, -1.2), (1.0, 1.0, -1.0))
    lines = ["v %g %g %g" % tuple(p) for p in bv] + ["f %d %d %d" % tuple(f + 1) for f in bf]
    (tmp_path / "wall.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "scene.xml").write_text(
        '<scene version="3.0.0">\n'
        '<shape type="obj" id="ground"><string name="filename" value="ground.obj"/>'
        '<bsdf type="diffuse"><spectrum name="reflectance" value="0.2"/></bsdf></shape>\n'
        '<shape type="obj" id="wall"><string name="filename" value="wall.obj"/>'
        '<bsdf type="diffuse"><spectrum name="reflectance" value="0.3"/></bsdf></shape>\n'
        '</scene>\n')
    p = tmp_path / name
    p.write_text('[scene]\nfile = "scene.xml"\n[site]\nlatitude = 35.0\nlongitude = 139.0\n'
                 'timezone = 9.0\n[terrain]\nground = "ground"\n' + sensors_toml)
    return p


GOOD = '''
[[sensors]]
name = "open"
position = [0.5, 0.5, 0.5]
size = 0.4
[[sensors]]
name = "fluence"
kind = "spherical"
position = [0.5, 0.5, -0.5]
size = 0.4
[[sensors]]
name = "bed"
layout = "ground_grid"
spacing = 0.5
height = 0.3
size = 0.3
'''


def test_scenario_sensors_are_built_and_wrong_fields_refused(tmp_path):
    from mitsuba_veg.scenario import load_scenario

    scn = load_scenario(_scenario(tmp_path, GOOD))
    s = S.from_scenario(scn, scn.load_scene(daylight=False))
    assert list(s.names[:2]) == ["open", "fluence"] and len(s) == 2 + 16
    assert s.groups == ["open", "fluence", "bed"]
    assert np.allclose(s.position[2:, 1], 0.3, atol=1e-5)   # flat ground at y = 0
    bad = [('[[sensors]]\nname = "a"\nposition = [0, 1, 0]\ncolour = "red"\n',
            "sensors.colour"),
           ('[[sensors]]\nname = "a"\nposition = [0, 1, 0]\nsize = 50.0\n', "sensors.size"),
           ('[[sensors]]\nname = "a"\nkind = "conical"\nposition = [0, 1, 0]\n',
            "sensors.kind"),
           ('[[sensors]]\nname = "a"\nposition = [0, 1]\n', "sensors.position")]
    for text, field in bad:
        with pytest.raises(ParameterError) as e:
            load_scenario(_scenario(tmp_path, text, "bad.toml"))
        assert field in str(e.value) and "allowed" in str(e.value)
    semantic = [('[[sensors]]\nname = "a"\n', "sensors[0].position"),
                ('[[sensors]]\nname = "a"\nposition = [0, 1, 0]\nspacing = 0.5\n',
                 "sensors[0].spacing"),
                ('[[sensors]]\nname = "g"\nlayout = "ground_grid"\nspacing = 0.00001\n',
                 "sensors.spacing"),
                ('[[sensors]]\nname = "g"\nlayout = "ground_grid"\nspacing = 0.002\n',
                 "sensors[0].spacing"),
                ('[[sensors]]\nname = "a"\nposition = [0, 1, 0]\nnormal = [0, 0, 0]\n',
                 "sensors[0].normal")]
    for text, field in semantic:
        with pytest.raises(ParameterError) as e:
            scn = load_scenario(_scenario(tmp_path, text, "bad.toml"))
            S.from_scenario(scn, scn.load_scene(daylight=False))
        assert field in str(e.value), str(e.value)


# --------------------------------------------------------------------------------------------
# time series
# --------------------------------------------------------------------------------------------
def test_series_open_sensor_matches_spctral2_and_hourly_adds_up_to_daily():
    """An open horizontal sensor's daily DLI = the SPCTRAL2 open-sky DLI (direct and diffuse),
    and 24 hourly steps give the daily step's DLI; the DLI is mean PPFD x 86400 s / 1e6."""
    gv, gf = V.grid_mesh(2, 2, x=(-2, 2), z=(-2, 2))
    scene = mi.load_dict({"type": "scene", "ground": V.make_mesh("ground", gv, gf, 0.0)},
                         optimize=False)
    sensors = S.point("open", (0, 0.5, 0), size=1.0)
    kw = dict(latitude=35.0, longitude=139.0, timezone=9.0, start=dt.date(2026, 6, 21),
              end=dt.date(2026, 6, 21), photons=400_000, sky_photons=2_000_000)
    d = SS.run_series(scene, sensors, step="daily", **kw)
    h = SS.run_series(scene, sensors, step="hourly", **kw)
    days, dli, odli = SS.daily_light_integral(d)
    _, hdli, hodli = SS.daily_light_integral(h)
    assert dli[0, 0, 2] == pytest.approx(d.values[0, 0, 0, 2] * 86400e-6)
    assert odli[0, 2] == pytest.approx(hodli[0, 2], rel=0.002)      # same sun, 10-min steps
    assert 55 < odli[0, 2] < 70                                     # clear June day at 35 N
    for c in range(3):
        assert dli[0, 0, c] == pytest.approx(odli[0, c], rel=0.03), c
        assert hdli[0, 0, c] == pytest.approx(odli[0, c], rel=0.03), c
    hdays, hours = SS.hours_above(h, 200.0)
    assert hours[0, 0] == np.sum(h.values[:, 0, 0, 2] > 200.0) and 8 <= hours[0, 0] <= 14
    assert h.values[:3, 0, 0, 2].max() == 0                         # night


def test_cli_year_writes_the_table_dli_and_figures(tmp_path):
    """`light-study SCENARIO --year` on a tiny scenario at few photons: the tidy table has one
    row per day x sensor x band x component, dli.csv one per day x sensor, the figures exist."""
    import pandas as pd

    sc = _scenario(tmp_path, GOOD)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "mitsuba_veg.cli", "light-study", str(sc), "--year", "2025",
           "--photons", "3000", "--sky-photons", "30000", "--heatmap-every", "120",
           "--out", str(out), "--quiet"]
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    n = 18
    t = pd.read_parquet(out / "sensors.parquet")
    assert list(t.columns) == ["time", "sensor", "band", "component", "value", "unit"]
    assert len(t) == 365 * n * 5 * 3
    assert set(t["band"]) == {"par", "red", "far_red", "rfr", "shortwave"}
    c = pd.read_csv(out / "sensors.csv")
    assert len(c) == len(t) and c["time"].iloc[0] == "2025-01-01T00:00:00+09:00"
    assert np.allclose(c["value"], t["value"], rtol=1e-5, equal_nan=True)
    dli = pd.read_csv(out / "dli.csv")
    assert len(dli) == 365 * n
    # hours above the threshold on the 4 heat-map days (1 Jan + every 120 days) only
    assert dli["hours_above_threshold"].notna().sum() == 4 * n
    s = json.loads((out / "summary.json").read_text())
    assert s["period"]["days"] == 365 and s["passes"]["sun"] >= 365
    open_dli = dli.groupby("date")["open_dli_mol_m2_d"].first()
    assert 20 < open_dli.min() < open_dli.max() < 70
    for f in ("dli_map.png", "rfr_map.png", "sensor_year.png", "heatmap.png"):
        assert (out / f).stat().st_size > 10_000, f
    h = pd.read_parquet(out / "sensors_hourly.parquet")
    assert set(h["sensor"]) == {"open", "fluence"} and len(h) == 4 * 24 * 2 * 15


@pytest.mark.slow
def test_cli_series_refusals(tmp_path):
    sc = _scenario(tmp_path, "")
    base = [sys.executable, "-m", "mitsuba_veg.cli", "light-study", str(sc), "--out",
            str(tmp_path / "o"), "--quiet"]
    for extra, word in ((["--year", "2025"], "sensors"),
                        (["--from", "2025-06-02", "--to", "2025-06-01"], "--to"),
                        (["--from", "2025-06-01"], "--from/--to"),
                        (["--from", "June", "--to", "2025-06-01"], "--from")):
        p = subprocess.run(base + extra, capture_output=True, text=True, cwd=ROOT, timeout=120)
        assert p.returncode != 0 and word in p.stderr, p.stderr[-600:]
        assert "Traceback" not in p.stderr


def test_single_time_light_study_reads_the_scenario_sensors(tmp_path):
    """`light-study SCENARIO --when ...` reads [[sensors]] in its one pass: sensors.csv holds
    one row per sensor x band x component; the open cosine sensor's PPFD is within 5 % of the
    SPCTRAL2 open-sky PPFD (sun + sky; walls and a 0.2-albedo ground add a little)."""
    import pandas as pd

    from mitsuba_veg.foliage.light_study import run_light_study

    sc = _scenario(tmp_path, GOOD)
    s = run_light_study(sc, tmp_path / "o", photons=400_000, when="2026-06-21T12:00:00+09:00")
    t = pd.read_csv(tmp_path / "o" / "sensors.csv")
    assert list(t.columns) == ["time", "sensor", "band", "component", "value", "unit"]
    assert len(t) == 18 * 5 * 3
    assert s["sensors"]["open"]["ppfd"] == pytest.approx(s["open"]["ppfd"], rel=0.05)
    assert s["sensors"]["fluence"]["ppfd"] > s["sensors"]["open"]["ppfd"]
