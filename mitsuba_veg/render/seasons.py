"""Seasonal state of the render's trees: leaf-out in spring, autumn colour and leaf fall.

The moss run does not simulate trees, so a tree placed next to it (``[[render.trees]]``) gets a
simple phenology driven by the calendar and by light (documented in docs/render.md):

- **leaf-out**: leaves grow from nothing to full size between ``leaf_out`` (default day-of-year
  95, early April) and ``leaf_out + 30``: per-leaf ``leaf_scale`` (a smoothstep, 5 days earlier
  for the sunniest leaves);
- **autumn** (paper 003 through :func:`mitsuba_veg.foliage.autumn_time`): each
  leaf's logical time tau grows with its cumulative insolation from the onset day
  (``autumn_onset``, default day-of-year 258, mid-September). The daily insolation of a leaf is
  the clear-sky daily irradiation of the site (extraterrestrial irradiation x 0.55) times an
  exposure factor from its place in the crown (0.35 for inner, low leaves up to 1 for outer, top
  leaves: a proxy for the crown's self-shading, which the render does not trace);
- **leaf fall**: a leaf falls when its raw tau passes a per-leaf threshold (log-normal around
  1.25, as :class:`mitsuba_veg.foliage.AutumnParams` with ``fall=True``).

:meth:`TreeSeasons.apply` writes ``leaf_scale``, ``autumn_tau``, ``fallen`` and ``litter_age``
(days since the leaf fell, NaN before: :mod:`mitsuba_veg.render.litter` lays it on the ground)
into ``tree.leaves.attrs`` for one date; the renderer reads them.
"""
from __future__ import annotations

import datetime as _dt

import numpy as np

from ..climate import extraterrestrial_irradiation
from ..foliage import AutumnParams, autumn_time

__all__ = ["LEAF_OUT_DOY", "LEAF_OUT_DAYS", "AUTUMN_ONSET_DOY", "daily_extraterrestrial_mj",
           "leaf_exposure", "TreeSeasons"]

#: calendar phenology of decoration trees: the first day of leaf-out [day of year]
LEAF_OUT_DOY = 95
#: days from the first leaf to full leaf [d]
LEAF_OUT_DAYS = 30
#: day of year the autumn clock starts
AUTUMN_ONSET_DOY = 258


def daily_extraterrestrial_mj(latitude: float, doy) -> np.ndarray:
    """Daily extraterrestrial irradiation on a horizontal surface [MJ m-2].

    The climate's H0 (:func:`mitsuba_veg.climate.extraterrestrial_irradiation`, FAO-56 eqs
    21-25: the moss loop's model) in MJ m-2; negative values (none in practice) set to 0.

    Parameters
    ----------
    latitude : float
        Site latitude phi [degrees] (north positive).
    doy : int or array_like
        Day of the year [days] (1 = 1 January).

    Returns
    -------
    numpy.ndarray
        H0 [MJ m-2] (per day), of the shape of ``doy``.
    """
    h0 = extraterrestrial_irradiation(latitude, np.asarray(doy, float))
    return np.maximum(h0, 0.0) / 1e6


def leaf_exposure(tree) -> np.ndarray:
    """Exposure factor per leaf in [0.35, 1]: higher and outer leaves get more light.

    ``0.35 + 0.65 (0.6 h + 0.4 r)`` with h the leaf's height in the crown and r its horizontal
    distance from the crown's mean position, both scaled to [0, 1] [-]: a proxy for the crown's
    self-shading.

    Parameters
    ----------
    tree : Tree
        The tree (its ``leaves.position`` (n, 3) [m]).

    Returns
    -------
    numpy.ndarray
        Exposure factor (n,) in [0.35, 1] [-] (empty for a tree without leaves).
    """
    p = tree.leaves.position
    if len(p) == 0:
        return np.zeros(0)
    y = p[:, 1]
    h = (y - y.min()) / max(float(np.ptp(y)), 1e-9)
    c = p.mean(0)
    r = np.hypot(p[:, 0] - c[0], p[:, 2] - c[2])
    r = r / max(float(r.max()), 1e-9)
    return np.clip(0.35 + 0.65 * (0.6 * h + 0.4 * r), 0.35, 1.0)


class TreeSeasons:
    """Phenology of one tree over a date range (precomputed once, then :meth:`apply` per date)."""

    def __init__(self, tree, latitude: float, start: _dt.date, days: int, seed: int = 0,
                 leaf_out: int = LEAF_OUT_DOY, onset: int = AUTUMN_ONSET_DOY):
        self.tree = tree
        self.start = start
        n = len(tree.leaves)
        self.days = int(days)
        dates = [start + _dt.timedelta(days=i) for i in range(self.days)]
        self.doy = np.array([d.timetuple().tm_yday for d in dates])
        exp = leaf_exposure(tree)
        rng = np.random.default_rng(seed)
        self.leaf_out_day = leaf_out - 5.0 * exp + rng.normal(0, 2.0, n)
        H = daily_extraterrestrial_mj(latitude, self.doy) * 0.55          # MJ m-2 per day
        daily = exp[:, None] * H[None, :]
        # onset: the first day of the range on or after the onset day of year
        after = np.nonzero(self.doy >= onset)[0]
        onset_idx = int(after[0]) if len(after) else self.days
        if onset_idx < self.days:
            self.state = autumn_time(daily, AutumnParams(onset_day=onset_idx, fall=True),
                                     seed=seed)
            self.tau_raw = self.state.tau_raw
            self.fall_thr = self.state.fall_threshold
        else:   # the range ends before the autumn onset: green all along
            self.state = None
            self.tau_raw = np.zeros((n, self.days))
            self.fall_thr = np.full(n, np.inf)
        # the day index each leaf falls (raw tau first past its threshold), NaN: not in range
        past = self.tau_raw >= self.fall_thr[:, None]
        self.fall_index = np.where(past.any(1), np.argmax(past, axis=1), np.nan)

    def apply(self, date: _dt.date) -> None:
        """Write the tree's leaf attributes for ``date``.

        Sets ``leaf_scale`` (the leaf-out smoothstep, 0..1 [-]; 1 after day-of-year 200),
        ``autumn_tau`` (logical autumn time clipped to [0, 1] [-]), ``fallen`` (raw tau past the
        leaf's fall threshold) and ``litter_age`` (days since the leaf fell [days], NaN if it
        has not) in ``tree.leaves.attrs``.

        Parameters
        ----------
        date : datetime.date
            The date; dates outside the precomputed range use its first or last day's autumn state.
        """
        i = int(np.clip((date - self.start).days, 0, self.days - 1))
        doy = date.timetuple().tm_yday
        lv = self.tree.leaves
        x = np.clip((doy - self.leaf_out_day) / LEAF_OUT_DAYS, 0.0, 1.0)
        scale = x * x * (3 - 2 * x)
        if doy > 200:           # after midsummer: leaves stay out until they fall
            scale = np.ones_like(scale)
        lv.attrs["leaf_scale"] = scale
        raw = self.tau_raw[:, i]
        lv.attrs["autumn_tau"] = np.clip(raw, 0.0, 1.0)
        lv.attrs["fallen"] = raw >= self.fall_thr
        age = (date - self.start).days - self.fall_index
        lv.attrs["litter_age"] = np.where(age >= 0, age, np.nan)
