"""Leaf phenology of the world's trees, day by day: leaf-out, autumn colour, leaf fall.

Each leaf i carries (Dr.Jit arrays over the leaves on the variant's device, updated by one
vectorised step a day):

- **leaf-out** (spring; documented parameters, not from the papers): leaves grow from nothing to
  full size between day of year ``leaf_out_doy`` and ``leaf_out_doy + leaf_out_days`` (a
  smoothstep of the blade size). Then last year's leaves (fallen, or still hanging) are
  replaced by new green ones (stage 1), their autumn clocks reset.
- **autumn** (paper 003 §3.3, :mod:`mitsuba_veg.foliage.autumn`): from day of year
  ``autumn_onset_doy`` the leaf's insolation H_i [MJ m-2] accumulates the light it received
  that day **in the world's photon pass** (the same pass that lights the terrain); the logical
  time τ_raw = ξ_i [(1 − β) H_i / H_full + β t / D_full] (t: days since the onset), τ = clip(τ_raw,
  0, 1) and the Ishikura stage = 1 + 6 τ.
- **leaf fall**: a leaf falls when τ_raw reaches its threshold φ_i (log-normal around
  ``fall_tau``); a fallen leaf no longer blocks light (hidden in the pass's tables, its blade
  later taken out of the light scene) until it grows again next spring. The day it fell is kept
  (``fall_day``, the date's proleptic Gregorian ordinal; −1 before its first fall) until it falls
  again, through the next leaf-out: the render lays it on the ground as litter
  (:mod:`mitsuba_veg.render.litter`). A leaf still hanging at the next leaf-out is shed that
  day. The record is output only: nothing of the simulation reads it.

Before the first leaf-out of a run that starts in winter or early spring the trees are bare.
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import asdict, dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import host_array, opaque
from ..errors import check_range
from ..foliage.autumn import AutumnParams, leaf_factors, tau_raw
from ..foliage.pigments import stage_from_tau


__all__ = ["PhenologyParams", "Phenology"]

@dataclass(frozen=True)
class PhenologyParams:
    """Scenario ``[phenology]`` (days of year are 1-366)."""

    leaf_out_doy: int = 95          # first day of leaf-out (early April)
    leaf_out_days: int = 30         # days from bud to full blade
    autumn_onset_doy: int = 258     # mid-September: the abscission layer forms
    insolation_full: float = 250.0  # H_full [MJ m-2] (paper 003 §3.3, AutumnParams)
    time_weight: float = 0.2        # β [-]
    days_full: float = 60.0         # D_full [days]
    rate_sigma: float = 0.15        # log-sd of ξ
    fall_tau: float = 1.25          # median τ_raw at which a leaf falls
    fall_sigma: float = 0.1         # log-sd of φ

    def validate(self, source: str | None = None) -> "PhenologyParams":
        """Check every field's range (days of year 1-366, leaf-out 1-180 days, the autumn model's).

        Parameters
        ----------
        source : str, optional
            Scenario file named in the error message.

        Returns
        -------
        PhenologyParams
            ``self``, unchanged.

        Raises
        ------
        ParameterError
            When a field is out of range.
        """
        check_range("phenology.leaf_out_doy", self.leaf_out_doy, 1, 366, source=source)
        check_range("phenology.leaf_out_days", self.leaf_out_days, 1, 180, source=source)
        check_range("phenology.autumn_onset_doy", self.autumn_onset_doy, 1, 366, source=source)
        self.autumn().validate()
        return self

    def autumn(self) -> AutumnParams:
        """The autumn model's parameters (paper 003 §3.3) of these settings.

        Returns
        -------
        AutumnParams
            ``insolation_full`` [MJ m-2], ``time_weight`` [-], ``days_full`` [days], ``rate_sigma``,
            ``fall_tau``, ``fall_sigma`` [-] from these fields; leaf fall on, no pigment variation.
        """
        return AutumnParams(insolation_full=self.insolation_full, time_weight=self.time_weight,
                            days_full=self.days_full, rate_sigma=self.rate_sigma,
                            pigment_sigma=0.0, fall=True, fall_tau=self.fall_tau,
                            fall_sigma=self.fall_sigma)

    def to_dict(self) -> dict:
        """The parameters as a plain dict (``dataclasses.asdict``).

        Returns
        -------
        dict
            Field name -> value (units as in the class).
        """
        return asdict(self)


class Phenology:
    """The state of ``n`` leaves on the device (see the module docstring): one vectorised step
    a day, nothing read back (:meth:`to_numpy` reads the state for checkpoints and maps).

    Attributes ``H`` [MJ m-2], ``t`` [days], ``tau_raw`` [-], ``grown`` [-] (blade size 0..1),
    ``rate``, ``fall_threshold`` [-], ``fall_day`` (the ordinal of the date the leaf last fell,
    ``datetime.date.toordinal``; −1: not yet) are ``mi.Float64`` arrays, ``fallen`` a ``mi.Bool``.
    """

    FIELDS = ("H", "t", "tau_raw", "fallen", "grown", "rate", "fall_threshold", "fall_day")
    #: fields a checkpoint may lack (written before they existed) and their value then
    OPTIONAL = {"fall_day": -1.0}

    def __init__(self, n: int, params: PhenologyParams = PhenologyParams(), seed: int = 0,
                 leaf_out_shift=None):
        self.params = params
        self.n = int(n)
        self.autumn_params = params.autumn()
        rate, thr = leaf_factors(self.n, self.autumn_params, seed)
        self.rate, self.fall_threshold = host_array(mi.Float64, rate), host_array(mi.Float64, thr)
        # sunnier leaves unfold a few days earlier (leaf_out_shift [days], <= 0)
        self.shift = host_array(mi.Float64, np.zeros(self.n) if leaf_out_shift is None else
                                leaf_out_shift)
        self.H = dr.zeros(mi.Float64, self.n)          # insolation since the onset [MJ m-2]
        self.t = dr.zeros(mi.Float64, self.n)          # days since the onset
        self.tau_raw = dr.zeros(mi.Float64, self.n)
        self.fallen = dr.zeros(mi.Bool, self.n)
        self.grown = dr.zeros(mi.Float64, self.n)      # blade size 0..1 (leaf-out)
        self.fall_day = dr.full(mi.Float64, -1.0, self.n)   # date ordinal of the last fall
        dr.eval(self.rate, self.fall_threshold, self.shift, self.H, self.t, self.tau_raw,
                self.fallen, self.grown, self.fall_day)

    # ---- one day ------------------------------------------------------------------------
    def start_of_day(self, date: _dt.date, evaluate: bool = True) -> None:
        """Leaf-out (blade size) for ``date``.

        Blades grow as a smoothstep of (doy − (leaf_out_doy + shift)) / leaf_out_days; on day
        ``leaf_out_doy`` a new season starts: last year's leaves (fallen or still hanging) give
        way to new, green ones (on a first leaf-out there is nothing to reset: the same).

        Parameters
        ----------
        date : datetime.date
            The simulated day.
        evaluate : bool
            Evaluate the state now (one kernel); False when the caller evaluates
            :meth:`arrays` in a kernel of its own that day.
        """
        p = self.params
        doy = date.timetuple().tm_yday
        # the day as a kernel input: one kernel serves every day
        d = opaque(mi.Float64, float(doy))
        x = dr.clip((d - (p.leaf_out_doy + self.shift)) / float(p.leaf_out_days), 0.0, 1.0)
        if doy == p.leaf_out_doy:
            # last year's leaves still hanging are shed today (the litter's record only): out
            # and not fallen, on the tree through more of the autumn clock's days than a new
            # leaf unfolding early this spring (at most -shift days) can have been
            hanging = (self.grown > 0) & (self.t > 1.0 - self.shift) & ~self.fallen
            self.fall_day = dr.select(hanging, opaque(mi.Float64, float(date.toordinal())),
                                      self.fall_day)
            self.H = dr.zeros(mi.Float64, self.n)
            self.t = dr.zeros(mi.Float64, self.n)
            self.tau_raw = dr.zeros(mi.Float64, self.n)
            self.fallen = dr.zeros(mi.Bool, self.n)
            self.grown = dr.zeros(mi.Float64, self.n)
        # a leaf grows with the calendar and keeps its size until it falls (also across the
        # new year: a leaf still on the tree in January stays until it falls)
        self.grown = dr.select(self.fallen, 0.0, dr.maximum(self.grown, x * x * (3 - 2 * x)))
        # evaluated now (one kernel): a state left lazy grows its expression day by day, and
        # every later day would compile a longer kernel
        if evaluate:
            self.evaluate()

    def end_of_day(self, date: _dt.date, insolation_mj) -> None:
        """Add the day's insolation of each leaf (after the autumn onset), update τ and leaf fall.

        Only leaves on the tree accumulate, from ``autumn_onset_doy`` until the next leaf-out.

        Parameters
        ----------
        date : datetime.date
            The simulated day.
        insolation_mj : mi.Float64 or array_like
            (n,) the day's insolation of each leaf [MJ m-2] (negative values count as 0).
        """
        doy = date.timetuple().tm_yday
        p = self.params
        if not (doy >= p.autumn_onset_doy or doy < p.leaf_out_doy):
            return
        ins = insolation_mj if dr.is_array_v(insolation_mj) else \
            mi.Float64(np.asarray(insolation_mj, float))
        on = (self.grown > 0) & ~self.fallen
        self.H = self.H + dr.select(on, dr.maximum(mi.Float64(ins), 0.0), 0.0)
        self.t = self.t + dr.select(on, 1.0, 0.0)
        self.tau_raw = dr.select(on, tau_raw(self.H, self.t, self.rate, self.autumn_params),
                                 self.tau_raw)
        fell = on & (self.tau_raw >= self.fall_threshold)
        self.fallen = self.fallen | fell
        self.fall_day = dr.select(fell, opaque(mi.Float64, float(date.toordinal())),
                                  self.fall_day)
        self.grown = dr.select(self.fallen, 0.0, self.grown)
        self.evaluate()                          # (see start_of_day)

    def arrays(self) -> list:
        """The state's Dr.Jit arrays (to evaluate with others in one kernel).

        Returns
        -------
        list
            H, t, τ_raw, fallen, grown, fall_day.
        """
        return [self.H, self.t, self.tau_raw, self.fallen, self.grown, self.fall_day]

    def evaluate(self) -> None:
        """Evaluate the state (one kernel for the day's updates)."""
        dr.eval(*self.arrays())

    # ---- views --------------------------------------------------------------------------
    @property
    def tau(self):
        """Autumn logical time τ ∈ [0, 1] per leaf [-] (τ_raw clipped; mi.Float64)."""
        return dr.clip(self.tau_raw, 0.0, 1.0)

    @property
    def stage(self):
        """Continuous Ishikura stage 1..7 per leaf (mi.Float64)."""
        return stage_from_tau(self.tau)

    @property
    def on_tree(self):
        """Leaves that are out and have not fallen (mi.Bool)."""
        return (self.grown > 1e-3) & ~self.fallen

    # ---- checkpoints --------------------------------------------------------------------
    def to_numpy(self, prefix: str = "phen_") -> dict:
        """The leaves' state for a checkpoint (read back).

        Parameters
        ----------
        prefix : str
            Prefix of the keys (default ``"phen_"``).

        Returns
        -------
        dict
            ``{prefix + field: (n,) array}`` for :attr:`FIELDS`: H [MJ m-2], t [days], tau_raw [-],
            fallen (bool), grown [-] (blade size 0..1), rate [-], fall_threshold [-], fall_day
            (date ordinal of the last fall, −1: none).
        """
        return {prefix + k: np.array(getattr(self, k)) for k in self.FIELDS}

    def load_numpy(self, d: dict, prefix: str = "phen_") -> None:
        """Restore the state saved by :meth:`to_numpy`.

        Parameters
        ----------
        d : dict
            A checkpoint holding the keys of :meth:`to_numpy` (a checkpoint written before
            ``fall_day`` existed restores it as −1: no fall recorded).
        prefix : str
            Prefix of the keys (default ``"phen_"``).

        Raises
        ------
        ValueError
            When a saved array does not have one value per leaf.
        KeyError
            When a field is missing.
        """
        for k in self.FIELDS:
            if prefix + k not in d and k in self.OPTIONAL:
                setattr(self, k, dr.full(mi.Float64, self.OPTIONAL[k], self.n))
                continue
            v = np.asarray(d[prefix + k])
            if v.shape != (self.n,):
                raise ValueError(f"{prefix + k}: {v.shape} != ({self.n},)")
            setattr(self, k, host_array(mi.Bool if k == "fallen" else mi.Float64, v))
