"""Spectral materials of the final render: reflectance spectra and Mitsuba BSDF dicts.

Every material is an explicit spectrum over Mitsuba's range (360-830 nm, 5 nm steps), never an
RGB colour: RGB is up-sampled inside the visible range only and means nothing at 730 nm, and the
render's far-red band must see the vegetation's red edge.

- **Measured** (``mitsuba_veg/data/earthlib_spectra.csv``, from the Earth Library, earthlib
  1.1.0, MIT licence; ``scripts/vendor_earthlib.py`` documents the selection): soils (``humus``,
  ``humus_light``: the 8th and 22nd percentiles of 4,185 soil spectra, the darker, organic end),
  ``sand``, ``asphalt``, ``gravel``, ``concrete`` (sidewalks), ``bark``, ``wood`` and leaf
  ``litter``, each with a dark or light variant for texture. earthlib starts at 400 nm; below,
  the curves are extended linearly.
- **Fitted** (no measured library curve at hand): ``stone`` (weathered granite-like rock, flat
  and grey, rising a little into the red), ``grass`` (a meadow, for surroundings) and the moss
  species (chlorophyll: a little green,
  absorption near 670 nm, the red edge at ~700-740 nm up to a near-infrared plateau). Their band
  means agree with the moss model's albedo per band (``[moss] albedo`` of the moss garden: red
  0.05, far-red 0.45) within a few hundredths; ``band_mean`` reports them.

Leaves use PROSPECT-D spectra and the two-sided ``veg_leaf`` BSDF (:mod:`mitsuba_veg.foliage`).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..foliage import leaf_bsdf_dict, leaf_spectra

#: wavelength grid of every material spectrum [nm]
WAVELENGTHS = np.arange(360.0, 830.0 + 1e-9, 5.0)


def _logistic(x, x0, w):
    return 1.0 / (1.0 + np.exp(-(x - x0) / w))


def _gauss(x, x0, s):
    return np.exp(-0.5 * ((x - x0) / s) ** 2)


def _vegetation(blue, green, red, nir, yellow=0.0, edge=705.0, edge_width=11.0,
                green_width=32.0):
    """Chlorophyll vegetation: low blue, a green bump at 550 nm, a red trough at ~670 nm and the
    red edge (logistic at ``edge``) up to the near-infrared plateau ``nir``."""
    wl = WAVELENGTHS
    base = blue + (red - blue) * _logistic(wl, 600.0, 25.0)
    bump = (green - blue) * _gauss(wl, 552.0, green_width) + yellow * _gauss(wl, 600.0, 25.0)
    vis = base + bump
    redge = _logistic(wl, edge, edge_width)
    return vis * (1.0 - redge) + nir * redge


#: the measured curves (earthlib), one column per material
MEASURED_FILE = Path(__file__).resolve().parents[1] / "data" / "earthlib_spectra.csv"


def _measured() -> dict:
    lines = [ln for ln in MEASURED_FILE.read_text().splitlines() if not ln.startswith("#")]
    rows = list(csv.reader(lines))
    a = np.array(rows[1:], float)
    if not np.allclose(a[:, 0], WAVELENGTHS):
        raise ValueError(f"{MEASURED_FILE}: wavelengths are not 360-830 nm in 5 nm steps")
    return {name: a[:, j + 1] for j, name in enumerate(rows[0][1:])}


def _spectra() -> dict:
    wl = WAVELENGTHS
    s = {
        **_measured(),
        # a meadow (the courtyard's surroundings): chlorophyll, a little dry grass
        "grass": _vegetation(0.035, 0.11, 0.045, 0.42, yellow=0.02, green_width=30.0),
        "grass_light": _vegetation(0.05, 0.15, 0.08, 0.46, yellow=0.05, green_width=34.0),
        # rock: no measured curve at hand (earthlib has none); weathered granite-like grey
        "stone": 0.2 + 0.07 * _logistic(wl, 560.0, 90.0),
        "stone_light": 0.26 + 0.08 * _logistic(wl, 560.0, 90.0),
        # moss: established (dark) and young/tip (light) tones per species
        # (silver moss: hyaline leaf tips make its young shoots silvery grey-green; Hypnum
        # yellowish to golden green; Polytrichum dark green)
        "bryum_argenteum": _vegetation(0.04, 0.11, 0.055, 0.44, yellow=0.01, green_width=30.0),
        "bryum_argenteum_light": _vegetation(0.11, 0.19, 0.13, 0.52, green_width=45.0),
        "hypnum_plumaeforme": _vegetation(0.025, 0.10, 0.035, 0.42, yellow=0.025,
                                          green_width=28.0),
        "hypnum_plumaeforme_light": _vegetation(0.035, 0.16, 0.06, 0.48, yellow=0.05,
                                                green_width=30.0),
        "polytrichum": _vegetation(0.02, 0.065, 0.025, 0.38, green_width=26.0),
        "polytrichum_light": _vegetation(0.03, 0.10, 0.035, 0.44, yellow=0.01, green_width=26.0),
    }
    return {k: np.clip(v, 0.0, 0.95) for k, v in s.items()}


#: every material: name -> reflectance on :data:`WAVELENGTHS` [-]
SPECTRA: dict[str, np.ndarray] = _spectra()
#: geology class (mitsuba_veg.terrain.GEOLOGY order) -> material name
GEOLOGY_MATERIAL = {"humus": "humus", "sand": "sand", "asphalt": "asphalt"}
#: moss species key -> material name (other species use hypnum_plumaeforme's)
MOSS_MATERIAL = {"bryum_argenteum": "bryum_argenteum",
                 "hypnum_plumaeforme": "hypnum_plumaeforme",
                 "polytrichum": "polytrichum"}


def spectrum(name_or_values) -> np.ndarray:
    """Reflectance on :data:`WAVELENGTHS`: a material name or an array of that length.

    Parameters
    ----------
    name_or_values : str, float or array_like
        A key of :data:`SPECTRA`, a constant reflectance [-], or 95 reflectances [-] on
        360-830 nm in 5 nm steps.

    Returns
    -------
    numpy.ndarray
        Reflectance (95,) [-] on :data:`WAVELENGTHS` [nm].

    Raises
    ------
    ParameterError
        If the name is unknown or the array has another length.
    """
    if isinstance(name_or_values, str):
        if name_or_values not in SPECTRA:
            raise ParameterError("material", name_or_values, "one of " + ", ".join(sorted(SPECTRA)),
                                 "use a built-in material name or give a spectrum")
        return SPECTRA[name_or_values]
    v = np.asarray(name_or_values, float)
    if v.ndim == 0:
        return np.full(len(WAVELENGTHS), float(v))
    if v.shape != WAVELENGTHS.shape:
        raise ParameterError("material spectrum", v.shape, f"{len(WAVELENGTHS)} values on "
                             "360-830 nm in 5 nm steps")
    return v


def regular(values) -> dict:
    """A Mitsuba ``regular`` spectrum dict on :data:`WAVELENGTHS`.

    Parameters
    ----------
    values : str, float or array_like
        As for :func:`spectrum`: a material name or reflectances [-].

    Returns
    -------
    dict
        ``{"type": "regular", "wavelength_min": 360, "wavelength_max": 830, "values": ...}``
        (wavelengths [nm]).
    """
    v = spectrum(values)
    return {"type": "regular", "wavelength_min": float(WAVELENGTHS[0]),
            "wavelength_max": float(WAVELENGTHS[-1]),
            "values": ", ".join(f"{x:.5g}" for x in v)}


def diffuse(name_or_values) -> dict:
    """A ``diffuse`` BSDF dict with an explicit spectral reflectance.

    Parameters
    ----------
    name_or_values : str, float or array_like
        As for :func:`spectrum`: a material name or reflectances [-].

    Returns
    -------
    dict
        The BSDF dict.
    """
    return {"type": "diffuse", "reflectance": regular(name_or_values)}


def blend(bsdf0: dict, bsdf1: dict, weight) -> dict:
    """``blendbsdf``: weight 0 -> ``bsdf0``, 1 -> ``bsdf1``.

    Parameters
    ----------
    bsdf0, bsdf1 : dict
        The two BSDF dicts.
    weight : float or dict
        Blend weight in [0, 1] [-]: a number (a ``uniform`` texture) or a texture dict.

    Returns
    -------
    dict
        The ``blendbsdf`` dict.
    """
    w = {"type": "uniform", "value": float(weight)} if np.isscalar(weight) else weight
    return {"type": "blendbsdf", "weight": w, "bsdf_0": bsdf0, "bsdf_1": bsdf1}


def band_mean(name_or_values, lo: float, hi: float) -> float:
    """Mean reflectance over [lo, hi] nm (linear interpolation of the 5-nm grid).

    Parameters
    ----------
    name_or_values : str, float or array_like
        As for :func:`spectrum`: a material name or reflectances [-].
    lo, hi : float
        Band edges [nm].

    Returns
    -------
    float
        Band-mean reflectance [-] (64 evenly spaced wavelengths).
    """
    x = np.linspace(lo, hi, 64)
    return float(np.interp(x, WAVELENGTHS, spectrum(name_or_values)).mean())


def srgb(name_or_values, exposure: float = 1.0) -> np.ndarray:
    """sRGB (0-1, gamma-encoded) of a reflectance under D65, for legends and checks.

    Parameters
    ----------
    name_or_values : str, float or array_like
        As for :func:`spectrum`: a material name or reflectances [-].
    exposure : float, optional
        Factor on XYZ before encoding [-] (default 1: a perfect white reflector has Y = 1).

    Returns
    -------
    numpy.ndarray
        sRGB (3,) in [0, 1] [-].
    """
    import colour
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    wl = np.arange(380.0, 781.0, 5.0)
    r = np.interp(wl, WAVELENGTHS, spectrum(name_or_values))
    xyz_bar = np.stack([np.interp(wl, cmfs.wavelengths, cmfs.values[:, i]) for i in range(3)], 1)
    e = np.interp(wl, d65.wavelengths, d65.values)
    XYZ = (r * e) @ xyz_bar / (e @ xyz_bar[:, 1]) * exposure
    rgb = colour.XYZ_to_sRGB(XYZ)
    return np.clip(rgb, 0.0, 1.0)


# ---- leaves ----------------------------------------------------------------------------------
def leaf_bsdf(tau: float = 0.0) -> dict:
    """BSDF dict of a leaf at autumn logical time ``tau``.

    PROSPECT-D reflectance and transmittance (paper 003) in the two-sided ``veg_leaf`` BSDF.

    Parameters
    ----------
    tau : float, optional
        Autumn logical time [-], clipped to 0 (green) .. 1 (red) (default 0).

    Returns
    -------
    dict
        The ``veg_leaf`` BSDF dict.
    """
    return leaf_bsdf_dict(leaf_spectra(tau=float(np.clip(tau, 0.0, 1.0))))


__all__ = ["WAVELENGTHS", "SPECTRA", "GEOLOGY_MATERIAL", "MOSS_MATERIAL", "spectrum", "regular",
           "diffuse", "blend", "band_mean", "srgb", "leaf_bsdf"]
