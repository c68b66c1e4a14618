"""Scene dicts of the ``veg_leaf`` BSDF from leaf spectra (:func:`leaf_bsdf_dict`).

The BSDF itself (a thin two-sided leaf, diffuse reflectance R(λ) + diffuse transmittance T(λ))
is :class:`mitsuba_veg.integrators.veg_leaf.LeafBSDF`, registered with Mitsuba by
:mod:`mitsuba_veg.integrators`.
"""
from __future__ import annotations

import numpy as np

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.integrators.veg_leaf import PLUGIN_NAME

from .spectra import mitsuba_spectrum

__all__ = ["leaf_bsdf_dict"]


def leaf_bsdf_dict(spectra=None, reflectance=None, transmittance=None, index: int | None = None,
                   id: str | None = None) -> dict:
    """A ``veg_leaf`` BSDF dict from leaf spectra or from explicit R/T values or spectra.

    Parameters
    ----------
    spectra : LeafSpectra, optional
        :class:`~mitsuba_veg.foliage.spectra.LeafSpectra`: its reflectance and transmittance
        become ``regular`` spectra (extended down to 360 nm); row ``index`` when it holds several
        leaves.
    reflectance, transmittance : float or dict, optional
        Used without ``spectra``: a number [-] (a flat ``uniform`` spectrum) or a Mitsuba texture
        / spectrum dict; left out: the plugin's defaults (0.1 and 0.05).
    index : int, optional
        Row of ``spectra`` (required when it holds several leaves).
    id : str, optional
        The BSDF's id in the scene.

    Returns
    -------
    dict
        ``{"type": "veg_leaf", "reflectance": ..., "transmittance": ..., ["id": ...]}`` for
        ``mi.load_dict``.

    Raises
    ------
    ParameterError
        When ``spectra`` holds several leaves and ``index`` is None.
    """
    d: dict = {"type": PLUGIN_NAME}
    if spectra is not None:
        R, T = spectra.reflectance, spectra.transmittance
        if R.ndim > 1:
            if index is None:
                raise ParameterError("index", None, "a row of the spectra", "pick one leaf")
            R, T = R[index], T[index]
        d["reflectance"] = mitsuba_spectrum(spectra.wavelength, R)
        d["transmittance"] = mitsuba_spectrum(spectra.wavelength, T)
    else:
        for name, v in (("reflectance", reflectance), ("transmittance", transmittance)):
            if v is None:
                continue
            d[name] = {"type": "uniform", "value": float(v)} if np.isscalar(v) else v
    if id:
        d["id"] = id
    return d
