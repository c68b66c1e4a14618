"""The growth year of the world's trees that grow from their light (paper 001 in the world).

Every day the leaves of the trees of ``model = "growth"`` add the light the world's photon
pass gave them (:class:`YearLight`, device arrays, one value per leaf):

- S_l: the two-sided insolation [W m-2 d] (the autumn clock's S_leaf);
- R_l, FR_l: the red (655-665 nm) and far-red (725-735 nm) band irradiance on both sides
  [W m-2 d];
- N_l: the insolation on the side the blade's geometric normal g_l faces minus the other
  side's [W m-2 d]: the component g_l · F of the net flux vector F;
- and, on the days the leaf is on the tree, the open's references: the horizontal insolation
  B + D and the open's red and far-red band irradiance (B and D times the day's clear-sky band
  shapes times the band width).

At the end of each calendar year (the night of 31 December, when the leaves are down) every
growth tree grows one generation (:func:`mitsuba_veg.world.trees.regrow`, paper 001 §2.3) with
each leaf sphere's light from its leaves' sums (:meth:`DayGrowth.tip_lights`)::

    received  = Σ S_l / Σ B + D                          (eq 2.3's fraction of the open's light)
    R:FR      = (Σ R_l / Σ FR_l) / (Σ R_open / Σ FR_open)  (eq 2.5's ratio, 1 in the open)
    vector    = F / |F|,  F = argmin Σ (g_l · F − N_l)²      (eq 2.4's direction: where the net
                                                           light comes from)

over the sphere's leaves. The model's own sky (paper 001's H x V cells) is not used: the light
is the world's, with its sun path, sky, walls, other trees and their leaves' optics.
"""
from __future__ import annotations

import datetime as _dt

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import host_array
from ..light.photon import band_range
from ..plots import _mpl, plan_map, save_figure
from ..trees.growth import TipLight
from ..units import umol_per_joule
from ..world.trees import adapts, ages

__all__ = ["GROWTH_MODEL", "YearLight", "DayGrowth", "sphere_light", "floor_year", "floor_figure",
           "floor_years_figure"]

#: the model of the trees that grow from their light
GROWTH_MODEL = "growth"


class YearLight:
    """Per-leaf sums of the growth year so far (module docstring), and per ground triangle the
    floor's (PAR, red and far-red irradiance [W m-2 d], sky fraction [d]: the yearly floor
    maps), on the device.

    Parameters
    ----------
    n : int
        Leaves of the canopy.
    n_ground : int
        Triangles of the ground.
    """

    FIELDS = ("S", "red", "far_red", "net", "open_S", "open_red", "open_far_red")
    FLOOR_FIELDS = ("floor_par", "floor_red", "floor_far_red", "floor_sky")

    def __init__(self, n: int, n_ground: int = 0):
        self.n, self.n_ground = int(n), int(n_ground)
        for f in self.FIELDS:
            setattr(self, f, dr.zeros(mi.Float64, self.n))
        for f in self.FLOOR_FIELDS:
            setattr(self, f, dr.zeros(mi.Float64, self.n_ground))
        self.days = 0

    def arrays(self) -> list:
        """The sums, in :attr:`FIELDS` order.

        Returns
        -------
        list
            mi.Float64 arrays, one value per leaf.
        """
        return [getattr(self, f) for f in self.FIELDS + self.FLOOR_FIELDS]

    def to_numpy(self) -> dict:
        """The sums for a checkpoint.

        Returns
        -------
        dict
            ``year_light/<field>`` -> (n,) float64, ``year_light/days``.
        """
        d = {f"year_light/{f}": np.asarray(getattr(self, f), np.float64)
             for f in self.FIELDS + self.FLOOR_FIELDS}
        d["year_light/days"] = np.array(self.days)
        return d

    def load_numpy(self, d: dict) -> None:
        """Restore the sums from a checkpoint (:meth:`to_numpy`).

        Parameters
        ----------
        d : dict
            The checkpoint's arrays.

        Raises
        ------
        ValueError
            When a sum does not have one value per leaf.
        """
        for f in self.FIELDS + self.FLOOR_FIELDS:
            v = np.asarray(d[f"year_light/{f}"], np.float64)
            n = self.n if f in self.FIELDS else self.n_ground
            if v.shape != (n,):
                raise ValueError(f"year_light/{f}: {v.shape} != ({n},)")
            setattr(self, f, host_array(mi.Float64, v))
        self.days = int(d["year_light/days"])


class DayGrowth:
    """The growth stage: the day's leaf light into the year's sums, and the year's end
    (module docstring).

    Parameters
    ----------
    site : Site
        The run's site; its trees of ``model = "growth"`` grow.
    """

    def __init__(self, site):
        self.site = site
        c = site.canopy
        self.trees = [i for i, wt in enumerate(site.trees)
                      if wt.model == GROWTH_MODEL and wt.tree is not None]
        #: Weber-Penn trees that age every year (``age`` in their scenario entry)
        self.ageing = [i for i, wt in enumerate(site.trees) if ages(wt)]
        #: Weber-Penn trees that paper 002's death rule adapts every year (``adapt_yearly``)
        self.adapting = [i for i, wt in enumerate(site.trees) if adapts(wt)]
        self.n = c.n_leaves
        self.widths = {b: band_range(b)[1] - band_range(b)[0] for b in ("red", "far_red")}

    def new_state(self) -> YearLight:
        """Empty sums for a new year.

        Returns
        -------
        YearLight
            Zeros, one per leaf and per ground triangle.
        """
        gsl = self.site.ground_slice
        return YearLight(self.n, gsl.stop - gsl.start)

    def accumulate(self, yl: YearLight, light, vals) -> list:
        """Add the day's leaf light (module docstring) to the sums; unevaluated.

        Parameters
        ----------
        yl : YearLight
            The sums (updated).
        light : DayLightResult
            The day's light (its ``S_leaf``, ``leaf``, ``S_leaf_net``, ``leaf_area``).
        vals : DayValues
            The day's inputs (B, D, band shapes).

        Returns
        -------
        list
            The new sums, for the day's evaluation.
        """
        on = dr.select(light.leaf_area > 0, 1.0, 0.0)
        B, D = mi.Float64(vals.weather["beam"]), mi.Float64(vals.weather["diffuse"])

        def band(b):
            return (B * mi.Float64(vals.shapes["beam", b])
                    + D * mi.Float64(vals.shapes["diffuse", b])) * self.widths[b]
        yl.S = yl.S + light.S_leaf
        yl.red = yl.red + light.leaf["red"]
        yl.far_red = yl.far_red + light.leaf["far_red"]
        if light.S_leaf_net is not None:
            yl.net = yl.net + light.S_leaf_net
        yl.open_S = yl.open_S + on * (B + D)
        yl.open_red = yl.open_red + on * band("red")
        yl.open_far_red = yl.open_far_red + on * band("far_red")
        # the floor: its bands and its sky fraction (the terrain comes first in the index)
        yl.floor_par = yl.floor_par + light.ground["par"]
        yl.floor_red = yl.floor_red + light.ground["red"]
        yl.floor_far_red = yl.floor_far_red + light.ground["far_red"]
        yl.floor_sky = yl.floor_sky + light.f_sky_ground
        yl.days += 1
        return yl.arrays()

    @staticmethod
    def is_year_end(date: _dt.date) -> bool:
        """Whether the trees grow after this day: the last day of a calendar year.

        Parameters
        ----------
        date : datetime.date
            The day just simulated.

        Returns
        -------
        bool
            True on 31 December.
        """
        return date.month == 12 and date.day == 31

    def tip_lights(self, yl: YearLight) -> dict:
        """The light of every leaf sphere of every growth tree from the year's sums (read
        back once a year).

        Parameters
        ----------
        yl : YearLight
            The year's sums.

        Returns
        -------
        dict
            ``{tree index: TipLight}`` for the trees whose leaves were out this year.
        """
        c = self.site.canopy
        v = {f: np.asarray(getattr(yl, f), np.float64) for f in YearLight.FIELDS}
        out = {}
        for i in self.trees:
            wt = self.site.trees[i]
            leaves = c.leaves_of(i)
            m = len(wt.tree.attrs["leaf_sphere_segment"])
            sphere = np.asarray(wt.tree.leaves.attrs["sphere"], np.int64)
            if len(sphere) != leaves.stop - leaves.start or m == 0:
                continue
            lt = sphere_light({f: x[leaves] for f, x in v.items()}, self._normals(leaves),
                              sphere, m)
            if lt is not None:
                out[i] = lt
        return out

    def _normals(self, leaves: slice) -> np.ndarray:
        """(k, 3) geometric unit normal of these leaves (each its first triangle's: the pass's
        "front" side); computed when a growth tree asks, once a year (a stand of Weber-Penn
        trees never does: 6.7 M leaves of a hectare would be 0.5 GB of temporaries)."""
        c = self.site.canopy
        t = c.tri[c._first[leaves]]
        g = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-30)

    def leaf_lights(self, yl: YearLight) -> dict:
        """The year's light of every leaf of the trees that adapt (paper 002), relative to the
        open: Σ S_l / Σ (B + D) over the days the leaf was out (read back once a year).

        Parameters
        ----------
        yl : YearLight
            The year's sums.

        Returns
        -------
        dict
            ``{tree index: (leaves,) float64}`` for the adapting trees whose leaves were out
            this year.
        """
        if not self.adapting:
            return {}
        c = self.site.canopy
        S = np.asarray(yl.S, np.float64)
        open_s = np.asarray(yl.open_S, np.float64)
        out = {}
        for i in self.adapting:
            leaves = c.leaves_of(i)
            o = open_s[leaves]
            if len(o) and np.any(o > 0):
                out[i] = np.where(o > 0, S[leaves] / np.maximum(o, 1e-300), 0.0)
        return out


def sphere_light(sums: dict, normals, sphere, m: int):
    """The light of ``m`` leaf spheres from their leaves' year sums (module docstring).

    Parameters
    ----------
    sums : dict
        Per leaf: ``S``, ``red``, ``far_red``, ``net``, ``open_S``, ``open_red``,
        ``open_far_red`` (:class:`YearLight`'s fields, as NumPy arrays).
    normals : array_like
        (leaves, 3) unit geometric normal of each leaf.
    sphere : array_like
        (leaves,) the leaf sphere of each leaf, 0 .. m - 1.
    m : int
        Leaf spheres.

    Returns
    -------
    TipLight or None
        Received light relative to the open, red : far-red relative to the open and the unit
        light vector of each sphere; None when no leaf was out (no light to grow from).
    """
    sphere = np.asarray(sphere, np.int64)
    g = np.asarray(normals, float).reshape(-1, 3)

    def per(x):
        return np.bincount(sphere, weights=np.asarray(x, float), minlength=m)
    open_s = per(sums["open_S"])
    if not np.any(open_s > 0):
        return None
    lit = open_s > 0
    received = np.where(lit, per(sums["S"]) / np.maximum(open_s, 1e-300), 0.0)
    open_ratio = per(sums["open_red"]) / np.maximum(per(sums["open_far_red"]), 1e-300)
    ratio = per(sums["red"]) / np.maximum(per(sums["far_red"]), 1e-300)
    rfr = np.where(lit, ratio / np.maximum(open_ratio, 1e-300), 1.0)
    # the net flux vector F per sphere by least squares: (Σ g gᵀ) F = Σ g N
    A = np.zeros((m, 3, 3))
    np.add.at(A, sphere, g[:, :, None] * g[:, None, :])
    b = np.zeros((m, 3))
    np.add.at(b, sphere, g * np.asarray(sums["net"], float)[:, None])
    reg = 1e-9 * np.maximum(np.trace(A, axis1=1, axis2=2), 1e-30)[:, None, None]
    F = np.linalg.solve(A + reg * np.eye(3), b[:, :, None])[:, :, 0]
    norm = np.linalg.norm(F, axis=1)
    vec = np.where(norm[:, None] > 0, F / np.maximum(norm, 1e-300)[:, None],
                   np.array([0.0, 1.0, 0.0]))
    # a sphere whose leaves were never out got no light: it dies
    return TipLight(received, rfr, vec)


def floor_year(yl: YearLight, areas, cover) -> dict:
    """The floor's year from the year's sums: per ground triangle the mean PAR [W m-2], the
    daily light integral DLI [mol m-2 d-1], the red : far-red photon ratio and the sky fraction
    [-] (the share of the open's sky light that reaches it, direct and reflected: the floor's
    gap fraction), and their area-weighted means with the moss cover (read back once a year).

    Parameters
    ----------
    yl : YearLight
        The year's sums (``days`` of them).
    areas : array_like
        (ground triangles,) areas [m2].
    cover : array_like
        (ground triangles,) moss cover at the year's end [-].

    Returns
    -------
    dict
        ``maps`` (``par_W_m2``, ``dli_mol_m2_d``, ``red_far_red``, ``sky_fraction``, ``cover``:
        NumPy arrays) and the means (``dli_mol_m2_d``, ``red_far_red``, ``gap_fraction``,
        ``moss_cover``, ``moss_covered_m2``, ``days``).
    """
    days = max(int(yl.days), 1)
    a = np.asarray(areas, float)
    par = np.asarray(yl.floor_par, float) / days
    red = np.asarray(yl.floor_red, float) * umol_per_joule(*band_range("red"))
    fr = np.asarray(yl.floor_far_red, float) * umol_per_joule(*band_range("far_red"))
    sky = np.asarray(yl.floor_sky, float) / days
    dli = par * umol_per_joule(*band_range("par")) * 86_400 / 1e6
    rfr = np.where(fr > 0, red / np.maximum(fr, 1e-300), np.nan)
    cover = np.asarray(cover, float)
    w = a / max(a.sum(), 1e-30)
    return {"maps": {"par_W_m2": par, "dli_mol_m2_d": dli, "red_far_red": rfr,
                     "sky_fraction": sky, "cover": cover},
            "days": int(yl.days),
            "dli_mol_m2_d": float((dli * w).sum()),
            "red_far_red": float(red.sum() / fr.sum()) if fr.sum() > 0 else None,
            "gap_fraction": float((sky * w).sum()),
            "moss_cover": float((cover * w).sum()),
            "moss_covered_m2": float((cover * a).sum())}


def floor_figure(path, vertices, faces, year: int, floor: dict, trees=()) -> str:
    """``years/floor_<year>.png``: the floor seen from above, four panels (moss cover at the
    year's end, DLI, red : far-red, sky fraction) with the crowns (dashed) and trunks.

    Parameters
    ----------
    path : path-like
        The PNG (written atomically).
    vertices, faces : array_like
        The ground mesh.
    year : int
        The year shown.
    floor : dict
        :func:`floor_year`'s result.
    trees : sequence of WorldTree
        The trees of that year.

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    m = floor["maps"]
    # a fixed layout: the constrained one took a third of the figure's time (once a year,
    # but on the stand's critical path)
    fig, axs = plt.subplots(1, 4, figsize=(17, 4.1))
    fig.subplots_adjust(left=0.04, right=0.985, bottom=0.12, top=0.84, wspace=0.32)
    plan_map(axs[0], vertices, faces, m["cover"], title="moss cover at the year's end",
             label="cover [-]", cmap="Greens", vmin=0.0, vmax=1.0)
    plan_map(axs[1], vertices, faces, m["dli_mol_m2_d"], title="daily light integral",
             label="DLI [mol m$^{-2}$ d$^{-1}$]", cmap="inferno", vmin=0.0)
    plan_map(axs[2], vertices, faces, m["red_far_red"], title="red : far-red",
             label="R:FR [-]", cmap="RdYlGn", vmin=0.0)
    plan_map(axs[3], vertices, faces, m["sky_fraction"], title="sky fraction (gap fraction)",
             label="[-]", cmap="Blues", vmin=0.0, vmax=1.0)
    # the crowns as one dashed line (circles apart by NaN) and the trunks as one marker line
    # per panel: a hectare's 300 trees as single artists took 4 s a year
    t = np.r_[np.linspace(0.0, 2.0 * np.pi, 65), np.nan]
    ring = np.concatenate([np.c_[c[0] + r * np.cos(t), -c[1] + r * np.sin(t)]
                           for c, r in ((wt.crown_centre(), wt.crown_radius())
                                        for wt in trees)]) if len(trees) else np.zeros((0, 2))
    trunks = np.array([[wt.position[0], -wt.position[2]] for wt in trees]).reshape(-1, 2)
    for ax in axs:
        ax.autoscale(False)
        if len(trees):
            ax.plot(ring[:, 0], ring[:, 1], "--", lw=0.6, color="tab:green")
            ax.plot(trunks[:, 0], trunks[:, 1], "^", color="saddlebrown", ms=3, ls="none")
    rfr = floor["red_far_red"]
    fig.suptitle(f"{year}: moss cover {floor['moss_covered_m2']:.2f} m², DLI "
                 f"{floor['dli_mol_m2_d']:.1f} mol m⁻² d⁻¹, R:FR "
                 + (f"{rfr:.2f}" if rfr is not None else "-")
                 + f", gap fraction {floor['gap_fraction']:.2f}", fontsize=11)
    return save_figure(fig, path)


def floor_years_figure(path, rows: list) -> str:
    """``floor_years.png``: the floor's moss cover, DLI, R:FR and gap fraction year by year.

    Parameters
    ----------
    path : path-like
        The PNG (written atomically).
    rows : list of dict
        One per year: ``year`` and :func:`floor_year`'s means.

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    years = [r["year"] for r in rows]
    fig, axs = plt.subplots(1, 4, figsize=(15, 3.4))
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.17, top=0.86, wspace=0.35)
    for ax, key, label in zip(axs, ("moss_covered_m2", "dli_mol_m2_d", "red_far_red",
                                    "gap_fraction"),
                              ("moss cover [m²]", "DLI [mol m⁻² d⁻¹]", "R:FR [-]",
                               "gap fraction [-]")):
        ax.plot(years, [r[key] if r[key] is not None else np.nan for r in rows], "o-",
                color="tab:green" if key == "moss_covered_m2" else "tab:blue")
        ax.set_xlabel("year")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.suptitle("the forest floor year by year", fontsize=11)
    return save_figure(fig, path)
