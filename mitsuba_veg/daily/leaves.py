"""The leaves stage of a day: phenology (paper 003's autumn clock, leaf-out, leaf fall) and the
canopy's tables for the photon pass, on the device.

Before the pass (:meth:`DayLeaves.start`): leaf-out for the date, then the canopy's stage bins
and shown/hidden state (and, on a few days a year, its blades' vertices); the leaf triangles'
mode and BSDF tables for the pass. After it (:meth:`DayLeaves.end`): each leaf's insolation of
the day (the pass's S_leaf [W m-2] x 86 400 s) advances its autumn clock and leaf fall.

The state (:class:`~mitsuba_veg.world.phenology.Phenology`, the canopy's blades) is Dr.Jit
arrays; one day reads back three counts (whether the leaf mesh moves today).
"""
from __future__ import annotations

import numpy as np

from ..world.canopy import Canopy
from ..world.phenology import Phenology


__all__ = ["DayLeaves"]

class DayLeaves:
    """The leaves stage (module docstring).

    Parameters
    ----------
    site : Site
        The run's site (its canopy and trees).
    """

    def __init__(self, site):
        self.site = site
        self.canopy: Canopy = site.canopy
        cfg = site.config
        c = self.canopy
        # sunnier (higher, outer) leaves unfold a few days earlier
        shift = np.zeros(c.n_leaves)
        for t_i, _ in enumerate(site.trees):
            m = c.leaves_of(t_i)
            if m.stop > m.start:
                p = c.centre[m]
                h = (p[:, 1] - p[:, 1].min()) / max(float(np.ptp(p[:, 1])), 1e-9)
                shift[m] = -4.0 * h
        self.params = cfg.phenology
        self.shift = shift
        self.seed = int(cfg.seed)

    def new_state(self) -> Phenology:
        """The leaves before the first day (bare).

        Returns
        -------
        Phenology
            Every leaf not yet out.
        """
        return Phenology(self.canopy.n_leaves, self.params, seed=self.seed,
                         leaf_out_shift=self.shift)

    def start(self, ph: Phenology, date, scene_params):
        """Leaf-out for ``date``, the canopy's state and the pass's leaf tables.

        Parameters
        ----------
        ph : Phenology
            The leaves (updated in place).
        date : datetime.date
            The day.
        scene_params : mi.SceneParameters
            ``mi.traverse`` of the light scene (the blades' vertices).

        Returns
        -------
        callable or None
            :meth:`Canopy.trace_tables`: (modes, BSDF registry ids) of leaf triangles, on the
            device (None when the canopy has no stage optics).
        """
        # the phenology's state and the canopy's tables in one kernel
        ph.start_of_day(date, evaluate=False)
        self.canopy.update(scene_params, ph.tau, ph.grown, ph.on_tree, also=ph.arrays())
        # a function of the triangles: the light stage computes the tables in the kernel that
        # writes them into the pass's tables
        return self.canopy.trace_tables if self.canopy.stage_bsdfs else None

    def end(self, ph: Phenology, date, S_leaf) -> None:
        """The day's insolation advances the autumn clock (paper 003 §3.3) and leaf fall.

        Parameters
        ----------
        ph : Phenology
            The leaves (updated in place, one kernel).
        date : datetime.date
            The day.
        S_leaf : mi.Float64
            The leaves' insolation of the day [W m-2].
        """
        ph.end_of_day(date, S_leaf * (86400.0 / 1e6))
