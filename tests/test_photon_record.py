"""Recording a subset of the shapes (``trace(..., record=...)``): the photons see every shape,
only the recorded shapes' flux is kept (a smaller accumulator and read-back)."""
import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers plugins)
import mitsuba as mi

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.light import validation as V
from mitsuba_veg.light.photon import integrator


def _scene():
    gv, gf = V.grid_mesh(6, 6, x=(-2.0, 2.0), z=(-2.0, 2.0))
    sv, sf = V.grid_mesh(3, 3, x=(-0.5, 0.5), z=(-0.5, 0.5), y=0.5)
    sun = V.sun_vector(55.0)
    return mi.load_dict({
        "type": "scene", "ground": V.make_mesh("ground", gv, gf, 0.3),
        "panel": V.make_mesh("panel", sv, sf, 0.5),
        "sun": {"type": "directional", "direction": (-sun).tolist(),
                "irradiance": {"type": "uniform", "value": 1.0}},
        "sky": {"type": "constant", "radiance": {"type": "uniform", "value": 0.1}}},
        optimize=False)


def test_recorded_shapes_get_the_same_flux_as_a_full_pass():
    scene = _scene()
    integ = integrator(photons=200_000, seed=4, bands=("total", "par"))
    full = integ.trace(scene)
    part = integ.trace(scene, record=["ground"])
    n_ground = 72
    assert part.flux.shape[1] == n_ground and full.flux.shape[1] == n_ground + 18
    # the same photons, the same records: bit for bit
    assert np.array_equal(part.shape_flux("ground"), full.shape_flux("ground"))
    assert np.array_equal(part.irradiance("ground", "par"), full.irradiance("ground", "par"))
    e = part.element_irradiance("total")
    assert np.array_equal(e[:n_ground], full.element_irradiance("total")[:n_ground])
    assert np.all(e[n_ground:] == 0) and np.any(full.element_irradiance("total")[n_ground:] > 0)
    t = part.tensor()
    assert t.shape == full.tensor().shape and np.all(t[n_ground:] == 0)
    # the panel still casts its shadow and reflects: bookkeeping identical
    assert np.array_equal(part.absorbed, full.absorbed)
    with pytest.raises(ParameterError, match="record"):
        part.irradiance("panel")
    with pytest.raises(Exception):
        integ.trace(scene, record=["no_such_shape"])
