"""
Moss fitness: the three species of paper 000
============================================

The daily fitness of a moss is a product of three bell-shaped factors of surface temperature,
surface humidity and insolation (paper 000 eqs 3.17-3.19,
:func:`mitsuba_veg.moss.fitness`), each 0.5 at the ends of the species' range and sharpened or
flattened by its tolerance n. The species' ranges are table 4.2 of the paper.
"""
import matplotlib.pyplot as plt
import numpy as np

import mitsuba_veg as mv

fig, axes = plt.subplots(1, 3, figsize=(10, 3))
for name in ("bryum_argenteum", "hypnum_plumaeforme", "polytrichum"):
    sp = mv.moss.get_species(name)
    T = np.linspace(265, 310, 200)
    rh = np.linspace(0.6, 1.4, 200)
    S = np.linspace(0, 120, 200)
    axes[0].plot(T, mv.moss.fitness(T, sp.T0, sp.T1, sp.nT), label=name)
    axes[1].plot(rh, mv.moss.fitness(rh, sp.rh0, sp.rh1, sp.nrh))
    axes[2].plot(S, mv.moss.fitness(S, sp.S0, sp.S1, sp.nS))
    print(f"{name}: T {sp.T0}-{sp.T1} K, rh {sp.rh0}-{sp.rh1}, S {sp.S0}-{sp.S1} W m-2")
for a, lab in zip(axes, ("surface temperature Ts [K]", "surface humidity rhs", "insolation S [W m-2]")):
    a.set_xlabel(lab)
    a.set_ylim(0, 1.05)
axes[0].set_ylabel("g")
axes[0].legend(fontsize=7)
fig.tight_layout()
