"""The world's trees as parts of the simulated scene: their wood and leaves in the light scene
(:class:`Canopy`), the leaves' phenology on the device (:class:`Phenology`: leaf-out, paper
003's autumn clock, leaf fall) and the trees themselves (:func:`build_trees`: papers 001, 002,
004 or a user's meshes). The daily pipeline (:mod:`mitsuba_veg.daily`) runs them with the
light, soil and moss of a scenario with ``[[trees]]`` entries."""
from .canopy import Canopy
from .phenology import Phenology, PhenologyParams
from .trees import WorldTree, build_trees

__all__ = ["Canopy", "Phenology", "PhenologyParams", "WorldTree", "build_trees"]
