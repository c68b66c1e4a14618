"""Gemmae and spores: where they are released and where they land (paper 000 §3.3, §3.6).

- gemma (eq 3.22): B = M + k I, I a uniform random unit vector, k a fixed distance [m];
- spore (eq 3.23): Q = M + l I_N, I_N a random unit vector at an angle φ to the parent's surface
  normal N with 0° < φ < 45° or 135° < φ < 180° (either cone, uniform in solid angle), l fixed;
- a propagule released in the air falls (−y) until it touches a polygon or another moss
  (another moss sits on a polygon: landing in its cell is a conflict, see below); a propagule
  that touches nothing, or lands on the back of a polygon, is removed;
- a propagule landing where an individual already is: the higher priority survives, priority =
  species priority + G_moss (a propagule has G_moss = 0); ties keep the one that was there. Among
  propagules landing in one empty cell the same day, the highest species priority, then the
  lowest parent slot, wins (deterministic).

The release point is reached along a ray from the parent: if that ray meets a surface before the
distance k (or l), the propagule stops there (it cannot pass through walls). All of it is a few
ray casts for the whole day's propagules at once.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .population import MossPopulation
from .spatial import _SLOT_MASK


__all__ = ["uniform_sphere", "spore_direction", "land", "settle"]

def uniform_sphere(u: mi.Point2f) -> mi.Vector3f:
    """Uniform random unit vectors on the sphere (the direction I of a gemma, eq 3.22).

    Parameters
    ----------
    u : mi.Point2f
        Uniform random samples in [0, 1)^2 [-].

    Returns
    -------
    mi.Vector3f
        Unit vectors [-], uniform in solid angle.
    """
    return mi.warp.square_to_uniform_sphere(u)


def spore_direction(nrm: mi.Vector3f, u: mi.Point2f, side: mi.Float) -> mi.Vector3f:
    """Spore directions I_N of eq (3.23), uniform in solid angle within a 45° cone.

    Unit vectors at an angle < 45° to ``nrm`` (side >= 0.5) or > 135° (side < 0.5), uniform in
    solid angle within the cone (eq 3.23).

    Parameters
    ----------
    nrm : mi.Vector3f
        Unit surface normal N of the parent [-].
    u : mi.Point2f
        Uniform random samples in [0, 1)^2 [-] (direction within the cone).
    side : mi.Float
        Uniform random number in [0, 1) [-]: >= 0.5 picks the cone around ``nrm``, < 0.5 the cone
        around ``-nrm``.

    Returns
    -------
    mi.Vector3f
        Unit directions in world space [-].
    """
    cos45 = float(np.cos(np.radians(45.0)))
    local = mi.warp.square_to_uniform_cone(u, cos45)
    n = dr.select(side < 0.5, -nrm, nrm)
    return mi.Frame3f(n).to_world(local)


def land(scene: mi.Scene, lookup: mi.UInt32, origin: mi.Point3f, direction: mi.Vector3f,
         distance: float, active: mi.Bool):
    """Where propagules released from ``origin`` come to rest.

    Move propagules from ``origin`` along ``direction`` by ``distance`` [m] (stopping at the first
    surface), then let them fall along -y.

    Parameters
    ----------
    scene : mi.Scene
        The scene to cast rays into.
    lookup : mi.UInt32
        Registry id of a shape (``si.shape`` reinterpreted as UInt32) -> global index of its
        first element (``SceneIndex.lookup``): ``lookup[shape] + prim_index`` is the element.
    origin : mi.Point3f
        Positions of the parents [m].
    direction : mi.Vector3f
        Unit release directions [-] (I of eq 3.22 or I_N of eq 3.23).
    distance : float
        Release distance k (gemma) or l (spore) [m].
    active : mi.Bool
        Which lanes carry a propagule.

    Returns
    -------
    landed : mi.Bool
        False for those that hit nothing or the back of a polygon.
    elem : mi.UInt32
        Global element (triangle) index of the landing point (valid where ``landed``).
    pos : mi.Point3f
        Landing point [m], lifted 1e-4 m off the surface along its normal.
    nrm : mi.Vector3f
        Surface normal at the landing point [-].
    """
    ray = mi.Ray3f(origin, direction, distance)
    si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal, coherent=False, active=active)
    stopped = active & si.is_valid()
    front1 = dr.dot(si.n, direction) < 0
    release = dr.select(stopped, si.p, origin + direction * distance)
    # falling: straight down from the release point
    down = mi.Vector3f(0.0, -1.0, 0.0)
    fall = active & ~stopped
    si2 = scene.ray_intersect(mi.Ray3f(release, down), ray_flags=mi.RayFlags.Minimal,
                              coherent=False, active=fall)
    hit2 = fall & si2.is_valid()
    front2 = dr.dot(si2.n, down) < 0
    landed = (stopped & front1) | (hit2 & front2)
    p = dr.select(stopped, si.p, si2.p)
    n = dr.select(stopped, si.n, si2.n)
    shape = dr.select(stopped, dr.reinterpret_array(mi.UInt32, si.shape),
                      dr.reinterpret_array(mi.UInt32, si2.shape))
    prim = dr.select(stopped, si.prim_index, si2.prim_index)
    elem = dr.gather(mi.UInt32, lookup, shape, landed) + prim
    # lift the point off the surface a little so later rays do not start inside it
    return landed, elem, mi.Point3f(p + n * 1e-4), mi.Vector3f(n)


def settle(pop: MossPopulation, grid, new_pos: mi.Point3f, new_species: mi.UInt32,
           new_order: mi.UInt32, landed: mi.Bool, may_evict: bool = True):
    """Resolve where propagules may stay (one individual per cell, priority rule above).

    Parameters
    ----------
    pop : MossPopulation
        The population (species priorities, species and G_moss of the occupants).
    grid : SpotGrid
        The spot grid (:class:`~mitsuba_veg.moss.spatial.SpotGrid`), in step with ``pop``
        (``grid.sync(pop.state)`` since the population last changed).
    new_pos : mi.Point3f
        Landing points of the new propagules [m].
    new_species : mi.UInt32
        Species index of each new propagule.
    new_order : mi.UInt32
        Tie-break order of each new propagule among equal species priorities: the lowest wins
        (the day's order: gemmae, then spores, each by parent slot).
    landed : mi.Bool
        Which new propagules landed (the others take no part).
    may_evict : bool
        False when no newcomer can evict an occupant (equal species priorities, no occupant
        with G_moss < 0): the evicted list is then empty without being looked for.

    Returns
    -------
    keep : mi.Bool
        Mask over the new propagules: those that take their cell.
    evicted : mi.UInt32
        The slots of existing individuals that lose their cell.
    cells : mi.UInt32
        The pool cell of every landed propagule (the grid's blocks exist for them).
    """
    # the landing cells' blocks exist from here on: each cell has its own claim entry
    cells = grid.cells(new_pos, landed)
    # among the newcomers of one cell: highest species priority, then lowest order
    pri_new = dr.gather(mi.Float, pop.table.priority, new_species)
    rank = mi.UInt64(dr.gather(mi.UInt32, pop.table.priority_rank, new_species))  # high first
    first = grid.first_per_pool_cell(cells, (rank << 32) | mi.UInt64(new_order), landed)
    # against the individual already there
    there = dr.gather(mi.UInt32, grid.pool, cells, first) & _SLOT_MASK
    has = first & (there > 0)
    slot = dr.select(has, there - 1, 0)
    pri_old = dr.gather(mi.Float, pop.table.priority, dr.gather(mi.UInt32, pop.species, slot, has),
                        has) + dr.gather(mi.Float, pop.growth, slot, has)
    wins = ~has | (pri_new > pri_old)
    keep = first & wins
    if not may_evict:
        return keep, mi.UInt32(), cells
    # each cell has one newcomer at most, so no occupant is evicted twice
    evicted = dr.gather(mi.UInt32, slot, dr.compress(has & wins))
    return keep, evicted, cells
