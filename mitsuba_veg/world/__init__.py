"""One living world: trees (papers 001, 002, 004), their foliage (003) and the moss (000) in one
daily photon loop (:class:`WorldSimulation`), from a scenario with ``[[trees]]`` entries."""
from .canopy import Canopy
from .phenology import Phenology, PhenologyParams
from .simulation import WorldSimulation, band_shapes
from .trees import WorldTree, build_trees

__all__ = ["Canopy", "Phenology", "PhenologyParams", "WorldSimulation", "WorldTree",
           "band_shapes", "build_trees"]
