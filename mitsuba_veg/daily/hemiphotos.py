"""Hemispherical photographs at fixed points of a world (a scenario's ``[[hemiphotos]]``), taken
by the daily loop on their days, and the files they make.

Each point is ``at = [x, z]`` [m] of the floor, ``height`` above the ground there (default
1 m, the height of a tripod); the lens looks at the zenith, north at the image's top. On each
of its days of the year (``on``, ``"MM-DD"``, default 15 July) the run's hook
(:class:`PhotoSeries`) takes the photograph of the day's world: the scenario's shapes and the
trees with the leaves the day's phenology shows (:class:`~mitsuba_veg.world.visible_canopy.
VisibleCanopy`), by one ray per pixel (:func:`mitsuba_veg.light.fisheye.gap_image`), and
reads it as the field would (:func:`mitsuba_veg.light.gap_fraction.analyse`: gap fractions of
the LAI-2000 rings and of rings of ``ring_width``, openness, effective LAI by the LAI-2000
formula and by Miller's integral, Lang & Xiang's clumping-corrected LAI, the diffuse site
factor for the uniform sky of the daily loop and the standard overcast sky, and the direct and
total site factors of the year's clear-sky sun paths at the site), with the true leaf, wood
and plant area index in the LAI-2000's view cone (74°) beside them
(:meth:`VisibleCanopy.cone_area_index`).

A run writes into ``hemiphotos/``: ``<name>_<date>.png`` (the photograph with the LAI-2000
rings), ``<name>_<date>.csv`` (its tidy table: photo, date, x_m, z_m, height_m, quantity,
ring_lo_deg, ring_hi_deg, value, unit) and ``series.csv`` (one row per photograph: the series
at the fixed points over the years). ``mitsuba-veg hemiphoto RUN_DIR`` takes the same
photographs of any day of a finished run, with a photon pass as the truth of the light.
"""
from __future__ import annotations

import csv
import datetime as _dt
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import mitsuba as mi
import numpy as np

from ..atomic import atomic_write
from ..errors import ParameterError, check_range
from ..light.fisheye import GapImage, Lens, gap_image
from ..light.gap_fraction import LAI2000_RINGS, PhotoAnalysis, analyse, rings_of_width, year_sun
from ..integrators.veg_fisheye import radius_of_zenith
from ..plots import _mpl, save_figure
from ..world.visible_canopy import LeafState, VisibleCanopy

__all__ = ["DEFAULTS", "CONE_DEG", "PhotoPoint", "Photo", "ground_points", "check_clear",
           "points_at",
           "points_from_scenario", "parse_on", "take_photos", "photo_figure", "write_photo",
           "SERIES_COLUMNS", "write_series", "PhotoSeries", "FOLDER"]

#: defaults of a ``[[hemiphotos]]`` entry
DEFAULTS = {"height": 1.0, "on": ["07-15"], "size": 1024, "projection": "equidistant",
            "ring_width": 5.0}
#: half-angle of the view cone of the true area index [deg] (the LAI-2000's outer ring)
CONE_DEG = 74.0
#: the run's folder of photographs
FOLDER = "hemiphotos"


@dataclass
class PhotoPoint:
    """A photo point: its name, floor position and lens.

    Attributes
    ----------
    name : str
        Name (file names, tables).
    x, z : float
        Floor position [m].
    height : float
        Lens height above the ground [m].
    position : numpy.ndarray
        (3,) lens centre [m].
    """

    name: str
    x: float
    z: float
    height: float
    position: np.ndarray


def ground_points(ground, xz, height: float, field_name: str = "--at") -> np.ndarray:
    """Lens centres ``height`` above a ground mesh at floor positions.

    Parameters
    ----------
    ground : mitsuba.Shape
        The terrain (only it is hit: trees and walls above are ignored).
    xz : array_like
        (n, 2) floor positions [m].
    height : float
        Height above the ground [m], 0.01-100.
    field_name : str
        Field named by the error for a point with no ground below it.

    Returns
    -------
    numpy.ndarray
        (n, 3) positions [m].
    """
    check_range("height", height, 0.01, 100.0, fix="lens height above the ground in metres, "
                "e.g. 1")
    p = np.asarray(xz, float).reshape(-1, 2)
    bb = ground.bbox()
    top = float(bb.max[1]) + 1.0
    only = mi.load_dict({"type": "scene", "ground": ground}, optimize=False)
    n = len(p)
    o = mi.Point3f(mi.Float(p[:, 0].astype(np.float32)), mi.Float(np.full(n, top, np.float32)),
                   mi.Float(p[:, 1].astype(np.float32)))
    t = np.asarray(only.ray_intersect_preliminary(mi.Ray3f(o, mi.Vector3f(0, -1, 0))).t, float)
    bad = ~np.isfinite(t)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ParameterError(field_name, f"{p[k, 0]:g},{p[k, 1]:g}", "a floor position over "
                             f"the ground (x {float(bb.min[0]):.3g}..{float(bb.max[0]):.3g}, z "
                             f"{float(bb.min[2]):.3g}..{float(bb.max[2]):.3g} m)",
                             "pick a point on the terrain")
    return np.column_stack([p[:, 0], top - t + float(height), p[:, 1]])


def check_clear(base_scene, positions, heights, field_name: str = "--at", source=None) -> None:
    """Refuse a lens inside or on top of an object of the scene (a log, a rock, a wall): the
    line from the ground up to the lens must be free.

    Parameters
    ----------
    base_scene : mitsuba.Scene
        The scenario's scene (every shape but the trees).
    positions : array_like
        (n, 3) lens centres [m].
    heights : array_like
        (n,) their heights above the ground [m].
    field_name : str
        Field named by the error.
    source : str, optional
        The scenario file, for the error.
    """
    p = np.asarray(positions, float).reshape(-1, 3)
    h = np.broadcast_to(np.asarray(heights, float), (len(p),))
    n = len(p)
    start = p - np.column_stack([np.zeros(n), h - 1e-3, np.zeros(n)])
    o = mi.Point3f(*[mi.Float(start[:, k].astype(np.float32)) for k in range(3)])
    ray = mi.Ray3f(o, mi.Vector3f(0, 1, 0))
    ray.maxt = mi.Float((h - 1e-3).astype(np.float32))
    hit = np.asarray(base_scene.ray_intersect_preliminary(ray).is_valid(), bool)
    if hit.any():
        k = int(np.flatnonzero(hit)[0])
        raise ParameterError(field_name, f"{p[k, 0]:g},{p[k, 2]:g}", "a lens with nothing "
                             "between it and the ground below it (this one would be inside or "
                             "on top of an object of the scene: a log, a rock, a wall)",
                             "move the point a little", source)


def _ground(base_scene, ground_id: str, source=None):
    shapes = {s.id(): s for s in base_scene.shapes()}
    if ground_id not in shapes:
        raise ParameterError("terrain.ground", ground_id, "a shape id of the scene ("
                             + ", ".join(shapes) + ")", None, source)
    return shapes[ground_id]


def points_at(base_scene, ground_id: str, at, height: float = 1.0, names=None) -> list:
    """Photo points at floor positions.

    Parameters
    ----------
    base_scene : mitsuba.Scene
        The scenario's scene (its terrain).
    ground_id : str
        The terrain's shape id.
    at : sequence of (float, float)
        Floor positions (x, z) [m].
    height : float
        Lens height above the ground [m].
    names : sequence of str, optional
        Their names (default ``p1``, ``p2``, ...).

    Returns
    -------
    list of PhotoPoint
        The points.
    """
    at = np.asarray(at, float).reshape(-1, 2)
    pos = ground_points(_ground(base_scene, ground_id), at, height)
    check_clear(base_scene, pos, height)
    names = names or [f"p{i + 1}" for i in range(len(at))]
    return [PhotoPoint(str(n), float(a[0]), float(a[1]), float(height), q)
            for n, a, q in zip(names, at, pos)]


def parse_on(text, field_name: str = "on") -> tuple[int, int]:
    """A day of the year as (month, day) from ``"MM-DD"``.

    Parameters
    ----------
    text : str
        ``"MM-DD"``.
    field_name : str
        Field named by the error.

    Returns
    -------
    tuple of int
        (month, day).
    """
    try:
        m, d = (int(v) for v in str(text).split("-"))
        _dt.date(2024, m, d)                       # a leap year: 02-29 is a day
        return m, d
    except (ValueError, TypeError):
        raise ParameterError(field_name, text, "a day of the year MM-DD", "e.g. \"07-15\"") \
            from None


def points_from_scenario(scn, base_scene) -> list:
    """The photo points of a scenario's ``[[hemiphotos]]`` with their settings.

    Parameters
    ----------
    scn : Scenario
        The loaded scenario.
    base_scene : mitsuba.Scene
        Its scene.

    Returns
    -------
    list of (PhotoPoint, dict)
        Each point and its entry's settings (``on`` as (month, day) pairs, ``size``,
        ``projection``, ``ring_width``); empty without ``[[hemiphotos]]``.
    """
    entries = scn.get("hemiphotos") or []
    if isinstance(entries, dict):
        entries = [entries]
    src = str(scn.path)
    ground = _ground(base_scene, scn.get("terrain.ground", "ground"), src)
    out, names = [], set()
    for k, e in enumerate(entries):
        where = f"hemiphotos[{k}]"
        if "at" not in e:
            raise ParameterError(f"{where}.at", None, "[x, z] [m]: the floor position",
                                 "add at = [x, z]", src)
        name = str(e.get("name", f"photo{k + 1}"))
        if name in names:
            raise ParameterError(f"{where}.name", name, "names unique among the hemiphotos",
                                 "rename one of them", src)
        names.add(name)
        s = {**DEFAULTS, **e}
        try:
            pos = ground_points(ground, [e["at"]], float(s["height"]), f"{where}.at")[0]
            check_clear(base_scene, [pos], float(s["height"]), f"{where}.at")
            s["on"] = [parse_on(t, f"{where}.on") for t in s["on"]]
        except ParameterError as err:
            raise ParameterError(err.field, err.value, err.allowed, err.fix, src) from None
        out.append((PhotoPoint(name, float(e["at"][0]), float(e["at"][1]), float(s["height"]),
                               pos), s))
    return out


@dataclass
class Photo:
    """One photograph and what it tells.

    Attributes
    ----------
    point : PhotoPoint
        Where.
    date : datetime.date
        When.
    image : GapImage
        The binary photograph.
    analysis : PhotoAnalysis
        Gap fractions, LAI, openness, site factors.
    truth : dict
        The true area indices in the view cone (:meth:`VisibleCanopy.cone_area_index`) and,
        after a photon pass, the light's truth.
    """

    point: PhotoPoint
    date: _dt.date
    image: GapImage
    analysis: PhotoAnalysis
    truth: dict = field(default_factory=dict)

    @property
    def stem(self) -> str:
        """File stem ``<name>_<YYYY-MM-DD>``."""
        return f"{self.point.name}_{self.date.isoformat()}"

    def rows(self) -> list[tuple]:
        """The tidy rows of its table.

        Returns
        -------
        list of tuple
            (quantity, ring_lo_deg, ring_hi_deg, value, unit).
        """
        out = self.analysis.rows()
        for k, v in self.truth.items():
            unit = "m2" if k.endswith("_m2") else "m" if k.endswith("_m") else \
                "day" if k == "snapshot_day" else \
                "count" if k in ("leaves", "photons") else "m2 m-2" if k[:3] in ("lai", "wai",
                                                                               "pai") else "-"
            out.append((k, math.nan, math.nan, float(v), unit))
        return out


_SUN: dict = {}


def _year_sun(lat, lon, year):
    key = (round(float(lat), 6), round(float(lon), 6), int(year))
    if key not in _SUN:
        if len(_SUN) > 8:
            _SUN.clear()
        _SUN[key] = year_sun(lat, lon, int(year))
    return _SUN[key]


def take_photos(scene, points, date, canopy: VisibleCanopy, state: LeafState, latitude: float,
                longitude: float, lens: Lens = Lens(), ring_width: float = 5.0,
                sectors: int = 8) -> list:
    """Photographs of a day's scene at photo points, read as the field reads them.

    Parameters
    ----------
    scene : mitsuba.Scene
        The day's scene as a camera sees it (:meth:`VisibleCanopy.scene`).
    points : sequence of PhotoPoint
        Where.
    date : datetime.date
        The day (its year's sun paths give the direct and total site factors).
    canopy : VisibleCanopy
        The trees (the true area indices).
    state : LeafState
        The day's leaves.
    latitude, longitude : float
        The site [deg].
    lens : Lens
        Size, projection and field of view.
    ring_width : float
        Width of the extra rings [deg].
    sectors : int
        Azimuth sectors of Lang & Xiang's average.

    Returns
    -------
    list of Photo
        One per point.
    """
    sun = _year_sun(latitude, longitude, date.year)
    rings = rings_of_width(ring_width)
    out = []
    for p in points:
        img = gap_image(scene, p.position, lens)
        a = analyse(img, rings, sun=sun, sectors=sectors)
        out.append(Photo(p, date, img, a, canopy.cone_area_index(p.position, state, CONE_DEG)))
    return out


def photo_figure(photo: Photo, path, colour=None) -> str:
    """The photograph with the LAI-2000's rings, the cardinal points and its main values.

    Parameters
    ----------
    photo : Photo
        The photograph.
    path : str or pathlib.Path
        The PNG.
    colour : numpy.ndarray, optional
        (h, w, 3) sRGB image [0, 1] of the same lens, drawn beside the binary one.

    Returns
    -------
    str
        The path written.
    """
    plt = _mpl()
    n = photo.image.lens.size
    panels = 2 if colour is not None else 1
    fig, axes = plt.subplots(1, panels, figsize=(5.6 * panels, 6.0), constrained_layout=True)
    axes = np.atleast_1d(axes)
    inside = photo.image.pixel_map()["inside"]
    img = np.where(photo.image.gap, 1.0, 0.18)
    rgb = np.stack([img * 0.85 + (1 - img) * 0.1, img * 0.9 + (1 - img) * 0.35,
                    img * 1.0 + (1 - img) * 0.12], -1)
    rgb[~inside] = 0.0
    shown = [(axes[0], rgb, "binary (ray cast)")]
    if colour is not None:
        shown.append((axes[1], colour, "colour (spectral render)"))
    lens = photo.image.lens
    for ax, im, label in shown:
        ax.imshow(im, extent=(0, n, n, 0), interpolation="nearest")
        for lo, hi in LAI2000_RINGS:
            for th in (lo, hi):
                if th <= 0:
                    continue
                r = float(radius_of_zenith(math.radians(th), lens.projection, lens.theta_max))
                ax.add_patch(plt.Circle((n / 2, n / 2), r * n / 2, fill=False, lw=0.8,
                                        color="tab:orange"))
        for lab, az in (("N", 0), ("E", 90), ("S", 180), ("W", 270)):
            a = math.radians(az)
            ax.text(n / 2 - 0.53 * n * math.sin(a), n / 2 - 0.53 * n * math.cos(a), lab,
                    ha="center", va="center", fontsize=9)
        ax.set_xlim(-0.07 * n, 1.07 * n)
        ax.set_ylim(1.07 * n, -0.07 * n)
        ax.set_axis_off()
        ax.set_title(label, fontsize=9)
    v, t = photo.analysis.values, photo.truth
    p = photo.point
    text = (f"{p.name} ({p.x:g}, {p.z:g}) m, {p.height:g} m up, {photo.date.isoformat()}\n"
            f"openness {v['openness']:.3f}   DSF {v['site_factor_diffuse']:.3f}")
    if "site_factor_direct" in v:
        text += f"   DirSF {v['site_factor_direct']:.3f}   TSF {v.get('site_factor_total', math.nan):.3f}"
    text += (f"\nLAI-2000 Le {v['lai_lai2000']:.2f}   Miller {v['lai_miller']:.2f}   "
             f"Lang-Xiang {v['lai_lang_xiang']:.2f}")
    if "lai_true" in t:
        text += f"   true LAI {t['lai_true']:.2f}, PAI {t['pai_true']:.2f}"
    fig.suptitle(text, fontsize=9)
    return save_figure(fig, path, dpi=90)


def _table_text(photo: Photo) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["photo", "date", "x_m", "z_m", "height_m", "quantity", "ring_lo_deg",
                "ring_hi_deg", "value", "unit"])
    p = photo.point
    for q, lo, hi, v, u in photo.rows():
        w.writerow([p.name, photo.date.isoformat(), f"{p.x:g}", f"{p.z:g}", f"{p.height:g}", q,
                    "" if math.isnan(lo) else f"{lo:g}", "" if math.isnan(hi) else f"{hi:g}",
                    "" if v != v else f"{v:.6g}", u])
    return buf.getvalue()


def write_photo(photo: Photo, folder, colour=None) -> dict:
    """A photograph's PNG (with the ring overlay) and its tidy table.

    Parameters
    ----------
    photo : Photo
        The photograph.
    folder : str or pathlib.Path
        Where (``<name>_<date>.png`` and ``.csv``).
    colour : numpy.ndarray, optional
        Its colour render (sRGB [0, 1]), drawn beside.

    Returns
    -------
    dict
        ``{"png": path, "csv": path}``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    png = photo_figure(photo, folder / f"{photo.stem}.png", colour)
    path = folder / f"{photo.stem}.csv"
    with atomic_write(path, folder / f".{photo.stem}.tmp.csv") as tmp:
        Path(tmp).write_text(_table_text(photo))
    return {"png": png, "csv": str(path)}


#: the series table's columns (one row per photograph)
SERIES_COLUMNS = ["date", "photo", "x_m", "z_m", "height_m"] + \
    [f"gap_{int(lo)}_{int(hi)}" for lo, hi in LAI2000_RINGS] + \
    ["openness", "lai_lai2000", "lai_miller", "lai_lang_xiang", "clumping_index",
     "site_factor_diffuse", "site_factor_diffuse_soc", "site_factor_direct", "site_factor_total",
     "lai_true", "wai_true", "pai_true", "lai_mean_height", "height_qh_m", "lai_plot",
     "site_factor_diffuse_footprint", "site_factor_direct_day",
     "site_factor_direct_day_footprint",
     "sky_direct_share", "sky_direct_share_se", "sky_scattered_share", "sun_direct_share",
     "sun_direct_share_se", "sun_scattered_share", "open_sky_share", "open_sun_share",
     "snapshot_day", "saturated_rings", "saturated_sectors"]


def series_row(photo: Photo) -> dict:
    """One photograph's row of the series table.

    Parameters
    ----------
    photo : Photo
        The photograph.

    Returns
    -------
    dict
        :data:`SERIES_COLUMNS` (NaN for values it lacks).
    """
    p = photo.point
    row = {"date": photo.date.isoformat(), "photo": p.name, "x_m": p.x, "z_m": p.z,
           "height_m": p.height}
    for (lo, hi), g in zip(LAI2000_RINGS, photo.analysis.lai2000_gaps):
        row[f"gap_{int(lo)}_{int(hi)}"] = float(g)
    for k in SERIES_COLUMNS[5 + len(LAI2000_RINGS):]:
        row[k] = float(photo.analysis.values.get(k, photo.truth.get(k, math.nan)))
    return row


def write_series(rows: list, path) -> str:
    """The series table (CSV), written atomically.

    Parameters
    ----------
    rows : list of dict
        Rows of :func:`series_row`.
    path : str or pathlib.Path
        The CSV.

    Returns
    -------
    str
        The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(SERIES_COLUMNS)
    for r in rows:
        w.writerow([r[c] if isinstance(r[c], str) else ("" if r[c] != r[c] else f"{r[c]:.6g}")
                    for c in SERIES_COLUMNS])
    with atomic_write(path, path.with_name(f".{path.stem}.tmp.csv")) as tmp:
        Path(tmp).write_text(buf.getvalue())
    return str(path)


def read_series(path) -> list:
    """Rows of a series table written by :func:`write_series`.

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV.

    Returns
    -------
    list of dict
        Strings for ``date`` and ``photo``, floats otherwise; [] when the file is missing.
    """
    path = Path(path)
    if not path.is_file():
        return []
    out = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            out.append({k: (v if k in ("date", "photo") else (float(v) if v else math.nan))
                        for k, v in r.items() if k in SERIES_COLUMNS})
    return out


class PhotoSeries:
    """The daily loop's hook that takes a scenario's ``[[hemiphotos]]`` on their days (module
    docstring): call it after every day with the simulation and the day's record.

    Parameters
    ----------
    sim : Simulation
        The run (its scenario, site, trees and phenology; ``sim.out`` the run folder).
    """

    def __init__(self, sim):
        scn = sim.config.scn
        self.out = Path(sim.out) / FOLDER
        self.entries = points_from_scenario(scn, scn.load_scene(daylight=False)) \
            if scn.get("hemiphotos") else []
        self.lat = float(scn.get("site.latitude"))
        self.lon = float(scn.get("site.longitude"))
        self.bins = int(sim.config.stage_bins)
        self._canopy = None
        self._trees = None
        self.rows = read_series(self.out / "series.csv")

    def __bool__(self) -> bool:
        return bool(self.entries)

    def __call__(self, sim, rec) -> list:
        """Take the photographs due on the day just simulated.

        Parameters
        ----------
        sim : Simulation
            The run.
        rec : dict
            The day's record (its ``date``).

        Returns
        -------
        list of Photo
            The photographs taken (none on most days).
        """
        if not self.entries:
            return []
        date = _dt.date.fromisoformat(str(rec["date"])[:10])
        due = [(p, s) for p, s in self.entries if (date.month, date.day) in s["on"]]
        if not due:
            return []
        trees = list(sim.trees or [])
        if self._canopy is None or self._trees is None or len(self._trees) != len(trees) or \
                any(a is not b for a, b in zip(self._trees, trees)):
            self._canopy, self._trees = VisibleCanopy(trees, self.bins), trees
        state = LeafState.from_phenology(sim.phen) if sim.phen is not None else \
            LeafState.green(0)
        base = [s for s in sim.scene.shapes() if s.id() in set(sim.site.terrain_shapes)]
        scene = self._canopy.scene(base, state, optics=False)
        photos = []
        groups: dict = {}
        for p, s in due:
            groups.setdefault((int(s["size"]), s["projection"], float(s["ring_width"])),
                              []).append(p)
        for (size, proj, width), pts in groups.items():
            photos += take_photos(scene, pts, date, self._canopy, state, self.lat, self.lon,
                                  Lens(size, proj), width)
        for ph in photos:
            write_photo(ph, self.out)
            self.rows = [r for r in self.rows
                         if (r["date"], r["photo"]) != (ph.date.isoformat(), ph.point.name)]
            self.rows.append(series_row(ph))
        self.rows.sort(key=lambda r: (r["date"], r["photo"]))
        write_series(self.rows, self.out / "series.csv")
        return photos
