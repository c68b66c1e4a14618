"""Foliage: pigments and autumn colour (paper 003), leaf spectra (PROSPECT-D), the ``veg_leaf``
BSDF, Barnsley maple leaves, insolation per leaf, and spectral light studies.

Importing this package registers the Mitsuba BSDF plugin ``veg_leaf`` (a thin bi-Lambertian
leaf with spectral reflectance and transmittance).
"""
from __future__ import annotations

import mitsuba_veg as _mv  # noqa: F401  (selects a spectral variant first)

from .bsdf import LeafBSDF, leaf_bsdf_dict, register as _register_bsdf
from .pigments import (LeafTraits, pigments_at_stage, pigments_at_tau, stage_from_tau,
                       stage_table, tau_from_stage, vary_pigments)
from .prospect import prospect_d
from .spectra import LeafSpectra, leaf_spectra, mitsuba_spectrum, spectrum_to_srgb

_register_bsdf()

__all__ = ["LeafBSDF", "leaf_bsdf_dict", "LeafTraits", "pigments_at_stage", "pigments_at_tau",
           "stage_from_tau", "stage_table", "tau_from_stage", "vary_pigments", "prospect_d",
           "LeafSpectra", "leaf_spectra", "mitsuba_spectrum", "spectrum_to_srgb"]
