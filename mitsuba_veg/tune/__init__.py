"""Differentiable parameter tuning with Dr.Jit (docs/tuning.md).

- :mod:`.relax`      smooth relaxations of the moss thresholds, temperature t (t -> 0: discrete);
- :mod:`.smooth`     the relaxed daily soil + moss model on a scenario's triangles
                     (:func:`prepare`, :class:`SmoothMossModel`);
- :mod:`.dispersal`  expected propagule landing kernels (eqs 3.22-3.23);
- :mod:`.grad`       gradients through many days (optionally checkpointed), finite differences;
- :mod:`.fitting`        ``fit(scenario, target, params=[...], loss=..., steps=...)`` with Adam;
- :mod:`.discrete`   the discrete run as a function of parameters (common random numbers) and
                     ``fit_discrete`` / ``fit_discrete_experiments``: fits of the discrete
                     model by defect correction (one or several experiments);
- :mod:`.photo`      a photographed map (image + camera) -> covered fraction per triangle;
- :mod:`.light_fit`  ``fit_light``: emitter strengths / reflectances from a PAR or R:FR map;
- :mod:`.leaf_colour` ``fit_leaf_colour(target, params=("Cab", "Car", "Anth"), ...)``: pigment
                     contents from a leaf colour or spectrum (PROSPECT-D in Dr.Jit).
"""
from __future__ import annotations

from . import dispersal, grad, lifecycle, relax, smooth  # noqa: F401
from .fitting import FitResult, coverage_figure, coverage_from_checkpoint, fit  # noqa: F401
from .grad import finite_difference, value_and_grad  # noqa: F401
from . import leaf_colour  # noqa: F401
from . import discrete, light_fit, photo  # noqa: F401
from .discrete import (DiscreteExperiment, DiscreteMossModel, fit_discrete,  # noqa: F401
                       fit_discrete_experiments)
from .light_fit import LightStudy, fit_light  # noqa: F401
from .photo import cover_from_image, render_cover_image  # noqa: F401
from .leaf_colour import (LeafColourFit, colour_sensitivity, fit_leaf_colour,  # noqa: F401
                          predict_leaf_colour)
from .smooth import ModelData, RunResult, SmoothMossModel, prepare  # noqa: F401

__all__ = ["relax", "lifecycle", "smooth", "dispersal", "grad", "prepare",
           "SmoothMossModel", "ModelData", "RunResult", "value_and_grad", "finite_difference",
           "fit", "FitResult", "coverage_figure", "coverage_from_checkpoint", "leaf_colour",
           "fit_leaf_colour", "LeafColourFit", "colour_sensitivity", "predict_leaf_colour",
           "discrete", "DiscreteMossModel", "fit_discrete", "DiscreteExperiment",
           "fit_discrete_experiments", "light_fit", "LightStudy",
           "fit_light", "photo", "cover_from_image", "render_cover_image"]
