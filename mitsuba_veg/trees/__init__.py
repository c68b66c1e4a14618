"""Trees: the shared segment structure, growth (paper 001), non-growth deformation (002) and
Weber-Penn parametric trees with knots and smooth junctions (004).

    import mitsuba_veg as mv
    tree = mv.trees.grow(mv.trees.GrowthParams(), generations=10, position=(0, 0, 0))
    stand = mv.trees.grow_forest([(-3, 0, 0), (3, 0, 0)], scene=mv.trees.Environment.flat_ground())
    res = mv.trees.nongrowth.deform(stand, rules=("death", "heliotropism"))
    tree.metrics(); tree.to_mesh(); tree.export("tree.glb")
"""
from .structure import Tree, Leaves, tube_mesh, leaf_quads  # noqa: F401
from .environment import Environment  # noqa: F401
from .growth import GrowthParams, grow, grow_forest, branching  # noqa: F401
from . import nongrowth  # noqa: F401
from . import weber_penn, knots, junction  # noqa: F401

__all__ = ["Tree", "Leaves", "tube_mesh", "leaf_quads", "Environment", "GrowthParams", "grow",
           "grow_forest", "branching", "nongrowth", "weber_penn", "knots", "junction"]
