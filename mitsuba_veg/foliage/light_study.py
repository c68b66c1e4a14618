"""Spectral light studies: PAR, red, far-red and red:far-red under trees, per ground triangle and
per leaf (``mitsuba-veg light-study``).

:func:`run_light_study` takes a scenario TOML, a Mitsuba XML scene, a loaded ``mi.Scene``, a
:class:`~mitsuba_veg.trees.Tree`, or ``"sphere-tree"`` (a built-in test tree), traces one photon
pass (:func:`mitsuba_veg.light.photon_irradiance`, bands total / PAR / red / far-red, direct +
indirect) and writes into ``out_dir``:

- ``light_maps.png``: plan-view maps of the ground: PPFD (PAR photons), red and far-red
  irradiance, and the red:far-red photon ratio, each with a colour bar;
- ``light_study.npz``: per ground triangle ``ground/par_W_m2`` ... ``ground/rfr``, geometry,
  and per leaf ``leaves/*`` (when the scene has leaves);
- ``leaves.csv``: one row per leaf: position, PAR [W m-2 and µmol m-2 s-1], red, far-red [W m-2],
  R:FR (light arriving on both faces per unit one-sided leaf area);
- ``summary.json``: settings, open-sky reference, means, fractions of open light, timings;
- ``sensors.csv``, ``sensors.parquet``: with a scenario that has ``[[sensors]]``, their readings
  from the same pass (tidy: time, sensor, band, component, value, unit; docs/sensors.md).

With ``--year`` or ``--from``/``--to`` the command makes sensor time series instead
(:mod:`mitsuba_veg.foliage.light_series`). The command line is :mod:`mitsuba_veg.cli.light_study`.

Leaves are meshes whose shape id starts with ``leaves`` and whose triangles come in pairs
(one quad per leaf, as :func:`mitsuba_veg.trees.structure.leaf_quads` makes them); in trees built
here they carry the ``veg_leaf`` BSDF with PROSPECT-D spectra of their autumn stage.
"""
from __future__ import annotations

import time
from pathlib import Path

import mitsuba as mi
import numpy as np

from mitsuba_veg.atomic import atomic_write
from mitsuba_veg.errors import ParameterError, SceneError, check_range
from mitsuba_veg.light import photon_irradiance
from mitsuba_veg.light import sensors as S
from mitsuba_veg.light.clear_sky import (_day_of_year, band_irradiance, clear_sky_spectra,
                                        daylight_from_angles, photon_flux, red_far_red_ratio)
from mitsuba_veg.light.sensors import from_scenario
from mitsuba_veg.light.solar_position import sun_position
from mitsuba_veg.light.validation import grid_mesh
from mitsuba_veg.outputs import OutputFolder, write_json
from mitsuba_veg.plots import _mpl, plan_map
from mitsuba_veg.defaults import check_light
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.trees.structure import Tree
from mitsuba_veg.units import umol_per_joule
from mitsuba_veg.backend import versions

from .bsdf import leaf_bsdf_dict
from .canopy import bark_mesh_arrays, class_meshes, mesh, sphere_crown_tree
from .light_series import _write_table
from .pigments import LeafTraits
from .spectra import leaf_spectra

__all__ = ["BANDS", "DEFAULT_WHEN", "stage_classes", "tree_scene", "leaf_values", "open_reference",
           "run_light_study", "light_maps_figure"]

#: the bands of a light study's photon pass
BANDS = ("total", "par", "red", "far_red")
#: the time of a light study unless given (ISO 8601 with offset)
DEFAULT_WHEN = "2026-07-15T12:00:00+09:00"


# --------------------------------------------------------------------------------------------
# Scenes from trees
# --------------------------------------------------------------------------------------------
def stage_classes(tau, n_classes: int = 7) -> np.ndarray:
    """Integer class per leaf from τ (n_classes bins over [0, 1]).

    Parameters
    ----------
    tau : array_like
        Autumn logical time τ [-] per leaf (clipped to [0, 1]).
    n_classes : int
        Number of equal bins (default 7).

    Returns
    -------
    numpy.ndarray
        Class index per leaf in 0 .. n_classes − 1 (int).
    """
    t = np.clip(np.asarray(tau, float), 0.0, 1.0)
    return np.minimum((t * n_classes).astype(int), n_classes - 1)


def tree_scene(tree, *, emitters: dict, tau=None, n_classes: int = 7, ground=True,
               ground_extent: float | None = None, ground_resolution: int = 60,
               ground_albedo: float = 0.15, bark_albedo: float = 0.2, obstacles=(),
               traits=None):
    """A Mitsuba scene of a tree over a square ground grid.

    Shapes: ground (id ``ground``), bark (``bark``, grey diffuse), leaves in ``n_classes`` autumn
    classes (ids ``leaves_k``, ``veg_leaf`` BSDF with the PROSPECT-D spectra of the class's mean
    τ; all green when ``tau`` is None), obstacles (``obstacle0``...) and ``emitters`` (e.g.
    :func:`mitsuba_veg.light.daylight_from_angles`).

    Parameters
    ----------
    tree : Tree or Leaves
        The tree (leaves and live branches) or leaves only.
    emitters : dict
        Mitsuba emitter dicts by id.
    tau : array_like, optional
        (n_leaves,) autumn logical time [-] per leaf (default: green, τ = 0).
    n_classes : int
        Autumn classes (:func:`stage_classes`, default 7).
    ground : bool
        Add the ground grid (default True).
    ground_extent : float, optional
        Side of the square ground [m], centred on the leaves' mean (x, z); default four times the
        leaves' largest horizontal offset from it (at least 2 m).
    ground_resolution : int
        Cells per side of the ground grid (default 60; two triangles per cell).
    ground_albedo : float
        Diffuse reflectance of the ground [-] (default 0.15).
    bark_albedo : float
        Diffuse reflectance of the bark [-] (default 0.2).
    obstacles : sequence
        Further shapes: ``(vertices [m], faces)`` pairs or ``mi.Mesh``.
    traits : LeafTraits, optional
        Leaf structure, water and dry matter of the spectra (default ``LeafTraits()``).

    Returns
    -------
    scene : mi.Scene
        The scene.
    leaf_map : dict
        ``{shape_id: leaf indices}`` (leaf ``idx[j]`` owns triangles 2j, 2j + 1).

    Raises
    ------
    SceneError
        When ``emitters`` is empty (is the sun below the horizon at that time?).
    ParameterError
        When ``tau`` does not have one value per leaf.
    """



    if not emitters:
        raise SceneError("no emitters (is the sun below the horizon at that time?)")
    leaves = tree.leaves if hasattr(tree, "leaves") else tree
    n = len(leaves)
    tau = np.zeros(n) if tau is None else np.asarray(tau, float)
    if tau.shape != (n,):
        raise ParameterError("tau", tau.shape, f"one value per leaf ({n},)")
    cls = stage_classes(tau, n_classes)
    d = {"type": "scene", **emitters}
    leaf_map = {}
    traits = traits or LeafTraits()
    for k, (v, f, idx) in class_meshes(leaves, cls).items():
        spec = leaf_spectra(tau=float(tau[idx].mean()), traits=traits)
        sid = f"leaves_{k}"
        d[sid] = mesh(sid, v, f, bsdf=leaf_bsdf_dict(spec))
        leaf_map[sid] = idx
    if hasattr(tree, "alive") and tree.alive.any():
        bv, bf = bark_mesh_arrays(tree)
        d["bark"] = mesh("bark", bv, bf, bsdf={"type": "diffuse", "reflectance": {
            "type": "uniform", "value": float(bark_albedo)}})
    if ground:
        pos = leaves.position if n else np.zeros((1, 3))
        cx, cz = float(np.mean(pos[:, 0])), float(np.mean(pos[:, 2]))
        if ground_extent is None:
            r = float(np.max(np.abs(pos[:, [0, 2]] - [cx, cz]))) if n else 1.0
            ground_extent = 4.0 * max(r, 0.5)
        h = ground_extent / 2
        gv, gf = grid_mesh(ground_resolution, ground_resolution, x=(cx - h, cx + h),
                           z=(cz - h, cz + h))
        d["ground"] = mesh("ground", gv, gf, bsdf={"type": "diffuse", "reflectance": {
            "type": "uniform", "value": float(ground_albedo)}})
    for i, ob in enumerate(obstacles or ()):
        d[f"obstacle{i}"] = ob if isinstance(ob, mi.Mesh) else mesh(f"obstacle{i}", *ob)
    return mi.load_dict(d, optimize=False), leaf_map


def leaf_values(result, leaf_map: dict | None = None, n_leaves: int | None = None) -> dict:
    """Per-leaf light from a photon pass: both faces' incident power per one-sided leaf area.

    Leaves are the shapes whose id starts with ``leaves``, two triangles per leaf.

    Parameters
    ----------
    result : PhotonIrradianceResult
        The photon pass (:func:`mitsuba_veg.light.photon_irradiance`).
    leaf_map : dict, optional
        ``{shape_id: leaf indices}`` (from :func:`tree_scene`); default: the leaf shapes'
        leaves concatenated in shape order.
    n_leaves : int, optional
        Length of the arrays (default: the number of leaves in ``leaf_map``).

    Returns
    -------
    dict
        ``{"par_W_m2", "ppfd", "red_W_m2", "far_red_W_m2", "rfr", "front_par_W_m2",
        "back_par_W_m2", "area_m2"}`` arrays (one value per leaf, leaf order of ``leaf_map``'s
        indices, or concatenated shape order when ``leaf_map`` is None): PAR (400-700 nm), red
        (655-665 nm) and far-red (725-735 nm) irradiance [W m-2], PPFD [µmol m-2 s-1], R:FR
        photon ratio [-] (NaN without far-red), PAR on each face [W m-2], blade area [m2]; NaN
        for leaves not in ``leaf_map``. An empty dict when the scene has no leaf shapes.
    """
    ids = [s for s in result.index.shape_ids if s and s.startswith("leaves")]
    if not ids:
        return {}
    if leaf_map is None:
        leaf_map, off = {}, 0
        for s in ids:
            sl = result.index.shape_slice(s)
            m = (sl.stop - sl.start) // 2
            leaf_map[s] = np.arange(off, off + m)
            off += m
    n = n_leaves if n_leaves is not None else int(sum(len(v) for v in leaf_map.values()))
    out = {k: np.full(n, np.nan) for k in ("par_W_m2", "red_W_m2", "far_red_W_m2",
                                            "front_par_W_m2", "back_par_W_m2", "area_m2")}
    bands = [(b, k) for b, k in (("par", "par_W_m2"), ("red", "red_W_m2"),
                                 ("far_red", "far_red_W_m2")) if b in result.bands]
    for s, idx in leaf_map.items():
        sl = result.index.shape_slice(s)
        area = result.index.areas[sl].reshape(-1, 2).sum(1)
        out["area_m2"][idx] = area
        for b, key in bands:
            f = result.flux_of(s, b, side="both").reshape(-1, 2).sum(1)
            out[key][idx] = f / area
        for side in ("front", "back") if "par" in result.bands else ():
            f = result.flux_of(s, "par", side=side).reshape(-1, 2).sum(1)
            out[f"{side}_par_W_m2"][idx] = f / area
    out["ppfd"] = out["par_W_m2"] * umol_per_joule(400, 700)
    with np.errstate(divide="ignore", invalid="ignore"):
        out["rfr"] = np.where(out["far_red_W_m2"] > 0, out["red_W_m2"] * umol_per_joule(655, 665)
                              / (out["far_red_W_m2"] * umol_per_joule(725, 735)), np.nan)
    return out


def open_reference(azimuth: float, elevation: float, day_of_year: int = 172) -> dict:
    """Light on open flat ground from the daylight spectra (SPCTRAL2 beam + sky).

    Global horizontal spectral irradiance = DNI sin(elevation) + DHI of
    :func:`~mitsuba_veg.light.clear_sky.clear_sky_spectra`.

    Parameters
    ----------
    azimuth : float
        Sun azimuth [degrees] (not used: horizontal ground does not depend on it).
    elevation : float
        Sun elevation [degrees].
    day_of_year : int
        Day of the year (Earth-Sun distance; default 172).

    Returns
    -------
    dict
        ``par_W_m2`` (400-700 nm), ``red_W_m2`` (655-665 nm), ``far_red_W_m2`` (725-735 nm)
        [W m-2], ``ppfd`` [µmol m-2 s-1] and ``rfr`` (photon ratio) [-].
    """

    wl, dni, dhi = clear_sky_spectra(elevation, day_of_year=day_of_year)
    ghi = dni * np.sin(np.radians(elevation)) + dhi
    return {"par_W_m2": band_irradiance(wl, ghi, 400, 700),
            "ppfd": photon_flux(wl, ghi, 400, 700),
            "red_W_m2": band_irradiance(wl, ghi, 655, 665),
            "far_red_W_m2": band_irradiance(wl, ghi, 725, 735),
            "rfr": red_far_red_ratio(wl, ghi)}


# --------------------------------------------------------------------------------------------
# The study
# --------------------------------------------------------------------------------------------
def _load(scene_or_scenario, when, latitude, longitude, overrides, tau, tree_leaves):
    """-> (scene, leaf_map, info dict)"""


    info: dict = {}
    obj = scene_or_scenario
    if isinstance(obj, str) and obj == "sphere-tree":
        obj = sphere_crown_tree(tree_leaves, seed=0)
        info["scene"] = f"built-in sphere-crown test tree ({tree_leaves} leaves)"
    if isinstance(obj, Tree):
        when = when or DEFAULT_WHEN
        lat = 35.0 if latitude is None else latitude
        lon = 139.0 if longitude is None else longitude
        az, el = (float(np.asarray(x)) for x in sun_position(lat, lon, when))
        if el <= 0:
            raise ParameterError("when", when, "a time with the sun above the horizon")
        doy = _day_of_year(when)
        em = daylight_from_angles(az, el, day_of_year=doy)
        # ground: the crown, its shadow at this sun elevation and a margin (<= 60 m)
        pos = obj.leaves.position if len(obj.leaves) else obj.end
        r = float(np.max(np.hypot(pos[:, 0] - pos[:, 0].mean(), pos[:, 2] - pos[:, 2].mean())))
        top = float(max(pos[:, 1].max(), obj.end[:, 1].max() if len(obj) else 0.0))
        ext = min(2.0 * (r + top / np.tan(np.radians(max(el, 10.0)))) + 1.0, 60.0)
        scene, leaf_map = tree_scene(obj, emitters=em, tau=tau, ground_extent=ext,
                                     ground_resolution=80)
        info["_tree"] = obj
        info.setdefault("scene", f"tree '{obj.name}' ({len(obj.leaves)} leaves)")
        info.update(when=when, latitude=lat, longitude=lon, sun_azimuth=az, sun_elevation=el,
                    open=open_reference(az, el, doy))
        return scene, leaf_map, info
    if isinstance(obj, mi.Scene):
        info["scene"] = "mi.Scene"
        return obj, None, info
    p = Path(obj)
    if not p.exists():
        raise ParameterError("SCENE", str(p), "an existing .toml scenario or .xml scene, or "
                             "'sphere-tree'", "check the path")
    info["scene"] = str(p)
    if p.suffix.lower() == ".toml":
        ov = list(overrides or ())
        if when is not None:
            ov.append(f'light.when="{when}"')
        scn = load_scenario(p, ov)
        scene = scn.load_scene()
        w = scn.get("light.when")
        if w is not None:
            lat, lon = scn.get("site.latitude"), scn.get("site.longitude")
            az, el = (float(np.asarray(x)) for x in sun_position(lat, lon, w))
            info.update(when=w, latitude=lat, longitude=lon, sun_azimuth=az, sun_elevation=el,
                        open=open_reference(az, el, _day_of_year(w)))
        info["ground"] = scn.get("terrain.ground", "ground")
        info["_sensors"] = from_scenario(scn, scene)
        return scene, None, info
    if when is not None:
        raise ParameterError("--when", when, "a scenario (.toml) with a [site], or a tree, as "
                             "SCENE", "pass the scenario instead of the XML")
    try:
        return mi.load_file(str(p), optimize=False), None, info
    except Exception as e:  # Mitsuba's parser names the XML problem
        raise ParameterError("SCENE", str(p), "a Mitsuba 3 XML scene that loads",
                             f"correct the XML: {' '.join(str(e).split())[:400]}") from None


def run_light_study(scene_or_scenario, out_dir, *, photons: int = 2_000_000, seed: int = 0,
                    max_depth: int = 8, indirect: bool = True, when=None, latitude=None,
                    longitude=None, ground: str | None = None, overrides=(), tau=None,
                    tree_leaves: int = 3000, progress: bool = False) -> dict:
    """Run a spectral light study and write its files (module docstring). Returns the summary.

    Trees get daylight (SPCTRAL2 sun + Perez sky) at ``when`` for ``latitude``/``longitude`` and a
    ground grid covering the crown and its shadow; ``tau`` gives per-leaf autumn time for their
    spectra (default green).

    Parameters
    ----------
    scene_or_scenario : str, pathlib.Path, mi.Scene or Tree
        Scenario ``.toml`` / scene ``.xml`` path, ``mi.Scene``, ``Tree``, or ``"sphere-tree"``.
    out_dir : str or pathlib.Path
        Output folder (a ``light-study`` folder).
    photons : int
        Photons of the pass (default 2 000 000).
    seed : int
        Random seed (default 0).
    max_depth : int
        Most bounces of a photon path (default 8).
    indirect : bool
        Trace scattered light too (default True).
    when : str, optional
        Time (ISO 8601 with UTC offset): for trees default mid-July noon
        (:data:`DEFAULT_WHEN`); for a scenario it overrides ``light.when``; refused for an XML
        scene.
    latitude, longitude : float, optional
        Site of a tree [degrees] (default 35 N, 139 E).
    ground : str, optional
        Shape id of the ground (default: the scenario's ``terrain.ground``, else ``ground``).
    overrides : sequence of str
        ``--set`` overrides of a scenario.
    tau : array_like, optional
        (n_leaves,) autumn logical time [-] of a tree's leaves (default green).
    tree_leaves : int
        Leaves of the built-in ``"sphere-tree"`` (default 3000).
    progress : bool
        Progress bar of the photon pass.

    Returns
    -------
    dict
        The summary written to ``summary.json``: scene, sun and open-sky reference, settings,
        ground means (PAR [W m-2], PPFD [µmol m-2 s-1], red and far-red [W m-2], R:FR [-],
        fractions of open light), leaf and sensor statistics, timings [s] and the files written.

    Raises
    ------
    ParameterError
        When the scene cannot be read, a setting is out of range, or the sun is below the
        horizon for a tree.
    SceneError
        When the scene has no ground shape ``ground`` or no emitters.
    """


    check_light("photons", photons)
    check_light("max_depth", max_depth)
    check_light("seed", seed)
    check_range("leaves", tree_leaves, 1, 1_000_000)
    out = Path(out_dir)
    t0 = time.perf_counter()
    scene, leaf_map, info = _load(scene_or_scenario, when, latitude, longitude, overrides, tau,
                                  tree_leaves)
    t_load = time.perf_counter() - t0
    folder = OutputFolder(out, "light-study")
    sensors = info.pop("_sensors", None)
    bands, modes = BANDS, None
    if sensors is not None:  # the scenario's [[sensors]] are read in the same pass
        scene, owner = S.scene_with_sensors(scene, sensors)
        bands, modes = BANDS + ("shortwave",), {S.SENSOR_SHAPE: "sensor"}
    res = photon_irradiance(scene, photons=int(photons), seed=int(seed),
                            max_depth=int(max_depth), bands=bands, indirect=bool(indirect),
                            progress=progress, modes=modes)
    gid = ground or info.get("ground") or "ground"
    if gid not in res.index.shape_ids:
        raise SceneError(f"no ground shape '{gid}' in the scene (shapes: "
                         f"{res.index.shape_ids}); pass ground=... / --ground ID")
    sl = res.index.shape_slice(gid)
    area = res.index.areas[sl]
    g = {"par_W_m2": res.irradiance(gid, "par"), "red_W_m2": res.irradiance(gid, "red"),
         "far_red_W_m2": res.irradiance(gid, "far_red"),
         "ppfd": res.photon_flux_density(gid, "par"), "rfr": res.red_far_red(gid)}
    lv = leaf_values(res, leaf_map)

    def amean(x, w):
        m = np.isfinite(x)
        return float((x[m] * w[m]).sum() / w[m].sum()) if m.any() else None

    ground_sum = {k: amean(v, area) for k, v in g.items() if k != "rfr"}
    rf = res.photon_flux_density(gid, "red") * area
    ff = res.photon_flux_density(gid, "far_red") * area
    ground_sum["rfr"] = float(rf.sum() / ff.sum()) if ff.sum() > 0 else None
    ground_sum.update(area_m2=float(area.sum()), triangles=int(len(area)),
                      ppfd_min=float(np.nanmin(g["ppfd"])), ppfd_max=float(np.nanmax(g["ppfd"])),
                      rfr_min=float(np.nanmin(g["rfr"])), rfr_max=float(np.nanmax(g["rfr"])))
    if "open" in info:
        o = info["open"]
        ground_sum["ppfd_fraction_of_open"] = ground_sum["ppfd"] / o["ppfd"]
        ground_sum["ppfd_min_fraction_of_open"] = ground_sum["ppfd_min"] / o["ppfd"]

    # files
    verts, faces = res.index.geometry[gid]
    npz = {f"ground/{k}": v for k, v in g.items()}
    npz.update({"ground/vertices": verts, "ground/faces": faces, "ground/area_m2": area,
                "ground/centroid_m": res.index.centroids[sl]})
    npz.update({f"leaves/{k}": v for k, v in lv.items()})
    with atomic_write(out / "light_study.npz", out / "light_study.tmp.npz") as tmp:
        np.savez_compressed(tmp, **npz)
    files = {"npz": str(out / "light_study.npz")}
    files["png"] = light_maps_figure(verts, faces, g, out / "light_maps.png",
                                     title=_title(info, res))
    leaf_sum = {}
    if lv:
        files["leaves_csv"] = _write_leaves_csv(out / "leaves.csv", lv, leaf_map,
                                                info.get("_tree"))
        leaf_sum = {"leaves": int(np.isfinite(lv["par_W_m2"]).sum()),
                    "ppfd_mean": float(np.nanmean(lv["ppfd"])),
                    "ppfd_p10": float(np.nanpercentile(lv["ppfd"], 10)),
                    "ppfd_p90": float(np.nanpercentile(lv["ppfd"], 90)),
                    "rfr_mean": float(np.nanmean(lv["rfr"])),
                    "rfr_min": float(np.nanmin(lv["rfr"]))}
    sensor_sum = {}
    if sensors is not None:
        r = S.SensorReadings.from_watts(sensors, S.sensor_watts(res, sensors, owner,
                                                                S.beam_emitters(scene)))
        files["sensors"] = _write_table(r, out / "sensors", time=info.get("when"))
        sensor_sum = {str(n): {"ppfd": float(r.values[i, 0, 2]),
                               "ppfd_direct": float(r.values[i, 0, 0]),
                               "rfr": float(r.values[i, 3, 2]),
                               "shortwave_W_m2": float(r.values[i, 4, 2])}
                      for i, n in enumerate(sensors.names[:1000])}
    summary = {"command": "light-study", **{k: v for k, v in info.items() if k != "_tree"},
               "settings": {"photons": int(photons), "seed": int(seed), "max_depth": int(max_depth),
                            "indirect": bool(indirect), "bands_nm": dict(zip(res.bands,
                                                                             res.band_ranges))},
               "ground_id": gid, "ground": ground_sum, "leaves": leaf_sum,
               "sensors": sensor_sum,
               "timings_s": {"load": t_load, "photon_pass": res.seconds,
                             "total": time.perf_counter() - t0},
               "photons_per_s": float(res.photons.sum() / max(res.seconds, 1e-9)),
               "units": {"par_W_m2": "W m-2 (400-700 nm)", "ppfd": "umol m-2 s-1",
                         "red_W_m2": "W m-2 (655-665 nm)", "far_red_W_m2": "W m-2 (725-735 nm)",
                         "rfr": "photon ratio red:far-red"},
               "files": files, "versions": versions()}
    write_json(out / "summary.json", summary)
    files["summary"] = str(out / "summary.json")
    folder.release()
    return summary


def _title(info, res):
    t = f"light study: {info.get('scene', '')}"
    if "when" in info:
        t += (f" | {info['when']} | sun az {info['sun_azimuth']:.0f} deg, el "
              f"{info['sun_elevation']:.0f} deg")
    return t + f" | {int(res.photons.sum()):,d} photons"


def _write_leaves_csv(path, lv, leaf_map, src):
    pos = None
    if src is not None and hasattr(src, "leaves"):
        pos = src.leaves.position
    cols = ["par_W_m2", "ppfd", "red_W_m2", "far_red_W_m2", "rfr", "front_par_W_m2",
            "back_par_W_m2", "area_m2"]
    n = len(lv["par_W_m2"])
    with atomic_write(path, str(path) + ".tmp") as tmp, open(tmp, "w") as fh:
        fh.write("leaf," + ("x_m,y_m,z_m," if pos is not None else "") + ",".join(cols) + "\n")
        for i in range(n):
            row = [str(i)]
            if pos is not None:
                row += [f"{pos[i, 0]:.4f}", f"{pos[i, 1]:.4f}", f"{pos[i, 2]:.4f}"]
            row += [f"{lv[c][i]:.6g}" for c in cols]
            fh.write(",".join(row) + "\n")
    return str(path)


def light_maps_figure(vertices, faces, values: dict, path, title: str = "") -> str:
    """2 x 2 plan-view maps (PPFD, red, far-red, R:FR) with colour bars.

    Parameters
    ----------
    vertices : numpy.ndarray
        (n, 3) ground vertices [m].
    faces : numpy.ndarray
        (f, 3) ground triangles.
    values : dict
        Per-triangle ``ppfd`` [µmol m-2 s-1], ``red_W_m2``, ``far_red_W_m2`` [W m-2] and ``rfr``
        [-].
    path : pathlib.Path
        PNG file to write (atomically).
    title : str
        Figure title.

    Returns
    -------
    str
        The path written.
    """

    plt = _mpl()
    fig, axs = plt.subplots(2, 2, figsize=(11, 9.2), constrained_layout=True)
    ppfd = values["ppfd"]
    plan_map(axs[0, 0], vertices, faces, ppfd, title="PAR photon flux density (400-700 nm)",
             label="PPFD [µmol m$^{-2}$ s$^{-1}$]", cmap="viridis", vmin=0.0)
    plan_map(axs[0, 1], vertices, faces, values["red_W_m2"], title="red irradiance (655-665 nm)",
             label="W m$^{-2}$", cmap="inferno", vmin=0.0)
    plan_map(axs[1, 0], vertices, faces, values["far_red_W_m2"],
             title="far-red irradiance (725-735 nm)", label="W m$^{-2}$", cmap="inferno",
             vmin=0.0)
    rfr = values["rfr"]
    top = float(np.nanmax(rfr)) if np.isfinite(rfr).any() else 1.3
    plan_map(axs[1, 1], vertices, faces, rfr, title="red : far-red (photon ratio)",
             label="R:FR", cmap="RdYlGn", vmin=0.0, vmax=max(1.3, top))
    fig.suptitle(title, fontsize=10)
    with atomic_write(path, f"{path}.tmp.png") as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)
    return str(path)


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------
