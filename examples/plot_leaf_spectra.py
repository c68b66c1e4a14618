"""
Leaf optics through the autumn stages
=====================================

PROSPECT-D (Féret et al. 2017) reflectance and transmittance of a maple leaf at Ishikura's seven
autumn stages (paper 003), from the package's pigment table
(:func:`mitsuba_veg.foliage.leaf_spectra`), and the leaf's colour under D65. As chlorophyll
breaks down and anthocyanin rises, red light is reflected and transmitted more: autumn crowns
pass more red and cast a weaker shade signal.
"""
import matplotlib.pyplot as plt
import numpy as np

import mitsuba_veg as mv
from mitsuba_veg.foliage.spectra import spectrum_to_srgb

fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.5))
colours = []
for stage in range(1, 8):
    sp = mv.foliage.leaf_spectra(stage=stage)
    rgb = spectrum_to_srgb(sp.wavelength, sp.reflectance, exposure=4.0)
    colours.append(rgb)
    ax.plot(sp.wavelength, sp.reflectance, color=np.clip(rgb, 0, 1), label=f"stage {stage}")
    bx.plot(sp.wavelength, sp.transmittance, color=np.clip(rgb, 0, 1))
    R, T = sp.at([660.0, 730.0])
    print(f"stage {stage}: R 660/730 nm {R[0]:.3f}/{R[1]:.3f}, T {T[0]:.3f}/{T[1]:.3f}")
for a, name in ((ax, "reflectance"), (bx, "transmittance")):
    a.set_xlim(400, 900)
    a.set_xlabel("wavelength [nm]")
    a.set_ylabel(name)
ax.legend(fontsize=7)
fig.tight_layout()

fig2, cx = plt.subplots(figsize=(7, 1.2))
cx.imshow(np.clip(np.array(colours)[None], 0, 1), aspect="auto")
cx.set_yticks([])
cx.set_xticks(range(7), [f"stage {k}" for k in range(1, 8)])
fig2.tight_layout()
