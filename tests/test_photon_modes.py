"""Element modes of the photon pass: sensors that record and let photons pass, hidden elements.

A sensor must measure the same light as a surface in its place would receive, and cast no
shadow; a hidden element must act as if it were not in the scene; neither absorbs anything
(energy bookkeeping stays closed)."""
import math

import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers plugins)
import mitsuba as mi

from mitsuba_veg.integrators.photon_irradiance import HIDDEN, SENSOR, SURFACE
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.light import BANDS, photon_irradiance
from mitsuba_veg.light import validation as V

NM = BANDS["total"][1] - BANDS["total"][0]
ELEV = 50.0


def _scene(ground_half=2.0, sensor_half=0.5, sensor_y=0.5, albedo=0.0, n=4):
    gv, gf = V.grid_mesh(n, n, x=(-ground_half, ground_half), z=(-ground_half, ground_half))
    sv, sf = V.grid_mesh(2, 2, x=(-sensor_half, sensor_half), z=(-sensor_half, sensor_half),
                         y=sensor_y)
    sun = V.sun_vector(ELEV)
    return mi.load_dict({
        "type": "scene", "ground": V.make_mesh("ground", gv, gf, albedo),
        "panel": V.make_mesh("panel", sv, sf, 0.0),
        "sun": {"type": "directional", "direction": (-sun).tolist(),
                "irradiance": {"type": "uniform", "value": 1.0}}}, optimize=False)


def test_sensor_records_open_light_and_casts_no_shadow():
    scene = _scene()
    expected = NM * math.sin(math.radians(ELEV))
    opaque = photon_irradiance(scene, photons=400_000, seed=2, bands=("total",))
    sensor = photon_irradiance(scene, photons=400_000, seed=2, bands=("total",),
                               modes={"panel": "sensor"})
    hidden = photon_irradiance(scene, photons=400_000, seed=2, bands=("total",),
                               modes={"panel": "hidden"})
    ground = lambda r: r.flux_of("ground", component="direct").sum()  # noqa: E731  [W]
    # the opaque panel shades 1 m2 of the 16 m2 ground; as a sensor or hidden it shades nothing
    shade = 1.0 - ground(opaque) / ground(sensor)
    assert abs(shade - 1.0 / 16.0) < 0.004
    assert ground(sensor) == pytest.approx(ground(hidden), rel=1e-6)
    assert abs(ground(sensor) / (16.0 * expected) - 1) < 0.005
    # the sensor reads the open-sky irradiance E sin(e) on both its triangles of each cell
    e = sensor.irradiance("panel", component="direct")
    assert np.all(np.abs(e / expected - 1) < 0.03)
    assert np.all(hidden.irradiance("panel") == 0)
    # nothing is absorbed by a sensor: the bookkeeping stays closed
    for r in (opaque, sensor, hidden):
        left = r.escaped.sum() + r.absorbed.sum() + r.truncated.sum()
        assert abs(left / r.emitted.sum() - 1) < 1e-4
    assert sensor.absorbed.sum() == pytest.approx(hidden.absorbed.sum(), rel=1e-6)


def test_sensor_counts_no_bounce_and_sees_indirect_light():
    """Under the sensor a reflective ground (albedo 0.3, 20 m x 20 m): the sensor's underside
    receives ~rho E sin(e) (view factor ~0.99), as indirect light after one bounce. With
    max_depth=1 nothing is indirect: crossing the sensor did not use the bounce."""
    scene = _scene(ground_half=10.0, sensor_half=1.0, sensor_y=0.5, albedo=0.3, n=2)
    r = photon_irradiance(scene, photons=2_000_000, seed=5, bands=("total",),
                          modes={"panel": "sensor"})
    e = NM * math.sin(math.radians(ELEV))
    back = r.irradiance("panel", component="indirect", side="back").mean()
    # view factor of a 20 m x 20 m square from 0.5 m above its centre (2 m x 2 m sensor): 0.98-0.99
    assert 0.95 * 0.3 * e < back < 1.02 * 0.3 * e
    one = photon_irradiance(scene, photons=200_000, seed=5, bands=("total",), max_depth=1,
                            modes={"panel": "sensor"})
    assert one.irradiance("ground", component="direct").mean() == pytest.approx(e, rel=0.02)
    assert np.all(one.irradiance("panel", component="indirect") == 0)


def test_per_triangle_modes_and_refusals():
    scene = _scene()
    n_panel = 8
    modes = np.full(n_panel, SENSOR)
    modes[:4] = HIDDEN
    r = photon_irradiance(scene, photons=200_000, seed=1, bands=("total",),
                          modes={"panel": modes, "ground": SURFACE})
    e = r.irradiance("panel", component="direct")
    assert np.all(e[:4] == 0) and np.all(e[4:] > 0)
    with pytest.raises(ParameterError, match="modes"):
        photon_irradiance(scene, photons=1000, modes={"panel": "glass"})
    with pytest.raises(ParameterError, match="modes"):
        photon_irradiance(scene, photons=1000, modes={"panel": np.full(3, SENSOR)})
    with pytest.raises(ParameterError, match="modes"):
        photon_irradiance(scene, photons=1000, modes={"panel": np.full(n_panel, 7)})
