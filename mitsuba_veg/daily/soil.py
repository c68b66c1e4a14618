"""The soil stage of a day: paper 000's heat and water model (eqs 3.2-3.16 and the bucket,
3.6-3.8) on every terrain element, on the device.

The moss density at the start of the day sets the bulk transfer coefficient C_H (eq 3.5);
:func:`mitsuba_veg.soil.soil_day` (the one implementation of the chain, shared with the relaxed
model of ``tune``) gives Ts, rhs, theta and the water left for the next day. The day's weather
is read from device arrays by the day's index, so every day runs the same kernel.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .. import soil as soil_model
from .inputs import DayValues


__all__ = ["day_soil"]

def day_soil(site, vals: DayValues, O, S, counts) -> soil_model.SoilDay:
    """One day of the soil model on the terrain elements (module docstring).

    Parameters
    ----------
    site : Site
        The run's site (soil depth, geology, moss capacity per element).
    vals : DayValues
        The day's weather on the device.
    O : mi.Float64
        Water stored at the end of the previous day [mm] per terrain element.
    S : mi.Float64
        The day's insolation [W m-2] per terrain element.
    counts : mi.UInt32
        Live moss per terrain element at the start of the day.

    Returns
    -------
    SoilDay
        Surface state (Ts [K], rhs [-], iotaE [W m-2], beta [-]), theta [m3 m-3] and the water
        of the next day [mm] (lazy: evaluated with the day's other per-element arrays).
    """
    C_H = soil_model.transfer_coefficient(dr.minimum(mi.Float64(counts) / site.d_M, 1.0))
    w = vals.weather
    return soil_model.soil_day(O, S, w["T"], w["rh"], w["U"], w["A"], w["P"], site.d_h,
                               site.geology_table, C_H)
