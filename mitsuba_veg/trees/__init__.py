"""Trees: the shared segment structure, growth (paper 001), non-growth deformation (002) and
Weber-Penn parametric trees with knots and smooth junctions (004)."""
from .structure import Tree, Leaves, tube_mesh, leaf_quads  # noqa: F401

__all__ = ["Tree", "Leaves", "tube_mesh", "leaf_quads"]
