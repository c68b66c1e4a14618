"""Scenes shared by the benchmark scripts."""
import numpy as np
import mitsuba as mi

from mitsuba_veg.light import validation as V


def garden_80k(sun_elevation=60.0):
    """~80k-triangle bumpy 2 m x 2 m terrain under a roof slab, sun + uniform sky."""
    gv, gf = V.grid_mesh(200, 200, height=lambda X, Z: 0.08 * np.sin(3 * X) * np.cos(2 * Z))
    rv, rf = V.box_mesh((-1.0, 0.7, -1.0), (1.0, 0.75, -0.1))
    sun = V.sun_vector(sun_elevation, 170.0)
    return mi.load_dict({
        "type": "scene",
        "ground": V.make_mesh("ground", gv, gf, 0.3),
        "roof": V.make_mesh("roof", rv, rf, 0.5),
        "sun": {"type": "directional", "direction": (-sun).tolist(),
                "irradiance": {"type": "uniform", "value": 1.0}},
        "sky": {"type": "constant", "radiance": {"type": "uniform", "value": 0.05}},
    }, optimize=False)
