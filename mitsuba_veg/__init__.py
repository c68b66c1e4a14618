"""mitsuba-veg: grow vegetation from light and render it spectrally with Mitsuba 3.

Importing the package selects a spectral Mitsuba variant (``cuda_ad_spectral`` when CUDA works,
else ``llvm_ad_spectral``) unless one is already set, and registers the package's plugins with
Mitsuba (integrator ``veg_photon_irradiance``, emitter ``veg_sky``).
"""
from __future__ import annotations

from .backend import __version__, select_variant as _select_variant, variant

_select_variant()

from . import errors  # noqa: E402,F401
from . import integrators  # noqa: E402,F401  (registers the Mitsuba plugins)
from . import light  # noqa: E402,F401
from . import climate, moss, scenario, soil, terrain  # noqa: E402,F401
from . import trees  # noqa: E402,F401
from . import foliage  # noqa: E402,F401  (registers the veg_leaf BSDF)
from .daily.run import run  # noqa: E402,F401
from . import world  # noqa: E402,F401  (trees, leaves and moss in one daily loop)
from . import tune  # noqa: E402,F401
from .sweeps import sweep  # noqa: E402,F401  (Dask is imported only when a sweep runs)

__all__ = ["__version__", "variant", "errors", "integrators", "light", "climate", "moss",
           "scenario", "soil", "terrain", "trees", "foliage", "world", "tune", "run", "sweep"]
