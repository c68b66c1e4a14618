"""The moss life cycle of paper 000 §3.6 on cohorts of expected densities (relaxed, Dr.Jit).

Why cohorts are exact: in the discrete model (``moss/population.py``) the daily fitness G of a
moss depends only on its triangle's environment and its species (eq 3.17), so every moss of one
species on one triangle that germinated on the same day has the same G_moss (eq 3.21), the same
gemma counter, and dies on the same day. Waiting propagules of one kind made on the same day on
one triangle have the same age L and the same germination test (eq 3.24). Holding the *number*
of individuals of each such cohort loses nothing; the relaxed model holds its expectation.

Per species, flat element-major Float arrays (element e, cohort / slot c: index e * C + c):

- ``n[e, c]``  moss per spot of cohort c: c = 0 the initial moss, c = 1 + day // cohort_days
  the moss that germinated in that birth window;
- ``B[e, c]``  growth offset: G_moss = cum[e] - B[e, c] with ``cum`` the running sum of the
  triangle's daily growth D (eq 3.20); a cohort born on day b has B = cum before day b;
- ``K[e, c]``  gemmae released per moss so far (discrete: ``gemmae`` = floor(max G_moss / 0.5));
- ``pg[e, j]``, ``ps[e, j]``: gemmae / spores per spot in ring slot j, made on a day b with
  b = j mod R; R = L1 + 1 slots, so every age 1 .. L1 + 1 is tested, then the slot is reused.

Per-element quantities are broadcast to the cohorts with ``dr.repeat`` and summed back with
``dr.block_sum``. Everything that changes from day to day (today's cohort and ring slot, the ages
of the slots) enters the kernels as opaque values or arrays, so every day runs the same kernels
(compiled once, then cached). (A version holding one array per cohort fused a day into fewer,
much larger kernels, but every variation of them - which scalar inputs alias, which adjoints
are zero - cost seconds of LLVM compilation: slower overall.)

The day (order of ``MossPopulation.live_day``): 1. germination of every slot with probability
``H_t(G g(L) - tau_b)``; 2. the new cohort gets the germinated density, G_moss = 0; growth
``cum += D``; death ``n *= 1 - H_t(tau_d - G_moss) H_t(-(G - tau_g))``; 3. gemmae
``K' = max(K, floor_t(max(G_moss, 0) / 0.5))``, released ``n (K' - K)`` times the share of moss
on the surface of a clump; 4. spores ``n H_t(G_moss - 2) H_t(G - tau_g)``. With t = 0 every step
is the discrete rule; :func:`mitsuba_veg.tune.relax.heaviside` etc. give the relaxation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..moss.fitness_model import (GEMMA_L0, GEMMA_L1, SPORE_L0, SPORE_L1, daily_fitness,
                                   fitness)
from ..moss.population import GEMMA, MOSS, PROPAGULE, SPORE, MossPopulation, SpeciesTable
from ..moss.species import PARAMETER_FIELDS
from . import relax

__all__ = ["SpeciesState", "CohortLifeCycle", "relaxed_life_cycle", "discrete_life_cycle", "GEMMA_STEP", "SPORE_THRESHOLD",
           "species_fitness", "real_type"]

GEMMA_STEP = 0.5          #: G_moss per gemma (population.py)
SPORE_THRESHOLD = 2.0     #: G_moss from which growing moss release spores (population.py)


def real_type(precision: str = "float32"):
    """The Dr.Jit AD float type of the active backend for ``"float32"`` or ``"float64"``.

    Parameters
    ----------
    precision : str
        ``"float32"`` or ``"float64"``.

    Returns
    -------
    type
        The Dr.Jit float array type (AD-enabled) of the active Mitsuba variant.

    Raises
    ------
    ValueError
        For another precision.
    """
    if precision not in ("float32", "float64"):
        raise ValueError(f"precision must be 'float32' or 'float64', not {precision!r}")
    return dr.float64_array_t(mi.Float) if precision == "float64" else dr.float32_array_t(mi.Float)


@dataclass
class SpeciesState:
    """Relaxed state of one species (see module docstring)."""

    n: object
    B: object
    K: object
    cum: object
    pg: object
    ps: object

    FIELDS = ("n", "B", "K", "cum", "pg", "ps")

    def arrays(self) -> list:
        """The state's arrays in the order of ``FIELDS``.

        Returns
        -------
        list
            ``[n, B, K, cum, pg, ps]`` (Dr.Jit float arrays).
        """
        return [getattr(self, f) for f in self.FIELDS]

    @staticmethod
    def from_arrays(a: list, *sizes) -> "SpeciesState":
        """The state from its arrays (inverse of :meth:`arrays`).

        Parameters
        ----------
        a : list
            ``[n, B, K, cum, pg, ps]`` (further entries are ignored).
        *sizes : int
            Ignored (kept for callers that pass the ring sizes).

        Returns
        -------
        SpeciesState
            The state.
        """
        return SpeciesState(*a[:6])


def species_fitness(p: dict, Ts, rhs, S):
    """Daily fitness G of eq 3.17 for species parameters ``p`` (numbers or Dr.Jit scalars).

    Parameters
    ----------
    p : dict
        Species parameters by name (``T0, T1, nT, rh0, rh1, nrh, S0, S1, nS``; temperatures
        [K], humidity [-], insolation [W m-2], tolerances [-]).
    Ts : Dr.Jit float array
        Surface temperature per element [K].
    rhs : Dr.Jit float array
        Surface relative humidity per element [-].
    S : Dr.Jit float array
        Daily-mean insolation per element [W m-2].

    Returns
    -------
    Dr.Jit float array
        G per element [-].
    """
    return daily_fitness(p, Ts, rhs, S)


class CohortLifeCycle:
    """Relaxed life cycle for ``n`` elements over at most ``days`` days (see module docstring).

    temperature: t of :mod:`.relax` (0: exact discrete thresholds); cohort_days: birth days
    merged into one moss cohort (1 = exact); precision: "float32" or "float64".
    """

    def __init__(self, n: int, days: int, temperature: float = 0.05, cohort_days: int = 1,
                 precision: str = "float32"):
        self.T = real_type(precision)
        self.n = int(n)
        self.days = int(days)
        self.cohort_days = max(int(cohort_days), 1)
        self.C = 1 + -(-self.days // self.cohort_days)   # initial cohort + birth windows
        self.Rg = int(min(int(GEMMA_L1) + 1, self.days + 1))
        self.Rs = int(min(int(SPORE_L1) + 1, self.days + 1))
        u = dr.uint32_array_t(self.T)
        self.slot_C = dr.tile(dr.arange(u, self.C), self.n)
        self.slot_g = dr.tile(dr.arange(u, self.Rg), self.n)
        self.slot_s = dr.tile(dr.arange(u, self.Rs), self.n)
        self.t_value = float(temperature)
        if not (self.t_value >= 0 and math.isfinite(self.t_value)):
            raise ValueError(f"temperature must be a number >= 0, not {temperature!r}")
        # opaque: a new temperature does not recompile the kernels
        self.t = 0.0 if self.t_value == 0 else dr.opaque(self.T, self.t_value)

    @property
    def arrays_per_species(self) -> int:
        """Arrays in a :class:`SpeciesState`.

        Returns
        -------
        int
            6.
        """
        return 6

    # ---- construction -----------------------------------------------------------------------
    def empty(self) -> SpeciesState:
        """A species with no moss and no propagules.

        Returns
        -------
        SpeciesState
            Zero arrays (cohorts and ring slots of every element).
        """
        T, n = self.T, self.n
        st = SpeciesState(dr.zeros(T, n * self.C), dr.zeros(T, n * self.C),
                          dr.zeros(T, n * self.C), dr.zeros(T, n), dr.zeros(T, n * self.Rg),
                          dr.zeros(T, n * self.Rs))
        return st

    def _arr(self, x):
        return x if dr.is_array_v(x) else self.T(np.broadcast_to(np.asarray(x, float),
                                                                 (self.n,)).copy())

    def seed_moss(self, s: SpeciesState, density, growth: float) -> SpeciesState:
        """Put ``density`` (per element) of established moss with G_moss = ``growth`` into the
        initial cohort (c = 0), its gemma counter at floor(growth / 0.5) as in population.py.

        Parameters
        ----------
        s : SpeciesState
            The state (modified and returned).
        density : array_like or Dr.Jit float array
            Moss per spot on each element [-].
        growth : float
            Their G_moss [-].

        Returns
        -------
        SpeciesState
            ``s``.
        """
        first = self.slot_C == 0
        s.n = dr.select(first, s.n + dr.repeat(self._arr(density), self.C), s.n)
        s.B = dr.select(first, -float(growth), s.B)
        s.K = dr.select(first, float(math.floor(max(growth, 0.0) / GEMMA_STEP)), s.K)
        return s

    def seed_propagules(self, s: SpeciesState, kind: str, density) -> SpeciesState:
        """Add propagules made yesterday (tested first on day 0, with L = 1).

        Parameters
        ----------
        s : SpeciesState
            The state (modified and returned).
        kind : str
            ``"gemma"`` or ``"spore"``.
        density : array_like or Dr.Jit float array
            Propagules per spot on each element [-].

        Returns
        -------
        SpeciesState
            ``s``.
        """
        return self.push(s, kind, density, -1, add=True)

    def push(self, s: SpeciesState, kind: str, density, day: int, add: bool = False):
        """Store the propagules of ``kind`` made on ``day`` in their ring slot.

        Parameters
        ----------
        s : SpeciesState
            The state (modified and returned).
        kind : str
            ``"gemma"`` or ``"spore"``.
        density : array_like or Dr.Jit float array
            Propagules per spot on each element [-].
        day : int
            The day they were made (0-based; -1: before the first day).
        add : bool
            Add to what the slot holds instead of replacing its old, expired content.

        Returns
        -------
        SpeciesState
            ``s``.
        """
        if kind == "gemma":
            R, slot, arr = self.Rg, self.slot_g, s.pg
        else:
            R, slot, arr = self.Rs, self.slot_s, s.ps
        m = slot == dr.opaque(dr.uint32_array_t(self.T), day % R)
        v = dr.repeat(self._arr(density), R)
        new = dr.select(m, arr + v if add else v, arr)
        if kind == "gemma":
            s.pg = new
        else:
            s.ps = new
        return s

    # ---- queries ----------------------------------------------------------------------------
    def moss(self, s: SpeciesState):
        """Moss per spot of each element, all cohorts.

        Parameters
        ----------
        s : SpeciesState
            The state.

        Returns
        -------
        Dr.Jit float array
            (elements,) moss per spot [-].
        """
        return dr.block_sum(s.n, self.C)

    def waiting(self, s: SpeciesState):
        """Waiting propagules (gemmae and spores) per spot of each element.

        Parameters
        ----------
        s : SpeciesState
            The state.

        Returns
        -------
        Dr.Jit float array
            (elements,) propagules per spot [-].
        """
        return dr.block_sum(s.pg, self.Rg) + dr.block_sum(s.ps, self.Rs)

    def ring(self, R: int, day: int, L0: float, L1: float):
        """Per slot of a ring of R slots on ``day``: g(L, L0, L1, 1) of eq 3.24 for its age L
        (slot j holds what was made on the latest day b < day, b = j mod R).

        Parameters
        ----------
        R : int
            Slots in the ring.
        day : int
            The day (0-based).
        L0, L1 : float
            Germination window of eq 3.24 [day].

        Returns
        -------
        numpy.ndarray
            (R,) g(L) [-].
        """
        L = ((day - 1 - np.arange(R)) % R) + 1.0
        return np.asarray(fitness(L, L0, L1, 1.0), float)

    def alive_after(self, R: int, day: int, L1: float):
        """Per slot of a ring of R slots on ``day``: 1 if what is left there after the
        germination test may wait on (age L <= L1), 0 if it expires today (L > L1).

        Parameters
        ----------
        R : int
            Slots in the ring.
        day : int
            The day (0-based).
        L1 : float
            Upper end of the germination window [day].

        Returns
        -------
        numpy.ndarray
            (R,) 0 or 1.
        """
        L = ((day - 1 - np.arange(R)) % R) + 1.0
        return (L <= L1).astype(float)

    # ---- the day ----------------------------------------------------------------------------
    def live(self, s: SpeciesState, G, p: dict, day: int):
        """Steps 1-2 of ``day``: germination, the new cohort, growth and death.

        Parameters
        ----------
        s : SpeciesState
            The state at the start of the day.
        G : Dr.Jit float array
            The day's fitness per element (eq 3.17) [-].
        p : dict
            Species parameters by name (``alpha_g, tau_g, tau_b, tau_d`` used here) [-].
        day : int
            The day (0-based).

        Returns
        -------
        state : SpeciesState
            The new state.
        Gm : Dr.Jit float array
            G_moss per cohort [-].
        Dg : Dr.Jit float array
            G - tau_g per element [-] (the sign of the growth D).
        germinated : Dr.Jit float array
            Germinated per spot of each element [-].
        """
        T, n, C, t = self.T, self.n, self.C, self.t
        Dg = G - p["tau_g"]                       # D / alpha_g: the sign of D (eq 3.20)
        D = p["alpha_g"] * Dg
        # 1. germination (eq 3.24): G g(L, L0, L1, 1) > tau_b, per age slot; the slot of age
        # L1 + 1 (> L1) is tested once more and then reused by today's push
        glg = dr.tile(T(self.ring(self.Rg, day, GEMMA_L0, GEMMA_L1)), n)
        gls = dr.tile(T(self.ring(self.Rs, day, SPORE_L0, SPORE_L1)), n)
        germ_g = s.pg * relax.heaviside(dr.repeat(G, self.Rg) * glg - p["tau_b"], t)
        germ_s = s.ps * relax.heaviside(dr.repeat(G, self.Rs) * gls - p["tau_b"], t)
        # what failed in the slot of age L1 + 1 has expired: its spots are free *today*, before
        # the day's newcomers settle (population.py frees them in live_day)
        pg = (s.pg - germ_g) * dr.tile(T(self.alive_after(self.Rg, day, GEMMA_L1)), n)
        ps = (s.ps - germ_s) * dr.tile(T(self.alive_after(self.Rs, day, SPORE_L1)), n)
        ngerm = dr.block_sum(germ_g, self.Rg) + dr.block_sum(germ_s, self.Rs)
        # 2. the day's cohort starts at G_moss = 0; then growth (eqs 3.20-3.21) and death
        is_new = self.slot_C == dr.opaque(dr.uint32_array_t(T), 1 + day // self.cohort_days)
        g_rep = dr.repeat(ngerm, C)
        c_rep = dr.repeat(s.cum, C)
        if self.cohort_days == 1:
            nn = dr.select(is_new, s.n + g_rep, s.n)
            B = dr.select(is_new, c_rep, s.B)
            K = dr.select(is_new, 0.0, s.K)
        else:  # merge into the window's cohort: density-weighted offset and counter
            tot = s.n + g_rep
            pos = tot > 0
            safe = dr.select(pos, tot, 1.0)
            nn = dr.select(is_new, tot, s.n)
            B = dr.select(is_new, dr.select(pos, (s.n * s.B + g_rep * c_rep) / safe, c_rep), s.B)
            K = dr.select(is_new, dr.select(pos, s.n * s.K / safe, 0.0), s.K)
        cum = s.cum + D
        Gm = dr.repeat(cum, C) - B
        die = relax.heaviside(p["tau_d"] - Gm, t) * dr.repeat(relax.heaviside(-Dg, t), C)
        nn = nn * (1.0 - die)
        return SpeciesState(nn, B, K, cum, pg, ps), Gm, Dg, ngerm

    def produce(self, s: SpeciesState, Gm, Dg, surface=1.0):
        """Steps 3-4: gemmae and spores made per spot of each element (updates ``s.K``).

        Parameters
        ----------
        s : SpeciesState
            The state after :meth:`live` (its ``K`` is updated).
        Gm : Dr.Jit float array
            G_moss per cohort [-].
        Dg : Dr.Jit float array
            G - tau_g per element [-].
        surface : float or Dr.Jit float array
            Per element, the share of moss on the surface of a clump [-] (only those release
            gemmae; the counter of the others moves on, as in population.py).

        Returns
        -------
        gemmae : Dr.Jit float array
            Gemmae made per spot of each element [-].
        spores : Dr.Jit float array
            Spores made per spot of each element [-].
        """
        t = self.t
        steps = relax.soft_floor(dr.maximum(Gm, 0.0) * (1.0 / GEMMA_STEP), t / GEMMA_STEP)
        Knew = dr.maximum(s.K, steps)
        gem = dr.block_sum(s.n * (Knew - s.K), self.C) * surface
        s.K = Knew
        spo = dr.block_sum(s.n * relax.heaviside(Gm - SPORE_THRESHOLD, t, strict=False),
                           self.C) * relax.heaviside(Dg, t)
        return gem, spo


# ---- the life cycle alone, relaxed and discrete (the t -> 0 limit) ---------------------------
def relaxed_life_cycle(species, env, start, t: float, growth0: float = 1.0,
                       precision: str = "float64") -> dict:
    """One species on n triangles for the days of ``env`` = (S [W m-2], Ts [K], rhs [-]), each
    an array [days, n], without space (no landing).

    Parameters
    ----------
    species : Species
        The species.
    env : tuple of numpy.ndarray
        (S [W m-2], Ts [K], rhs [-]), each (days, n).
    start : tuple of array_like
        (moss, gemmae, spores) per triangle at the start [-].
    t : float
        Temperature of the relaxation [-] (0: exact).
    growth0 : float
        G_moss of the initial moss [-].
    precision : str
        ``"float32"`` or ``"float64"``.

    Returns
    -------
    dict
        ``moss`` (alive), ``gemmae``, ``spores`` (made): arrays (days, n) [-].
    """
    (S, Ts, rhs), (m0, g0, s0) = env, start
    days, n = S.shape
    T = real_type(precision)
    p = {f: float(getattr(species, f)) for f in PARAMETER_FIELDS}
    life = CohortLifeCycle(n, days, t, precision=precision)
    s = life.seed_moss(life.empty(), np.asarray(m0, float), growth0)
    s = life.seed_propagules(s, "gemma", np.asarray(g0, float))
    s = life.seed_propagules(s, "spore", np.asarray(s0, float))
    out = {"moss": [], "gemmae": [], "spores": []}
    zero = dr.zeros(T, n)
    for d in range(days):
        G = species_fitness(p, T(Ts[d]), T(rhs[d]), T(S[d]))
        s, Gm, Dg, _ = life.live(s, G, p, d)
        gem, spo = life.produce(s, Gm, Dg, 1.0)
        life.push(s, "gemma", zero, d)
        life.push(s, "spore", zero, d)
        dr.make_opaque(s.arrays())
        out["moss"].append(np.asarray(life.moss(s)))
        out["gemmae"].append(np.asarray(gem))
        out["spores"].append(np.asarray(spo))
    return {k: np.array(v, float) for k, v in out.items()}


def discrete_life_cycle(species, env, start, growth0: float = 1.0,
                        capacity: int = 4096) -> dict:
    """The same with the discrete population (``MossPopulation.live_day``, individuals).

    Parameters
    ----------
    species : Species
        The species.
    env : tuple of numpy.ndarray
        (S [W m-2], Ts [K], rhs [-]), each (days, n).
    start : tuple of array_like
        (moss, gemmae, spores) per triangle at the start (integers) [-].
    growth0 : float
        G_moss of the initial moss [-].
    capacity : int
        Slots of the population.

    Returns
    -------
    dict
        ``moss`` (alive), ``gemmae``, ``spores`` (parents that day): arrays (days, n) [-].
    """
    (S, Ts, rhs), (m0, g0, s0) = env, start
    days, n = S.shape
    pop = MossPopulation(capacity, SpeciesTable([species]))

    def add(state, kind, counts, growth):
        el = np.repeat(np.arange(n), counts).astype(np.uint32)
        z = mi.Float(np.zeros(len(el), np.float32))
        pop.add(state, mi.UInt32(np.zeros(len(el), np.uint32)), kind, mi.UInt32(el),
                mi.Point3f(z, z, z), mi.Vector3f(z, z, z), growth)

    add(MOSS, GEMMA, m0, growth0)
    add(PROPAGULE, GEMMA, g0, 0.0)
    add(PROPAGULE, SPORE, s0, 0.0)
    out = {"moss": [], "gemmae": [], "spores": []}
    for d in range(days):
        gem, spo, _ = pop.live_day(mi.Float(S[d]), mi.Float(Ts[d]), mi.Float(rhs[d]))
        el = np.asarray(pop.elem)
        out["moss"].append(np.bincount(el[np.asarray(pop.state) == MOSS], minlength=n))
        out["gemmae"].append(np.bincount(el[np.asarray(gem)], minlength=n))
        out["spores"].append(np.bincount(el[np.asarray(spo)], minlength=n))
    return {k: np.array(v, float) for k, v in out.items()}
