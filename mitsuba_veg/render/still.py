"""Render an assembled scene and write the still outputs (EXR, PNG, red:far-red view)."""
from __future__ import annotations

import gc
import time
from dataclasses import replace
from pathlib import Path

import mitsuba as mi
import numpy as np
from tqdm.auto import tqdm

from ..errors import ParameterError, check_range
from ..outputs import OutputFolder, write_json
from ..backend import versions
from . import film as _film
from .history import load_run
from .denoise import timed_denoise
from .scene import IMAGE_LIMITS, RenderOptions, Terrain, build_scene
from .world import trees_for_run

__all__ = ["render", "write_outputs", "RENDER_DEFAULTS", "YEARS_FPS", "run_render",
           "year_end_days", "run_render_years", "check_image"]


def render(rs, spp: int | None = None, seed: int | None = None,
           denoise: bool | None = None) -> dict:
    """Render an assembled scene, and denoise its display image.

    Parameters
    ----------
    rs : RenderScene
        From :func:`mitsuba_veg.render.scene.build_scene`.
    spp : int, optional
        Samples per pixel (default: the scene's options).
    seed : int, optional
        Sampler seed (default: the scene's options).
    denoise : bool, optional
        Denoise the display image (default: the scene's ``options.denoise``; guided by albedo and
        normal buffers when the scene has their camera, ``options.denoise_guides``;
        :mod:`mitsuba_veg.render.denoise`).

    Returns
    -------
    dict
        :func:`mitsuba_veg.render.film.develop`'s images (``rgb`` linear sRGB, ``XYZ``, ``bands``
        band-mean spectral radiance [W m-2 sr-1 nm-1], ``r_fr`` photon ratio, all as rendered),
        ``display`` (the linear sRGB image to show: denoised, or ``rgb``), ``seconds`` (the
        render and its development [s]), and with denoising ``seconds_denoise`` (and
        ``seconds_aux`` for the guides' pass) [s].
    """
    t0 = time.perf_counter()
    if spp is not None:
        spp = replace(rs.options, spp=int(spp)).samples
    seed = int(rs.options.seed if seed is None else seed)
    img = mi.render(rs.scene, sensor=rs.sensor, spp=int(spp or rs.options.samples), seed=seed)
    a = np.asarray(img)   # waits for the kernel
    out = _film.develop(a)
    out["seconds"] = time.perf_counter() - t0
    out["display"] = out["rgb"]
    if rs.options.denoise if denoise is None else denoise:
        timed_denoise(rs, out, seed)
    return out


def write_outputs(images: dict, out_dir, stem: str = "render", meta: dict | None = None,
                  exposure: float | None = None, title: str | None = None) -> dict:
    """Write ``<stem>.exr``, ``<stem>.png`` and ``<stem>_rfr.png`` (each atomically).

    Parameters
    ----------
    images : dict
        From :func:`render`.
    out_dir : path-like
        The folder (created).
    stem : str
        File name stem.
    meta : dict, optional
        String attributes of the EXR header (units, time, camera ...).
    exposure : float, optional
        Exposure of the PNG (default: automatic, log-average luminance to 0.18).
    title : str, optional
        Title of the red:far-red picture.

    Returns
    -------
    dict
        ``files`` (paths by kind) and ``exposure`` used.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    exr = _film.write_exr(out_dir / f"{stem}.exr", images, meta)
    img8, exp = _film.to_srgb8(images.get("display", images["rgb"]), exposure)
    png = _film.write_png(out_dir / f"{stem}.png", img8)
    files = {"exr": str(exr), "png": str(png)}
    if "r_fr" in images:
        fc = _film.rfr_false_colour(images["r_fr"], luminance=images["XYZ"][..., 1], title=title)
        files["rfr_png"] = str(_film.write_png(out_dir / f"{stem}_rfr.png", fc))
    return {"files": files, "exposure": exp}


#: defaults of ``render`` (image size [px], samples per pixel, camera presets)
RENDER_DEFAULTS = {"width": 800, "height": 450, "spp": 32, "cameras": ("overview", "floor")}
#: frames per second of the years' animation (``render --years``)
YEARS_FPS = 1


def _cameras(camera) -> list[str]:
    if camera is None:
        return list(RENDER_DEFAULTS["cameras"])
    if isinstance(camera, str):
        return [c.strip() for c in camera.split(",") if c.strip()]
    return list(camera)


def run_render(run_dir, out=None, *, camera=None, width=None, height=None, spp=None,
               day=None, when=None, hour=None, max_depth=None, trees=None, scenario=None,
               seed=0, denoise=True, progress=True) -> dict:
    """Render one day of a run from one or more camera presets.

    Writes, per camera, ``render_<camera>.exr`` (RGB + red/far-red bands + R:FR),
    ``render_<camera>.png`` (sRGB) and ``render_<camera>_rfr.png`` (red:far-red false colour),
    and ``render.json`` (settings, counts, timings, files).

    Parameters
    ----------
    run_dir, out : path-like
        The run folder and the output folder (default ``RUN_DIR/render``).
    camera : str or list of str, optional
        Preset name(s), comma-separated or a list (default overview and shelter).
    width, height : int, optional
        Image size [pixels] (default 800 x 450).
    spp : int, optional
        Samples per pixel (default 24).
    day : int, optional
        The simulated day to show [days] (default: the last).
    when : str, optional
        ISO date-time of the light (default: that day at ``hour``).
    hour : float, optional
        Local hour of the light [h] (default 10).
    max_depth : int, optional
        Path length of the render (default :class:`RenderOptions`' 6).
    trees : list of Tree, optional
        Trees instead of the scenario's ``[[render.trees]]``.
    scenario : path-like, optional
        The run's scenario file (default: the one its summary names).
    seed : int, optional
        Sampler seed and tuft placement seed (default 0).
    denoise : bool, optional
        Denoise the PNG's image (default True; the EXR keeps the rendered channels).
    progress : bool, optional
        Show a progress bar over the cameras (default True).

    Returns
    -------
    dict
        The summary written to ``render.json``.

    Raises
    ------
    ParameterError
        If an image setting or ``day`` is out of range, or the run cannot be read.
    """
    t0 = time.perf_counter()
    check_image(width, height, spp, max_depth)
    run = load_run(run_dir, scenario)
    out = Path(out) if out is not None else Path(run_dir) / "render"
    last = run.final_day
    day = last if day is None else int(day)
    check_range("day", day, 1, max(last, 1), fix=f"a simulated day of the run (1-{last})")
    frame = run.frame(day)
    folder = OutputFolder(out, "render", info={"run": str(run.dir)}, reads=run.dir)
    opts = dict(width=width or RENDER_DEFAULTS["width"],
                height=height or RENDER_DEFAULTS["height"], spp=spp or RENDER_DEFAULTS["spp"],
                when=when, seed=int(seed), denoise=bool(denoise))
    if hour is not None:
        opts["hour"] = float(hour)
    if max_depth is not None:
        opts["max_depth"] = int(max_depth)
    tree_list, seasons = trees_for_run(run, trees, day)
    for s in seasons:
        s.apply(frame.date)
    terrain = Terrain.from_scenario(run.scenario)
    cams = _cameras(camera)
    results = {}
    files = {}
    bar = None
    if progress:
        bar = tqdm(total=len(cams), unit="image", desc="render")
    tree_cache = {}
    try:
        _render_cameras(cams, opts, run, frame, tree_list, terrain, tree_cache, out, day, bar,
                        results, files)
    finally:
        if bar is not None:
            bar.close()
    summary = {"command": "render", "run": str(run.dir), "day": day,
               "date": frame.date.isoformat(), "moss_exact": frame.exact,
               "moss": len(frame.moss), "trees": len(tree_list),
               "settings": {**opts, "cameras": cams, "max_depth": RenderOptions().max_depth
                            if max_depth is None else max_depth},
               "cameras": results, "files": files,
               "seconds": time.perf_counter() - t0, "versions": versions()}
    write_json(out / "render.json", summary)
    folder.release()
    return summary


def year_end_days(run) -> list:
    """The last snapshot day of every calendar year of a run: ``[(year, day)]``.

    Parameters
    ----------
    run : Run
        A loaded run.

    Returns
    -------
    list of (int, int)
        Years and their last snapshot days (1-based), by year.
    """
    last = {}
    for d, _ in sorted(run.snapshots):
        last[run.date(d).year] = d
    return sorted(last.items())


def run_render_years(run_dir, out=None, *, scenario=None, progress=True, **kw) -> dict:
    """Render the last snapshot day of every year of a run (a stand year by year, from the
    same cameras): ``run_render`` into ``<out>_<year>`` folders, and an animated GIF of the
    years per camera in ``<out>_years/<camera>.gif``.

    Parameters
    ----------
    run_dir : path-like
        The run folder.
    out : path-like, optional
        Prefix of the output folders (default ``RUN_DIR/render``: ``render_2026``, ...).
    scenario : path-like, optional
        The run's scenario file.
    progress : bool, optional
        Progress bars.
    **kw : dict
        The image settings of :func:`run_render` (camera, width, height, spp, hour,
        max_depth, seed).

    Returns
    -------
    dict
        ``{"years": {year: {"day", "date", "files"}}, "animations": {camera: GIF}}``: the
        years' animations (one frame a year, :data:`YEARS_FPS`) in ``<out>_years/``.

    Raises
    ------
    ParameterError
        When the run has no snapshots (run it with frames), or ``day``/``when`` is given.
    """
    for k in ("day", "when"):
        if kw.pop(k, None) is not None:
            raise ParameterError(f"--{k}", "given", "not with --years (each year's last "
                                 "snapshot day is rendered)")
    run = load_run(run_dir, scenario)
    days = year_end_days(run)
    if not days:
        raise ParameterError("RUN_DIR", str(run_dir), "a run with snapshots (frames)",
                             "run it again without --no-frames")
    base = Path(out) if out is not None else Path(run_dir) / "render"
    # claimed first: a folder another process writes is refused before hours of renders
    with OutputFolder(base.with_name(f"{base.name}_years"), "render_years",
                      info={"run": str(run.dir)}, reads=run.dir) as anim:
        years = {}
        for year, day in days:
            s = run_render(run_dir, base.with_name(f"{base.name}_{year}"), day=day,
                           scenario=scenario, progress=progress, **kw)
            years[year] = {"day": s["day"], "date": s["date"], "files": s["files"]}
        # the years as an animation per camera (one frame a year)
        gifs = {cam: str(_film.write_gif([y["files"][cam]["png"] for y in years.values()],
                                         anim.path / f"{cam}.gif", YEARS_FPS))
                for cam in s["files"]}
        write_json(anim.path / "render_years.json",
                   {"command": "render --years", "run": str(run.dir),
                    "years": {str(k): {"day": v["day"], "date": v["date"]}
                              for k, v in years.items()},
                    "files": gifs, "versions": versions()})
    return {"years": years, "animations": gifs}


def check_image(width, height, spp, max_depth=None, frames=None, every=None, fps=None):
    """Refuse image settings out of range (``None`` = the default).

    Parameters
    ----------
    width, height : int or None
        Image size [pixels], 8-16384 (:data:`~mitsuba_veg.render.scene.IMAGE_LIMITS`).
    spp : int or None
        Samples per pixel, 1-2^20.
    max_depth : int or None, optional
        Path length, 1-100.
    frames : int or None, optional
        Animation frames, 2-10000.
    every : int or None, optional
        Days between frames [d], 1-100000.
    fps : int or None, optional
        Frames per second, 1-120.

    Raises
    ------
    ParameterError
        If a value is out of its range (named by its command-line option, e.g. ``--width``).
    """
    L = IMAGE_LIMITS
    for name, v, lo, hi in (("--width", width, *L["width"]), ("--height", height, *L["height"]),
                            ("--spp", spp, *L["spp"]), ("--max-depth", max_depth, *L["max_depth"]),
                            ("--frames", frames, 2, 10000), ("--every", every, 1, 100_000),
                            ("--fps", fps, 1, 120)):
        if v is not None:
            check_range(name, v, lo, hi)


def _render_cameras(cams, opts, run, frame, tree_list, terrain, tree_cache, out, day, bar,
                    results, files):
    for cam in cams:
        o = RenderOptions(camera=cam, **opts)
        rs = build_scene(run.scenario, frame.moss, moss_size=run.moss_size, trees=tree_list,
                         date=frame.date, options=o, terrain=terrain, tree_cache=tree_cache)
        images = render(rs)
        meta = {"mitsuba_veg": "render", "run": str(run.dir), "day": str(day),
                "date": frame.date.isoformat(), "when": rs.info["when"], "camera": cam,
                "units": "R,G,B,X,Y,Z: CIE-weighted spectral radiance W m-2 sr-1 nm-1 (linear "
                         "sRGB / XYZ, Y = ybar-weighted mean); red_655_665, far_red_725_735: "
                         "band-mean spectral radiance W m-2 sr-1 nm-1; R_FR: photon ratio"}
        title = f"red : far-red   day {day} ({frame.date.isoformat()}), {cam}"
        w = write_outputs(images, out, stem=f"render_{cam}", meta=meta, title=title)
        rfr = images.get("r_fr")
        results[cam] = {"render_s": images["seconds"],
                        "denoise_s": images.get("seconds_aux", 0.0) +
                        images["seconds_denoise"] if "seconds_denoise" in images else None,
                        "exposure": w["exposure"],
                        "info": rs.info, "files": w["files"],
                        "r_fr_median": float(np.nanmedian(rfr)) if rfr is not None else None,
                        "mean_rgb": np.nanmean(images["rgb"].reshape(-1, 3), 0).tolist()}
        files[cam] = w["files"]
        del rs, images
        gc.collect()
        if bar is not None:
            bar.update(1)
            bar.set_postfix(camera=cam, s=f"{results[cam]['render_s']:.1f}")
