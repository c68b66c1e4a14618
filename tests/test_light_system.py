"""System tests of the light stack: daylight through the photon pass, the CLI, scenarios and
the variant selection."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv
import drjit as dr
import mitsuba as mi

from mitsuba_veg.errors import ParameterError, VariantError
from mitsuba_veg.light import photon_irradiance, daylight_from_angles
from mitsuba_veg.light import validation as V

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def open_ground(elevation, azimuth=180.0):
    gv, gf = V.grid_mesh(4, 4, x=(-5, 5), z=(-5, 5))
    d = {"type": "scene", "ground": V.make_mesh("ground", gv, gf, 0.2)}
    d.update(daylight_from_angles(azimuth, elevation))
    return mi.load_dict(d, optimize=False)


@pytest.mark.parametrize("elevation", [30.0, 60.0])
def test_open_daylight_red_far_red_through_photon_pass(elevation):
    """Open daylight on flat ground: R:FR (photon ratio) 1.1-1.2 (field value ~1.15)."""
    res = photon_irradiance(open_ground(elevation), photons=1_000_000, seed=1)
    area = res.index.areas
    r = (res.photon_flux_density("ground", "red") * area).sum()
    fr = (res.photon_flux_density("ground", "far_red") * area).sum()
    assert 1.1 <= r / fr <= 1.2
    rfr = res.red_far_red("ground")
    assert np.all((rfr > 1.05) & (rfr < 1.25))
    # the photon pass reproduces the spectra's own horizontal band irradiance
    from mitsuba_veg.light.clear_sky import clear_sky_spectra, band_irradiance
    wl, dni, dhi = clear_sky_spectra(elevation)
    ghi = dni * np.sin(np.radians(elevation)) + dhi
    par = (res.irradiance("ground", "par") * area).sum() / area.sum()
    assert par == pytest.approx(band_irradiance(wl, ghi, 400, 700), rel=0.01)


def test_sky_and_sun_components_are_separable():
    scene = open_ground(45.0)
    res = photon_irradiance(scene, photons=400_000, seed=2)
    sun = res.irradiance("ground", "par", emitter="sun").mean()
    sky = res.irradiance("ground", "par", emitter="sky").mean()
    both = res.irradiance("ground", "par").mean()
    assert both == pytest.approx(sun + sky, rel=1e-9)
    assert 0.05 < sky / both < 0.4
    with pytest.raises(ParameterError, match="emitter"):
        res.irradiance("ground", emitter="moon")


def test_scenario_load_validation_and_overrides(tmp_path):
    scn = mv.scenario.load_scenario(SCENARIO, ["light.photons=2000", "light.indirect=false"])
    assert scn.get("light.photons") == 2000 and scn.get("light.indirect") is False
    scene = scn.load_scene()
    assert {s.id() for s in scene.shapes()} == {"ground", "roof", "wall"}
    with pytest.raises(ParameterError, match=r"light\.photons = -5.*allowed"):
        mv.scenario.load_scenario(SCENARIO, ["light.photons=-5"])
    with pytest.raises(ParameterError, match=r"site\.latitude"):
        mv.scenario.load_scenario(SCENARIO, ["site.latitude=95"])
    bad = tmp_path / "s.toml"
    bad.write_text('[scene]\nfile = "missing.xml"\n')
    with pytest.raises(ParameterError, match=r"scene\.file.*missing\.xml"):
        mv.scenario.load_scenario(bad).load_scene()
    # daylight replaces the scene's emitters when light.when is set
    day = mv.scenario.load_scenario(SCENARIO, ['light.when="2026-06-21T12:00:00+09:00"'])
    sc = day.load_scene()
    assert {e.id() for e in sc.emitters()} == {"sun", "sky"}
    night = mv.scenario.load_scenario(SCENARIO, ['light.when="2026-06-21T00:00:00+09:00"'])
    with pytest.raises(ParameterError, match="above the horizon"):
        night.load_scene()


def test_cli_irradiance_writes_arrays_maps_and_summary(tmp_path):
    out = tmp_path / "irr"
    cmd = [sys.executable, "-m", "mitsuba_veg.cli", "irradiance", str(SCENARIO), "--photons",
           "200000", "--out", str(out), "--quiet", "--set", "light.seed=3"]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "wrote:" in p.stdout
    data = np.load(out / "irradiance.npz")
    assert data["ground/total/total"].shape == (3200,)
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["photons"] == 200000 and s["settings"]["seed"] == 3
    assert s["regions"]["under_roof"]["total.mean_W_m2"] < 0.3 * s["regions"]["open"]["total.mean_W_m2"]
    for sid in ("ground", "roof", "wall"):
        png = out / f"irradiance_{sid}.png"
        assert png.stat().st_size > 10_000
    # a bad value: one clear message, exit code 2, no traceback
    p = subprocess.run(cmd[:-2] + ["--set", "light.max_depth=0"], capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 2
    assert "light.max_depth = 0" in p.stderr and "Traceback" not in p.stderr


def test_variant_is_spectral_and_rgb_is_refused():
    assert mi.variant() in ("llvm_ad_spectral", "cuda_ad_spectral")
    code = ("import mitsuba as mi; mi.set_variant('scalar_rgb');\n"
            "try:\n import mitsuba_veg\nexcept Exception as e:\n print(type(e).__name__, e)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "VariantError" in p.stdout and "scalar_rgb" in p.stdout and "llvm_ad_spectral" in p.stdout
    assert issubclass(VariantError, RuntimeError)


def test_plugins_load_from_xml_after_import():
    """The integrator and the sky from a scene file: properties as XML tags, the sky's spectrum
    as a scene file writes it (one value, or wavelength:value pairs), read as given."""
    scene = mi.load_string("""<scene version="3.0.0">
        <integrator type="veg_photon_irradiance"><integer name="photons" value="1000"/>
        </integrator>
        <emitter type="veg_sky"><string name="distribution" value="uniform"/>
            <spectrum name="radiance" value="400:1, 700:2"/></emitter>
        <shape type="rectangle"/></scene>""")
    integ = scene.integrator()
    assert "PhotonIrradianceIntegrator" in str(integ) and integ.photons == 1000
    sky = scene.emitters()[0]
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum(400.0, 550.0, 650.0, 700.0)
    np.testing.assert_allclose(np.asarray(sky.m_radiance.eval(si)).ravel(),
                               [1.0, 1.5, 1.0 + 250.0 / 300.0, 2.0], rtol=1e-6)
    one = mi.load_string('<emitter version="3.0.0" type="veg_sky"><spectrum name="irradiance" '
                         'value="2.0"/></emitter>')
    assert one.spectrum_key == "irradiance"
    np.testing.assert_allclose(np.asarray(one.m_radiance.eval(si)).ravel(), 2.0)


def test_veg_sky_traverse_names_its_spectrum():
    """A value set through mi.traverse means what its name says: radiance or irradiance."""
    import mitsuba as mi
    for key in ("radiance", "irradiance"):
        sky = mi.load_dict({"type": "veg_sky", key: {"type": "uniform", "value": 1.0},
                            "sun_direction": [0.0, 1.0, 0.0]})
        names = list(mi.traverse(sky).keys())
        assert any(n.startswith(key + ".") for n in names), names
        other = "irradiance" if key == "radiance" else "radiance"
        assert not any(n.startswith(other + ".") for n in names), names


def test_daylight_keeps_unnamed_shapes_and_sensors(tmp_path):
    """Objects without an id all survive the daylight swap (none overwrites another)."""
    (tmp_path / "scene.xml").write_text(
        '<scene version="3.0.0">'
        '<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>'
        '</transform></shape>'
        '<shape type="rectangle"><transform name="to_world"><translate y="1"/></transform>'
        '</shape>'
        + ''.join('<sensor type="perspective"><transform name="to_world"><lookat origin="0,%d,0" '
                  'target="0,0,0" up="0,0,1"/></transform></sensor>' % h for h in (5, 6))
        + '</scene>')
    (tmp_path / "scenario.toml").write_text(
        '[scene]\nfile = "scene.xml"\n[site]\nlatitude = 35.0\nlongitude = 139.0\n'
        '[light]\nwhen = "2026-06-21T12:00:00+09:00"\n')
    sc = mv.scenario.load_scenario(tmp_path / "scenario.toml").load_scene()
    assert len(sc.shapes()) == 2 and len(sc.sensors()) == 2
    assert {e.id() for e in sc.emitters()} == {"sun", "sky"}
