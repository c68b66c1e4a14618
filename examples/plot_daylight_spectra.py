"""
Clear-sky daylight spectra and their red:far-red ratio
======================================================

SPCTRAL2 (Bird & Riordan 1984, through pvlib) gives the beam and diffuse spectra of a clear
day; the package resamples them to 1 nm and turns them into Mitsuba emitters
(:func:`mitsuba_veg.light.clear_sky.clear_sky_spectra`). Plants sense the photon ratio of red
(655-665 nm) to far-red (725-735 nm): about 1.15 in open daylight, lower in leaf shade.
"""
import matplotlib.pyplot as plt
import numpy as np

from mitsuba_veg.light.clear_sky import clear_sky_spectra, red_far_red_ratio

fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.5))
for elevation in (20, 45, 70):
    wl, dni, dhi = clear_sky_spectra(float(elevation), wavelength_range=(300.0, 1000.0))
    ghi = dni * np.sin(np.radians(elevation)) + dhi
    ax.plot(wl, ghi, label=f"sun at {elevation}°")
    print(f"elevation {elevation}°: R:FR global {red_far_red_ratio(wl, ghi):.3f}, "
          f"beam {red_far_red_ratio(wl, dni):.3f}, sky {red_far_red_ratio(wl, dhi):.3f}")
ax.axvspan(655, 665, color="red", alpha=0.2)
ax.axvspan(725, 735, color="darkred", alpha=0.2)
ax.set_xlabel("wavelength [nm]")
ax.set_ylabel("global horizontal [W m-2 nm-1]")
ax.legend()

els = np.linspace(5, 85, 17)
rfr = []
for e in els:
    wl, dni, dhi = clear_sky_spectra(float(e), wavelength_range=(600.0, 800.0))
    rfr.append(red_far_red_ratio(wl, dni * np.sin(np.radians(e)) + dhi))
bx.plot(els, rfr, "o-")
bx.set_xlabel("sun elevation [deg]")
bx.set_ylabel("red : far-red (photons)")
fig.tight_layout()
