"""Foliage: pigments and autumn colour (paper 003), leaf spectra (PROSPECT-D), scene dicts of the
``veg_leaf`` BSDF, Barnsley maple leaves, insolation per leaf, red/far-red attenuation and
spectral light studies. See docs/foliage.md.

The Mitsuba BSDF plugin ``veg_leaf`` (a thin bi-Lambertian leaf with spectral reflectance and
transmittance) is :class:`mitsuba_veg.integrators.veg_leaf.LeafBSDF`, registered by
:mod:`mitsuba_veg.integrators`; :func:`leaf_bsdf_dict` builds its scene dicts.
"""
from __future__ import annotations

from .bsdf import leaf_bsdf_dict
from .pigments import (LeafTraits, pigments_at_stage, pigments_at_tau, stage_from_tau,
                       stage_table, tau_from_stage, vary_pigments)
from .prospect import prospect_d
from .spectra import LeafSpectra, leaf_spectra, mitsuba_spectrum, spectrum_to_srgb
from .attenuation import (absorbed_fraction, growth_alphas, red_far_red_attenuation,
                          with_leaf_optics)
from .autumn import AutumnParams, AutumnState, apply_to_tree, autumn_time
from .ifs import MapleLeaf, chaos_game, leaf_image, maple_leaf
from .insolation import (InsolationResult, SunPath, instantaneous_insolation, leaf_insolation,
                         shadow_scene, sky_view_factor, sun_path)
from .light_study import run_light_study

__all__ = ["leaf_bsdf_dict", "LeafTraits", "pigments_at_stage", "pigments_at_tau",
           "stage_from_tau", "stage_table", "tau_from_stage", "vary_pigments", "prospect_d",
           "LeafSpectra", "leaf_spectra", "mitsuba_spectrum", "spectrum_to_srgb",
           "absorbed_fraction", "growth_alphas", "red_far_red_attenuation", "with_leaf_optics",
           "AutumnParams", "AutumnState",
           "apply_to_tree", "autumn_time", "MapleLeaf", "chaos_game", "leaf_image", "maple_leaf",
           "InsolationResult", "SunPath", "instantaneous_insolation", "leaf_insolation",
           "shadow_scene", "sky_view_factor", "sun_path", "run_light_study"]
