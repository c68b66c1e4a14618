"""Physical constants (SI, exact since 2019) and the energy-to-photon conversion of a band."""
from __future__ import annotations

__all__ = ["PLANCK", "LIGHT_SPEED", "AVOGADRO", "umol_per_joule"]

#: Planck constant h [J s]
PLANCK = 6.62607015e-34
#: speed of light c [m s-1]
LIGHT_SPEED = 2.99792458e8
#: Avogadro constant N_A [mol-1]
AVOGADRO = 6.02214076e23


def umol_per_joule(lo_nm: float, hi_nm: float) -> float:
    """Photons per joule of a narrow band, at its centre wavelength [µmol J-1].

    Parameters
    ----------
    lo_nm, hi_nm : float
        Band limits [nm].

    Returns
    -------
    float
        lambda / (h c N_A) x 1e6 at lambda = (lo + hi) / 2: 4.57 for PAR's 550 nm centre (the
        flat-spectrum value; the exact value of a spectrum is
        :func:`mitsuba_veg.light.clear_sky.photon_flux`), exact to < 0.1 % for 10 nm bands
        such as red (655-665) and far-red (725-735).
    """
    lam = 0.5 * (lo_nm + hi_nm) * 1e-9
    return lam / (PLANCK * LIGHT_SPEED) / AVOGADRO * 1e6
