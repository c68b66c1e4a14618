"""
Light on the moss garden's floor
================================

One photon pass (:func:`mitsuba_veg.light.photon_irradiance`) over paper 000's test scene:
the ground under the roof gets only light reflected by the wall and the roof's underside. Each
triangle's direct and indirect PAR is drawn from above with :func:`mitsuba_veg.plots.plan_map`.
"""
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import mitsuba as mi
import mitsuba_veg as mv
from mitsuba_veg.plots import plan_map

# the repository's scenes/ folder (the package's source tree sits beside it)
scenes = Path(mv.__file__).resolve().parents[1] / "scenes"
scene = mi.load_file(str(scenes / "moss_garden" / "scene.xml"), optimize=False)
res = mv.light.photon_irradiance(scene, photons=1_000_000, seed=0)
ground = next(s for s in scene.shapes() if s.id() == "ground")
V = np.array(ground.vertex_positions_buffer()).reshape(-1, 3)
F = np.array(ground.faces_buffer()).reshape(-1, 3)
fig, axes = plt.subplots(1, 2, figsize=(9, 4))
for ax, comp in zip(axes, ("direct", "indirect")):
    E = res.irradiance("ground", band="par", component=comp)
    plan_map(ax, V, F, E, title=f"{comp} PAR", label="W m-2")
    print(f"{comp}: mean {E.mean():.2f} W m-2, max {E.max():.2f}")
fig.tight_layout()
