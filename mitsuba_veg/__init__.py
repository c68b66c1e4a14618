"""mitsuba-veg: grow vegetation from light and render it spectrally with Mitsuba 3.

Importing the package selects a spectral Mitsuba variant (``cuda_ad_spectral`` when CUDA works,
else ``llvm_ad_spectral``) unless one is already set, and registers the package's plugins with
Mitsuba (:mod:`mitsuba_veg.integrators`, the one folder of every plugin class):

- integrator ``veg_photon_irradiance`` (the photon-irradiance pass),
- emitter ``veg_sky`` (a Perez / CIE clear-sky environment),
- emitters ``veg_sun_path`` (a day of sun directions) and ``veg_sun_steps`` (the sun over one
  step of a sensor study),
- BSDF ``veg_leaf`` (a thin two-sided leaf, diffuse reflectance and transmittance),
- sensor ``veg_fisheye`` (an equidistant or equisolid fisheye camera: hemispherical canopy
  photographs, :mod:`mitsuba_veg.canopy_photo`).
"""
from __future__ import annotations

from .backend import __version__, select_variant as _select_variant, variant

_select_variant()

from . import errors  # noqa: E402,F401
from . import integrators  # noqa: E402,F401  (registers every Mitsuba plugin)
from . import light  # noqa: E402,F401
from . import climate, moss, scenario, soil, terrain  # noqa: E402,F401
from . import trees  # noqa: E402,F401
from . import foliage  # noqa: E402,F401
from .daily.run import run  # noqa: E402,F401
from . import world  # noqa: E402,F401  (trees, leaves and moss in one daily loop)
from . import tune  # noqa: E402,F401
from .sweeps import sweep  # noqa: E402,F401  (Dask is imported only when a sweep runs)

__all__ = ["__version__", "variant", "errors", "integrators", "light", "climate", "moss",
           "scenario", "soil", "terrain", "trees", "foliage", "world", "tune", "run", "sweep"]
