"""The spectral bands of the photon pass: named bands [nm], the band of each of a Mitsuba
spectral sample's 4 wavelength slots, and the result's components and sides."""
from __future__ import annotations

import numpy as np

from mitsuba_veg.errors import ParameterError

__all__ = ["BANDS", "DEFAULT_BANDS", "COMPONENTS", "SIDES", "band_range", "parse_bands"]

#: Named spectral bands [nm]. "total" is Mitsuba's spectral range (360-830 nm, what its
#: irradiancemeter integrates); "shortwave" is the solar broadband range used for energy budgets.
BANDS: dict[str, tuple[float, float]] = {
    "total": (360.0, 830.0),
    "par": (400.0, 700.0),
    "red": (655.0, 665.0),
    "far_red": (725.0, 735.0),
    "shortwave": (300.0, 3000.0),
    "blue": (400.0, 500.0),
    "green": (500.0, 600.0),
    "nir": (700.0, 1100.0),
}

#: the bands a pass records unless told otherwise
DEFAULT_BANDS = ("total", "par", "red", "far_red")
#: components of a result: first hit, later hits, their sum
COMPONENTS = ("direct", "indirect", "total")
#: sides of an element: the one its geometric normal faces, the other
SIDES = ("front", "back")
_SLOTS = 4  # wavelengths carried by one Mitsuba spectral sample


def _scalar(x) -> float:
    """A Python float from a width-1 Dr.Jit array (a reduction result)."""
    return float(np.asarray(x, dtype=np.float64).ravel()[0])

def band_range(band) -> tuple[float, float]:
    """Wavelength range [nm] of a band given by name (see :data:`BANDS`) or as (min, max).

    Parameters
    ----------
    band : str or tuple of float
        A name of :data:`BANDS` or a (min_nm, max_nm) pair [nm], 0 < min_nm < max_nm.

    Returns
    -------
    tuple of float
        (min_nm, max_nm) [nm].
    """
    if isinstance(band, str):
        if band not in BANDS:
            raise ParameterError("band", band, f"one of {sorted(BANDS)} or a (min_nm, max_nm) pair",
                                 "use a known band name or pass the wavelength range explicitly")
        return BANDS[band]
    try:
        lo, hi = (float(v) for v in band)
    except (TypeError, ValueError):
        raise ParameterError("band", band, "a band name or a (min_nm, max_nm) pair") from None
    if not (0 < lo < hi):
        raise ParameterError("band", band, "0 < min_nm < max_nm", "swap or fix the bounds")
    return lo, hi


def _band_name(band) -> str:
    if isinstance(band, str):
        return band
    lo, hi = band_range(band)
    return f"{lo:g}-{hi:g}nm"


def parse_bands(spec) -> tuple:
    """Bands from a property string ``"total,par,500-510"`` (or a sequence): names or ranges.

    Parameters
    ----------
    spec : str or sequence
        Comma-separated band names of :data:`BANDS` or ``"min-max"`` ranges [nm].

    Returns
    -------
    tuple
        Band names and (min_nm, max_nm) pairs, validated by :func:`band_range`.
    """
    if not isinstance(spec, str):
        return tuple(spec)
    out = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        if item in BANDS:
            out.append(item)
            continue
        lo, sep, hi = item.partition("-")
        try:
            out.append((float(lo), float(hi)))
        except ValueError:
            raise ParameterError("bands", spec, f"comma-separated names of {sorted(BANDS)} or "
                                 "'min-max' ranges in nm", "e.g. \"total,par,500-510\"") from None
    for b in out:
        band_range(b)
    if not out:
        raise ParameterError("bands", spec, "at least one band", "e.g. \"total\"")
    return tuple(out)
