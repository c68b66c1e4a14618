"""
The sun's path through the year
===============================

The sun's elevation over the day at 48° N on the solstices and an equinox, from the package's
NREL SPA (:func:`mitsuba_veg.light.sun_position`, checked against the SPA report's worked
example and pvlib). Times are UTC; Munich's local noon is near 11:14 UTC.
"""
import matplotlib.pyplot as plt
import numpy as np

import mitsuba_veg as mv

fig, ax = plt.subplots(figsize=(7, 3.5))
for day in ("2026-06-21", "2026-03-20", "2026-12-21"):
    times = np.arange(f"{day}T00:00", f"{day}T23:59", np.timedelta64(10, "m"),
                      dtype="datetime64[m]")
    az, el = mv.light.sun_position(48.14, 11.58, times)
    hours = (times - times[0]) / np.timedelta64(1, "h")
    ax.plot(hours, el, label=day)
    print(f"{day}: highest {np.max(el):.1f}° at azimuth {az[np.argmax(el)]:.0f}°")
ax.axhline(0, color="grey", lw=0.5)
ax.set_xlabel("hour [UTC]")
ax.set_ylabel("sun elevation [deg]")
ax.set_ylim(-70, 70)
ax.legend()
fig.tight_layout()
