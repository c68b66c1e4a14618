"""Clear-sky daylight: SPCTRAL2 spectra and Mitsuba emitter dicts for the sun and the sky.

The spectra come from the Bird & Riordan (1984) Simple Spectral Model SPCTRAL2
(:func:`pvlib.spectrum.spectrl2`): direct-normal (beam) and diffuse-horizontal spectral
irradiance [W m-2 nm-1] at 122 wavelengths between 300 and 4000 nm, for a cloudless atmosphere
described by :class:`Atmosphere`. :func:`clear_sky_spectra` resamples them (linearly) onto a
regular grid (1 nm by default) and can scale them to measured broadband values (clouds).

:func:`daylight_from_angles` / :func:`daylight` turn them into Mitsuba emitter dicts:

- ``"sun"``: a ``directional`` emitter, ``irradiance`` = the beam spectrum (irradiance on a plane
  perpendicular to the beam) as an explicit ``regular`` spectrum;
- ``"sky"``: a ``veg_sky`` emitter (:mod:`mitsuba_veg.light.sky`) whose horizontal irradiance
  equals the SPCTRAL2 diffuse spectrum, with a Perez all-weather (default) or CIE clear-sky
  angular distribution.

Frame (project convention): +y up, +x east, +z south; azimuth clockwise from north [deg].
See ``docs/daylight.md``.
"""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, fields, replace
from typing import NamedTuple

import numpy as np

from ..errors import ParameterError, check_range
from ..units import AVOGADRO, LIGHT_SPEED, PLANCK
from .solar_position import sun_direction, sun_position

__all__ = [
    "Atmosphere", "DEFAULT_ATMOSPHERE", "DaylightSpectra", "clear_sky_spectra",
    "daylight", "daylight_from_angles", "regular_spectrum", "perez_sky_parameters",
    "photon_flux", "band_irradiance", "red_far_red_ratio", "SPCTRL2_RANGE_NM",
    "clear_sky_broadband",
]

#: wavelength range covered by SPCTRAL2 [nm]
SPCTRL2_RANGE_NM = (300.0, 4000.0)

_H, _C, _NA = PLANCK, LIGHT_SPEED, AVOGADRO


@dataclass(frozen=True)
class Atmosphere:
    """Cloudless atmosphere for SPCTRAL2.

    The defaults are a clear, rural mid-latitude summer day: aerosol optical depth 0.10 at
    500 nm (rural aerosol, Angstrom exponent 1.14), precipitable water 2.9 cm and ozone
    0.33 atm-cm (approximately the AFGL mid-latitude summer standard atmosphere), sea-level
    pressure and a ground albedo of 0.2 (vegetation / soil). With these, global daylight at
    30-60 deg sun elevation has a red:far-red photon ratio of 1.14-1.17 (field value ~1.15);
    with the drier US-standard atmosphere (1.42 cm) SPCTRAL2 gives only ~1.10 because the
    725-735 nm band sits on the 720 nm water-vapour band.
    """

    #: aerosol optical depth at 500 nm [-] (0.05 very clean ... 0.5 hazy)
    aerosol_turbidity: float = 0.10
    #: precipitable water [cm]
    precipitable_water: float = 2.9
    #: total column ozone [atm-cm] (0.33 atm-cm = 330 Dobson units)
    ozone: float = 0.33
    #: surface pressure [Pa]
    pressure: float = 101325.0
    #: broadband ground albedo [-] (used for the sky-ground multiple reflection in the DHI)
    ground_albedo: float = 0.2
    #: Angstrom exponent of the aerosol [-]
    angstrom_alpha: float = 1.14
    #: aerosol single-scattering albedo at 400 nm [-]
    aerosol_single_scattering_albedo: float = 0.945
    #: aerosol asymmetry factor [-]
    aerosol_asymmetry: float = 0.65

    def validate(self) -> "Atmosphere":
        """Check every field's range.

        Returns
        -------
        Atmosphere
            This atmosphere, unchanged.

        Raises
        ------
        ParameterError
            For the first field out of its range, naming the field, its value, the range and
            a fix.
        """
        check_range("aerosol_turbidity", self.aerosol_turbidity, 0.0, 5.0,
                    fix="give the aerosol optical depth at 500 nm, e.g. 0.05 (very clean) to "
                        "0.5 (hazy); 0.1 is a clear rural day")
        check_range("precipitable_water", self.precipitable_water, 0.0, 10.0,
                    fix="give the precipitable water column in cm (0.5 dry/cold ... 5 tropical)")
        check_range("ozone", self.ozone, 0.0, 1.0,
                    fix="give total ozone in atm-cm (0.25-0.45; 0.33 atm-cm = 330 DU)")
        check_range("pressure", self.pressure, 10000.0, 120000.0,
                    fix="give the surface pressure in Pa (101325 at sea level), not hPa")
        check_range("ground_albedo", self.ground_albedo, 0.0, 1.0,
                    fix="give a broadband albedo between 0 and 1 (0.2 for grass/soil)")
        check_range("angstrom_alpha", self.angstrom_alpha, 0.0, 4.0,
                    fix="typical Angstrom exponents are 0.5-2 (1.14 rural)")
        check_range("aerosol_single_scattering_albedo", self.aerosol_single_scattering_albedo,
                    0.0, 1.0, fix="use 0.945 (rural) or 0.9-0.99")
        check_range("aerosol_asymmetry", self.aerosol_asymmetry, -1.0, 1.0,
                    fix="use 0.65 (rural aerosol)")
        return self


#: the package's default atmosphere (see :class:`Atmosphere`)
DEFAULT_ATMOSPHERE = Atmosphere()


class DaylightSpectra(NamedTuple):
    """Clear-sky spectra; unpacks as ``(wavelengths, dni, dhi)``."""

    #: wavelengths [nm]
    wavelengths: np.ndarray
    #: direct-normal (beam) spectral irradiance [W m-2 nm-1]
    dni: np.ndarray
    #: diffuse-horizontal spectral irradiance [W m-2 nm-1]
    dhi: np.ndarray


def _atmosphere(atmosphere: Atmosphere | None, overrides: dict) -> Atmosphere:
    if atmosphere is None:
        atmosphere = DEFAULT_ATMOSPHERE
    elif not isinstance(atmosphere, Atmosphere):
        raise ParameterError("atmosphere", atmosphere, "an Atmosphere instance or None",
                             "use mitsuba_veg.light.clear_sky.Atmosphere(...) or keyword "
                             "arguments such as aerosol_turbidity=0.2")
    names = {f.name for f in fields(Atmosphere)}
    given = {k: v for k, v in overrides.items() if v is not None}
    unknown = set(given) - names
    if unknown:  # pragma: no cover - guarded by explicit keyword arguments
        raise ParameterError("atmosphere field", sorted(unknown), ", ".join(sorted(names)))
    return replace(atmosphere, **given).validate()


def _spectrl2(elevation_deg, day_of_year, atm: Atmosphere):
    """SPCTRAL2 (pvlib's spectrl2) for arrays of sun elevations > 0 [deg] and days of the year:
    (wl (122,), dni (122, n), dhi (122, n), dni_extra (122, n), airmass (n,)), with negative
    and NaN spectral values set to 0. The one call of the clear-sky model in the package."""
    from pvlib.atmosphere import get_relative_airmass
    from pvlib.spectrum import spectrl2

    zenith = 90.0 - np.asarray(elevation_deg, dtype=float).reshape(-1)
    doy = np.broadcast_to(np.asarray(day_of_year, dtype=float), zenith.shape)
    airmass = np.asarray(get_relative_airmass(zenith, model="kastenyoung1989"), dtype=float)
    res = spectrl2(
        apparent_zenith=zenith, aoi=zenith, surface_tilt=np.zeros_like(zenith),
        ground_albedo=atm.ground_albedo, surface_pressure=atm.pressure,
        relative_airmass=airmass, precipitable_water=atm.precipitable_water,
        ozone=atm.ozone, aerosol_turbidity_500nm=atm.aerosol_turbidity,
        dayofyear=doy,
        scattering_albedo_400nm=atm.aerosol_single_scattering_albedo,
        alpha=atm.angstrom_alpha, aerosol_asymmetry_factor=atm.aerosol_asymmetry)
    wl = np.asarray(res["wavelength"], dtype=float)
    dni = np.clip(np.nan_to_num(np.asarray(res["dni"], dtype=float)), 0.0, None)
    dhi = np.clip(np.nan_to_num(np.asarray(res["dhi"], dtype=float)), 0.0, None)
    etr = np.asarray(res["dni_extra"], dtype=float)
    return wl, dni, dhi, etr, airmass


def _spectrl2_native(elevation_deg: float, day_of_year: int, atm: Atmosphere):
    """SPCTRAL2 on its native 122 wavelengths for one sun: (wl, dni, dhi, dni_extra,
    airmass)."""
    wl, dni, dhi, etr, airmass = _spectrl2([float(elevation_deg)], [int(day_of_year)], atm)
    return wl, dni[:, 0], dhi[:, 0], etr[:, 0], float(airmass[0])


def clear_sky_broadband(elevation_deg, day_of_year, atmosphere: Atmosphere | None = None):
    """Broadband (300-4000 nm) clear-sky DNI and DHI for arrays of sun elevations.

    SPCTRAL2 (Bird & Riordan 1986) with the package's default atmosphere, one vectorised call
    of pvlib's spectrl2 (the same call as :func:`clear_sky_spectra`), integrated over its 122
    wavelengths (trapezoids); the clear-sky model of every sun path in the package
    (:func:`mitsuba_veg.light.sunpath.sun_path`, :func:`~mitsuba_veg.light.sunpath.day_sun_path`).

    Parameters
    ----------
    elevation_deg : array_like
        Sun elevations [deg]; at or below 0.5° both irradiances are 0.
    day_of_year : int or array_like
        Day of the year (Earth-Sun distance), broadcast against the elevations.
    atmosphere : Atmosphere, optional
        Default :data:`DEFAULT_ATMOSPHERE`.

    Returns
    -------
    dni, dhi : numpy.ndarray
        Direct normal and diffuse horizontal irradiance [W m-2], one per elevation.
    """
    atm = atmosphere or DEFAULT_ATMOSPHERE
    el = np.atleast_1d(np.asarray(elevation_deg, float))
    doy = np.broadcast_to(np.asarray(day_of_year, int), el.shape)
    dni = np.zeros(el.shape)
    dhi = np.zeros(el.shape)
    up = el > 0.5
    if up.any():
        wl, a, b, _etr, _am = _spectrl2(el[up], doy[up], atm)
        dni[up] = np.trapezoid(a, wl, axis=0)
        dhi[up] = np.trapezoid(b, wl, axis=0)
    return dni, dhi


def _check_elevation(elevation_deg, *, field="elevation_deg"):
    check_range(field, elevation_deg, 0.0, 90.0, lo_open=True,
                fix="the clear-sky model needs the sun above the horizon (0 < elevation <= 90 "
                    "deg); daylight()/daylight_from_angles() return no emitters at night")


def _check_day(day_of_year):
    check_range("day_of_year", day_of_year, 1, 366, fix="give the day of the year, 1-366")


def _scale(name_scale, scale, name_target, target, broadband):
    if target is not None:
        if scale is not None:
            raise ParameterError(name_scale, scale, f"None when {name_target} is given",
                                 f"give either {name_scale} or {name_target}, not both")
        check_range(name_target, target, 0.0, 1500.0,
                    fix=f"give the broadband {name_target[:3].upper()} in W/m2 (>= 0)")
        if broadband <= 0.0:
            return 0.0
        return float(target) / broadband
    if scale is None:
        return 1.0
    check_range(name_scale, scale, 0.0, 20.0, fix="use a factor >= 0 (1 = clear sky)")
    return float(scale)


def clear_sky_spectra(elevation_deg: float, *, day_of_year: int = 172,
                      atmosphere: Atmosphere | None = None,
                      aerosol_turbidity: float | None = None,
                      precipitable_water: float | None = None,
                      ozone: float | None = None, pressure: float | None = None,
                      ground_albedo: float | None = None,
                      beam_scale: float | None = None, diffuse_scale: float | None = None,
                      dni_target: float | None = None, dhi_target: float | None = None,
                      step_nm: float | None = 1.0,
                      wavelength_range: tuple[float, float] = SPCTRL2_RANGE_NM
                      ) -> DaylightSpectra:
    """Clear-sky beam (DNI) and diffuse-horizontal (DHI) spectral irradiance [W m-2 nm-1].

    SPCTRAL2 (Bird & Riordan 1984, :func:`pvlib.spectrum.spectrl2`) on its 122 wavelengths,
    optionally scaled (clouds) and resampled linearly onto a regular grid.

    Parameters
    ----------
    elevation_deg : float
        Apparent sun elevation above the horizon, 0 < el <= 90 [deg].
    day_of_year : int
        Day of the year, 1-366 (Sun-Earth distance).
    atmosphere : Atmosphere, optional
        The atmosphere (default :data:`DEFAULT_ATMOSPHERE`); the keyword arguments below
        override its fields.
    aerosol_turbidity : float, optional
        Aerosol optical depth at 500 nm [-].
    precipitable_water : float, optional
        Precipitable water [cm].
    ozone : float, optional
        Total column ozone [atm-cm].
    pressure : float, optional
        Surface pressure [Pa].
    ground_albedo : float, optional
        Broadband ground albedo [-].
    beam_scale, diffuse_scale : float, optional
        Factors applied to the beam / diffuse spectra [-] (clouds); or
    dni_target, dhi_target : float, optional
        Broadband (300-4000 nm) DNI / DHI [W m-2] to scale to (e.g. measured values); give a
        scale or a target per component, not both.
    step_nm : float or None
        Resampling step of the returned regular grid [nm] (linear interpolation of SPCTRAL2's
        122 wavelengths); ``None`` returns the native irregular grid.
    wavelength_range : tuple of float
        (min, max) of the returned grid [nm], within 300-4000 nm.

    Returns
    -------
    DaylightSpectra
        ``(wavelengths [nm], dni [W m-2 nm-1], dhi [W m-2 nm-1])``.
    """
    _check_elevation(elevation_deg)
    _check_day(day_of_year)
    atm = _atmosphere(atmosphere, dict(
        aerosol_turbidity=aerosol_turbidity, precipitable_water=precipitable_water,
        ozone=ozone, pressure=pressure, ground_albedo=ground_albedo))
    wl, dni, dhi, _etr, _am = _spectrl2_native(elevation_deg, day_of_year, atm)
    kb = _scale("beam_scale", beam_scale, "dni_target", dni_target, float(np.trapezoid(dni, wl)))
    kd = _scale("diffuse_scale", diffuse_scale, "dhi_target", dhi_target,
                float(np.trapezoid(dhi, wl)))
    dni, dhi = dni * kb, dhi * kd
    lo, hi = (float(v) for v in wavelength_range)
    if not (SPCTRL2_RANGE_NM[0] <= lo < hi <= SPCTRL2_RANGE_NM[1]):
        raise ParameterError("wavelength_range", wavelength_range,
                             "min < max within [300, 4000] nm (SPCTRAL2's range)")
    if step_nm is None:
        keep = (wl >= lo) & (wl <= hi)
        return DaylightSpectra(wl[keep], dni[keep], dhi[keep])
    check_range("step_nm", step_nm, 0.0, 100.0, lo_open=True, fix="use e.g. 1 or 5 nm")
    n = int(round((hi - lo) / step_nm))
    if n < 1 or not math.isclose(lo + n * step_nm, hi, rel_tol=0, abs_tol=1e-6 * step_nm):
        raise ParameterError("step_nm", step_nm, "a step that divides the wavelength range",
                             f"range {lo}-{hi} nm: use e.g. step_nm=1")
    grid = lo + step_nm * np.arange(n + 1)
    return DaylightSpectra(grid, np.interp(grid, wl, dni), np.interp(grid, wl, dhi))


# --------------------------------------------------------------------------- band helpers
def _band_integral(wavelengths, values, lo, hi, weight_by_lambda):
    wl = np.asarray(wavelengths, dtype=float)
    v = np.asarray(values, dtype=float)
    if not (wl[0] <= lo < hi <= wl[-1]):
        raise ParameterError("band", (lo, hi), f"within the spectrum's range {wl[0]}-{wl[-1]} nm")
    inner = wl[(wl > lo) & (wl < hi)]
    x = np.concatenate(([lo], inner, [hi]))
    y = np.interp(x, wl, v)          # the spectrum is piecewise linear between its samples
    if weight_by_lambda:
        # exact integral of a linear y(x) times x over each piece
        x0, x1, y0, y1 = x[:-1], x[1:], y[:-1], y[1:]
        dx = x1 - x0
        return float(np.sum(dx * (y0 * (2 * x0 + x1) + y1 * (x0 + 2 * x1)) / 6.0))
    return float(np.trapezoid(y, x))


def band_irradiance(wavelengths, values, lo: float, hi: float) -> float:
    """Energy irradiance of a spectrum in a band.

    The spectrum is taken as piecewise linear between its samples and integrated exactly.

    Parameters
    ----------
    wavelengths : array_like
        Increasing wavelengths [nm].
    values : array_like
        Spectral irradiance at them [W m-2 nm-1].
    lo, hi : float
        The band [nm], within the spectrum's range.

    Returns
    -------
    float
        Irradiance in the band [W m-2].
    """
    return _band_integral(wavelengths, values, lo, hi, False)


def photon_flux(wavelengths, values, lo: float, hi: float) -> float:
    """Photon flux density of a spectrum in a band.

    ∫ E(λ) λ / (h c N_A) dλ, exact for a spectrum piecewise linear between its samples.

    Parameters
    ----------
    wavelengths : array_like
        Increasing wavelengths [nm].
    values : array_like
        Spectral irradiance at them [W m-2 nm-1].
    lo, hi : float
        The band [nm], within the spectrum's range.

    Returns
    -------
    float
        Photon flux density in the band [umol m-2 s-1].
    """
    e_lambda = _band_integral(wavelengths, values, lo, hi, True)   # W m-2 nm-1 * nm * nm
    return e_lambda * 1e-9 / (_H * _C) / _NA * 1e6


def red_far_red_ratio(wavelengths, values) -> float:
    """Red:far-red photon ratio, 655-665 nm over 725-735 nm (Smith 1982).

    Parameters
    ----------
    wavelengths : array_like
        Increasing wavelengths [nm], covering 655-735 nm.
    values : array_like
        Spectral irradiance at them [W m-2 nm-1].

    Returns
    -------
    float
        Photon flux ratio R:FR [-].
    """
    return (photon_flux(wavelengths, values, 655.0, 665.0)
            / photon_flux(wavelengths, values, 725.0, 735.0))


# --------------------------------------------------------------------------- Mitsuba dicts
def regular_spectrum(wavelengths, values, *, fmt: str = "%.7g") -> dict:
    """A Mitsuba ``regular`` spectrum dict from values on an evenly spaced grid.

    Parameters
    ----------
    wavelengths : array_like
        Evenly spaced, increasing wavelengths [nm] (at least two).
    values : array_like
        Finite values >= 0 at them (e.g. [W m-2 nm-1] or [W m-2 sr-1 nm-1]).
    fmt : str
        printf format of each value in the dict's ``values`` string.

    Returns
    -------
    dict
        ``{"type": "regular", "wavelength_min", "wavelength_max", "values"}`` for
        :func:`mitsuba.load_dict`.
    """
    wl = np.asarray(wavelengths, dtype=float)
    v = np.asarray(values, dtype=float)
    if wl.ndim != 1 or wl.shape != v.shape or wl.size < 2:
        raise ParameterError("wavelengths/values", (wl.shape, v.shape),
                             "two 1D arrays of equal length >= 2")
    d = np.diff(wl)
    if np.any(d <= 0) or not np.allclose(d, d[0], rtol=1e-6, atol=1e-9):
        raise ParameterError("wavelengths", "irregular grid", "evenly spaced, increasing",
                             "resample first (clear_sky_spectra(step_nm=...))")
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ParameterError("values", "negative or non-finite", "finite values >= 0")
    return {"type": "regular", "wavelength_min": float(wl[0]), "wavelength_max": float(wl[-1]),
            "values": ", ".join(fmt % x for x in v)}


#: Perez et al. (1993) sky clearness bin edges
_PEREZ_EPS_EDGES = (1.065, 1.23, 1.5, 1.95, 2.8, 4.5, 6.2)


def perez_sky_parameters(dni: float, dhi: float, elevation_deg: float,
                         day_of_year: int = 172) -> tuple[float, float]:
    """Perez sky clearness epsilon and brightness delta from broadband DNI and DHI.

    epsilon = ((DHI + DNI)/DHI + 1.041 Z^3) / (1 + 1.041 Z^3), delta = DHI m / E0
    (Z zenith [rad], m relative air mass (Kasten & Young 1989), E0 extraterrestrial normal
    irradiance) (Perez et al. 1993).

    Parameters
    ----------
    dni : float
        Broadband direct-normal irradiance [W m-2].
    dhi : float
        Broadband diffuse-horizontal irradiance [W m-2], > 0.
    elevation_deg : float
        Sun elevation [deg].
    day_of_year : int
        Day of the year, 1-366 (E0).

    Returns
    -------
    epsilon, delta : float
        Sky clearness [-] and sky brightness [-].
    """
    from pvlib.atmosphere import get_relative_airmass
    from pvlib.irradiance import get_extra_radiation

    if dhi <= 0:
        raise ParameterError("dhi", dhi, "> 0 W/m2", "the sky needs diffuse light")
    z = math.radians(90.0 - float(elevation_deg))
    k = 1.041 * z ** 3
    eps = ((dhi + max(dni, 0.0)) / dhi + k) / (1.0 + k)
    am = float(get_relative_airmass(math.degrees(z), model="kastenyoung1989"))
    e0 = float(get_extra_radiation(int(day_of_year)))
    return float(eps), float(dhi * am / e0)


def _sun_vector(azimuth_deg, elevation_deg):
    """Unit vector towards the sun in the project frame (+x east, +y up, +z south)."""
    v = np.asarray(sun_direction(azimuth_deg, elevation_deg), dtype=float).reshape(3)
    return v / np.linalg.norm(v)


def daylight_from_angles(azimuth: float, elevation: float, *, sun: bool = True,
                         sky: bool = True, day_of_year: int = 172,
                         atmosphere: Atmosphere | None = None,
                         aerosol_turbidity: float | None = None,
                         precipitable_water: float | None = None,
                         ozone: float | None = None, pressure: float | None = None,
                         ground_albedo: float | None = None,
                         beam_scale: float | None = None, diffuse_scale: float | None = None,
                         dni_target: float | None = None, dhi_target: float | None = None,
                         sky_model: str = "perez", sky_resolution: int = 128,
                         step_nm: float = 1.0,
                         wavelength_range: tuple[float, float] = SPCTRL2_RANGE_NM) -> dict:
    """Mitsuba emitter dicts for the sun at (azimuth, elevation).

    The emitters are ready to be merged into a scene dict for :func:`mitsuba.load_dict`. When
    the sun is at or below the horizon (``elevation <= 0``) the clear-sky model does not apply
    and an **empty dict** is returned (night: no emitters). The spectra are explicit
    ``regular`` spectra over ``wavelength_range`` (300-4000 nm by default, 1 nm steps): the
    directional ``irradiance`` is the beam irradiance on a plane normal to the beam
    [W m-2 nm-1]; the sky's ``radiance`` is DHI/pi [W m-2 sr-1 nm-1] (the radiance of a
    uniform sky with the same horizontal irradiance), distributed over the upper hemisphere by
    ``sky_model``.

    Parameters
    ----------
    azimuth : float
        Sun azimuth [deg], clockwise from north.
    elevation : float
        Sun elevation [deg].
    sun, sky : bool
        Whether to return the sun's / the sky's emitter.
    day_of_year : int
        Day of the year, 1-366 (Sun-Earth distance).
    atmosphere : Atmosphere, optional
        As :func:`clear_sky_spectra`.
    aerosol_turbidity, precipitable_water, ozone, pressure, ground_albedo : float, optional
        Overrides of the atmosphere's fields, as :func:`clear_sky_spectra` (AOD at 500 nm [-],
        [cm], [atm-cm], [Pa], [-]).
    beam_scale, diffuse_scale : float, optional
        Factors applied to the spectra [-], as :func:`clear_sky_spectra`.
    dni_target, dhi_target : float, optional
        Broadband DNI / DHI to scale to [W m-2], as :func:`clear_sky_spectra`.
    sky_model : str
        ``"perez"`` (Perez all-weather model driven by SPCTRAL2's broadband DNI/DHI),
        ``"cie_clear"`` (CIE standard clear sky, type 12), ``"cie_turbid"`` (type 13) or
        ``"uniform"``.
    sky_resolution : int
        Resolution of the sky's angular table (``veg_sky``'s ``resolution``).
    step_nm : float
        Wavelength step of the spectra [nm].
    wavelength_range : tuple of float
        (min, max) of the spectra [nm], within 300-4000 nm.

    Returns
    -------
    dict
        ``{"sun": {...directional...}, "sky": {...veg_sky...}}`` (either can be switched off),
        or ``{}`` at night.
    """
    check_range("azimuth", azimuth, -360.0, 720.0, fix="give the azimuth in degrees, clockwise "
                "from north")
    check_range("elevation", elevation, -90.0, 90.0, fix="give the elevation in degrees")
    if sky_model not in ("perez", "cie_clear", "cie_turbid", "uniform"):
        raise ParameterError("sky_model", sky_model, "'perez', 'cie_clear', 'cie_turbid', "
                             "'uniform'")
    if float(elevation) <= 0.0 or not (sun or sky):
        return {}
    spec = clear_sky_spectra(
        elevation, day_of_year=day_of_year, atmosphere=atmosphere,
        aerosol_turbidity=aerosol_turbidity, precipitable_water=precipitable_water,
        ozone=ozone, pressure=pressure, ground_albedo=ground_albedo, beam_scale=beam_scale,
        diffuse_scale=diffuse_scale, dni_target=dni_target, dhi_target=dhi_target,
        step_nm=step_nm, wavelength_range=wavelength_range)
    s = _sun_vector(azimuth, elevation)
    out: dict = {}
    if sun and np.any(spec.dni > 0):
        out["sun"] = {"type": "directional", "direction": [float(-c) for c in s],
                      "irradiance": regular_spectrum(spec.wavelengths, spec.dni)}
    if sky and np.any(spec.dhi > 0):
        sky_d = {"type": "veg_sky", "sun_direction": [float(c) for c in s],
                 "radiance": regular_spectrum(spec.wavelengths, spec.dhi / math.pi),
                 "distribution": sky_model, "resolution": int(sky_resolution)}
        if sky_model == "perez":
            # broadband values over SPCTRAL2's whole range drive the sky's shape
            full = clear_sky_spectra(
                elevation, day_of_year=day_of_year, atmosphere=atmosphere,
                aerosol_turbidity=aerosol_turbidity, precipitable_water=precipitable_water,
                ozone=ozone, pressure=pressure, ground_albedo=ground_albedo,
                beam_scale=beam_scale, diffuse_scale=diffuse_scale, dni_target=dni_target,
                dhi_target=dhi_target, step_nm=None)
            eps, delta = perez_sky_parameters(float(np.trapezoid(full.dni, full.wavelengths)),
                                              float(np.trapezoid(full.dhi, full.wavelengths)),
                                              elevation, day_of_year)
            sky_d["perez_epsilon"] = eps
            sky_d["perez_delta"] = delta
        out["sky"] = sky_d
    return out


def _day_of_year(when) -> int:
    """Day of the year (1-366) of a datetime / numpy.datetime64 / ISO 8601 string."""
    v = when
    if isinstance(v, (str, np.str_)):
        t = str(v).strip()
        try:
            v = _dt.datetime.fromisoformat(t[:-1] + "+00:00" if t.endswith(("Z", "z")) else t)
        except ValueError:
            try:
                v = np.datetime64(t)
            except ValueError:
                v = None
    if isinstance(v, np.datetime64) and not np.isnat(v):
        return int((v.astype("datetime64[D]") - v.astype("datetime64[Y]"))
                   .astype("timedelta64[D]").astype(np.int64)) + 1
    if isinstance(v, (_dt.datetime, _dt.date)):
        return int(v.timetuple().tm_yday)
    raise ParameterError("when", when, "one time: a datetime, numpy.datetime64 or ISO 8601 "
                         "string", "pass e.g. datetime.datetime(2024, 6, 21, 12, "
                         "tzinfo=datetime.timezone.utc); call daylight() once per time")


def daylight(latitude: float, longitude: float, when, *, sun: bool = True, sky: bool = True,
             **kwargs) -> dict:
    """Emitter dicts for the sun and sky at a place and time.

    The sun's azimuth/elevation come from :func:`mitsuba_veg.light.solar_position.sun_position`;
    the day of year from ``when``.

    Parameters
    ----------
    latitude : float
        Latitude [deg], north positive.
    longitude : float
        Longitude [deg], east positive.
    when : datetime.datetime or numpy.datetime64 or str
        One time, as :func:`~mitsuba_veg.light.solar_position.sun_position` accepts it (e.g. a
        timezone-aware ``datetime``).
    sun, sky : bool
        Whether to return the sun's / the sky's emitter.
    **kwargs : dict, optional
        Those of :func:`daylight_from_angles`.

    Returns
    -------
    dict
        ``{"sun": ..., "sky": ...}`` as :func:`daylight_from_angles`; ``{}`` at night.
    """
    check_range("latitude", latitude, -90.0, 90.0, fix="give the latitude in degrees north")
    check_range("longitude", longitude, -180.0, 180.0, fix="give the longitude in degrees east")
    doy = _day_of_year(when)
    azimuth, elevation = sun_position(latitude, longitude, when)
    kwargs.setdefault("day_of_year", doy)
    return daylight_from_angles(float(np.asarray(azimuth).reshape(())),
                                float(np.asarray(elevation).reshape(())), sun=sun, sky=sky,
                                **kwargs)
