"""Animation frames as Dask tasks: ``mitsuba-veg animate RUN --scheduler ADDRESS`` (or
``--workers N`` for a local cluster).

The same frames as :func:`mitsuba_veg.render.animation.run_animate` (same days, camera, light,
labels and exposure): the last frame is rendered first, as one task, and fixes the exposure of
every frame (no flicker); the other frames are then rendered as independent tasks (each builds
its scene: no scene is shared between frames) and the PNGs are assembled in day order into
``animation.mp4`` and ``animation.gif``. The workers must see the run folder and ``out`` at the
same paths (a shared file system).
"""
from __future__ import annotations

import time
from pathlib import Path

from ..errors import ParameterError
from ..outputs import write_json
from ..render import animation
from ..render.animation import (ANIMATE_DEFAULTS, default_light, label_frame, prepare_animation,
                                write_mp4)
from ..render.film import to_srgb8, write_gif, write_png
from ..render.history import load_run
from ..render.scene import RenderOptions, Terrain, build_scene, render_time, sky_emitters
from ..render.still import render
from ..render.world import trees_for_run
from ..backend import versions
from .cluster import open_client, set_drjit_threads, worker_drjit_threads

__all__ = ["TASK_PREFIX", "render_frame", "animate_on_dask", "run_animate"]

#: task key prefix (groups the frames on the Dask dashboard)
TASK_PREFIX = "mitsuba-veg-frame"


def render_frame(spec: dict) -> dict:
    """Render one animation frame to its PNG (a Dask task; also callable in-process).

    Parameters
    ----------
    spec : dict
        ``run_dir``, ``scenario`` (a path or None: the run's own), ``k`` (frame index),
        ``day`` (1-based simulated day), ``png`` (output path), ``options`` (keyword arguments
        of :class:`~mitsuba_veg.render.RenderOptions`), ``when`` (ISO date-time of a fixed
        light, or None: the frame's own date), ``exposure`` (None: this frame sets it),
        ``seed``, ``drjit_threads``, ``host_workers``.

    Returns
    -------
    dict
        ``k``, ``day``, ``date``, ``moss`` (count), ``exact``, ``render_s`` [s], ``exposure``,
        ``png``.
    """

    set_drjit_threads(worker_drjit_threads(spec.get("drjit_threads"),
                                           spec.get("host_workers") or {}))
    run = load_run(spec["run_dir"], spec.get("scenario"))
    o = RenderOptions(**spec["options"]).validate()
    tree_list, seasons = trees_for_run(run, None, int(spec["day"]))
    fr = run.frame(int(spec["day"]))
    for s in seasons:
        s.apply(fr.date)
    emitters = sky_emitters(run.scenario, spec["when"]) if spec.get("when") else None
    rs = build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=tree_list,
                     date=fr.date, options=o, terrain=Terrain.from_scenario(run.scenario),
                     emitters=emitters, species=run.species)
    images = render(rs, seed=int(spec["seed"]))     # one seed for every frame: no flicker
    img8, exp = to_srgb8(images["display"], spec.get("exposure"))
    text = f"day {fr.day:3d}  {fr.date.isoformat()}  {len(fr.moss):,d} moss"
    p = write_png(spec["png"], label_frame(img8, text))
    return {"k": int(spec["k"]), "day": int(fr.day), "date": fr.date.isoformat(),
            "moss": len(fr.moss), "exact": bool(fr.exact), "render_s": images["seconds"],
            "exposure": exp, "png": str(p), "when": rs.info.get("when"),
            "trees": len(tree_list)}


def animate_on_dask(run_dir, out=None, *, scheduler=None, workers=None, client=None,
                    threads=None, camera=None, width=None, height=None, spp=None, frames=None,
                    every=None, fps=None, when=None, hour=None, light=None, scenario=None,
                    gif_width=None, seed=0, denoise=True, progress=True) -> dict:
    """Render the days of a moss run as Dask tasks into ``animation.mp4`` and ``animation.gif``.

    See the module docstring: the last frame runs first and fixes the exposure of every frame.

    Parameters
    ----------
    run_dir : str or Path
        A moss run folder (``mitsuba-veg run ... --out DIR``).
    out : str or Path, optional
        Output folder (default ``RUN_DIR/animation``).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); as in
        :func:`mitsuba_veg.sweeps.sweep` (default: a local cluster of one worker process per
        core).
    workers : int, optional
        Worker processes of the local cluster; with ``scheduler`` or ``client``: wait for this
        many workers.
    client : distributed.Client, optional
        An open Dask client (left open).
    threads : int, optional
        Dr.Jit threads per worker (default: the host's cores // its worker processes).
    camera : str, optional
        Camera preset (default ``overview``); the settings from here to ``seed`` are as in
        :func:`mitsuba_veg.render.animation.run_animate`.
    width, height : int, optional
        Image size [pixels] (default 480 x 270).
    spp : int, optional
        Samples per pixel (default 8).
    frames : int, optional
        At most this many frames spread over the snapshot days (default 31).
    every : int, optional
        One frame every ``every`` days [days] instead of ``frames``.
    fps : int, optional
        Frames per second [s-1] (default 6).
    when : str, optional
        ISO date-time of a fixed light.
    hour : float, optional
        Local hour of the light [h] (default 10).
    light : {"daily", "fixed"}, optional
        Each frame's own date (default without ``when``) or one fixed light (default with
        ``when``).
    scenario : str or Path, optional
        A scenario file instead of the run's own (default None).
    gif_width : int, optional
        Downscale the GIF to this width [pixels] (default 360; 0 keeps the frame width).
    seed : int, optional
        Render seed; frame k uses ``seed + k`` (default 0).
    denoise : bool, optional
        Denoise the frames (default True).
    progress : bool
        Print the dashboard link and show a progress bar (frames).

    Returns
    -------
    dict
        The summary written to ``animate.json`` (as ``run_animate``'s, plus ``dask``).
    """

    light = default_light(light, when)
    t0 = time.perf_counter()
    run, out, fdir, days, fps, opts, o, folder = prepare_animation(
        run_dir, out, scenario, camera=camera, width=width, height=height, spp=spp,
        frames=frames, every=every, fps=fps, when=when, hour=hour, seed=seed, denoise=denoise)
    fixed_when = render_time(run.scenario, run.date(days[-1]), o) if light == "fixed" else None
    scen = scenario if scenario is None or hasattr(scenario, "data") else \
        str(Path(scenario).resolve())
    base = {"run_dir": str(Path(run_dir).resolve()), "scenario": scen, "options": opts,
            "when": fixed_when, "seed": int(seed), "exposure": None}
    specs = [dict(base, k=k, day=d, png=str(fdir / f"frame_{k:04d}.png"))
             for k, d in enumerate(days)]
    records = [None] * len(days)
    with open_client(scheduler, workers, client, threads, ":8787") as (cl, info):
        from distributed import as_completed
        for s in specs:
            s["drjit_threads"], s["host_workers"] = info.drjit_threads, info.host_workers
        if progress:
            print(f"mitsuba-veg animate: {len(days)} frames on {info.workers} Dask worker"
                  f"{'s' if info.workers != 1 else ''} "
                  f"({'local cluster' if info.local else info.address})")
            if info.dashboard:
                print(f"Dask dashboard: {info.dashboard}")
        bar = None
        if progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=len(days), unit="frame", desc="animate")
        # the last frame first: it sets the exposure of every frame (no flicker)
        last = cl.submit(render_frame, specs[-1], key=f"{TASK_PREFIX}-last-{time.time_ns()}",
                         pure=False).result()
        records[-1] = last
        if bar is not None:
            bar.update(1)
            bar.set_postfix(day=last["day"], frame="last, for the exposure")
        rest = []
        for s in specs[:-1]:
            s["exposure"] = last["exposure"]
            rest.append(cl.submit(render_frame, s, pure=False,
                                  key=f"{TASK_PREFIX}-{s['k']:04d}-{time.time_ns()}"))
        for fut in as_completed(rest):
            r = fut.result()
            records[r["k"]] = r
            if bar is not None:
                bar.update(1)
                bar.set_postfix(day=r["day"], moss=r["moss"])
        if bar is not None:
            bar.close()
        dask_info = {"local": info.local, "address": info.address, "workers": info.workers,
                     "dashboard": info.dashboard, "drjit_threads": info.drjit_threads}
    t3 = time.perf_counter()
    paths = [r["png"] for r in records]
    for q in paths:          # written by the workers: into the folder's manifest
        folder.record(q)
    mp4 = write_mp4(fdir, "frame_%04d.png", out / "animation.mp4", fps)
    gif = write_gif(paths, out / "animation.gif", fps,
                    ANIMATE_DEFAULTS["gif_width"] if gif_width is None else gif_width)
    t_encode = time.perf_counter() - t3
    frames_out = [{"day": r["day"], "date": r["date"], "moss": r["moss"], "exact": r["exact"],
                   "render_s": r["render_s"]} for r in records]
    summary = {"command": "animate", "run": str(run.dir), "frames": frames_out,
               "exact": all(r["exact"] for r in records),
               "settings": {**opts, "fps": fps, "light": light, "when": last.get("when")},
               "trees": last["trees"],
               "files": {"mp4": str(mp4) if mp4 else None, "gif": str(gif), "frames": str(fdir)},
               "timings_s": {"render": sum(r["render_s"] for r in records), "encode": t_encode,
                             "total": time.perf_counter() - t0},
               "dask": dask_info, "versions": versions()}
    if mp4 is None:
        summary["warning"] = "ffmpeg not found: no MP4 written (install ffmpeg)"
    write_json(out / "animate.json", summary)
    folder.release()
    return summary


def run_animate(run_dir, out=None, *, scheduler=None, workers=None, client=None, trees=None,
                **kwargs) -> dict:
    """Animate a run here or with its frames as Dask tasks.

    Without ``scheduler``, ``workers`` and ``client`` the frames render in this process
    (:func:`mitsuba_veg.render.animation.run_animate`), else as Dask tasks
    (:func:`animate_on_dask`).

    Parameters
    ----------
    run_dir, out : path-like
        The run folder and the output folder (default ``RUN_DIR/animation``).
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``).
    workers : int, optional
        Worker processes of a local Dask cluster.
    client : distributed.Client, optional
        An open Dask client.
    trees : list of Tree, optional
        Trees instead of the scenario's (in this process only).
    **kwargs : dict
        The settings of :func:`mitsuba_veg.render.animation.run_animate` (sizes in pixels,
        ``spp`` samples per pixel, ``fps`` frames per second, ...).

    Returns
    -------
    dict
        The summary written to ``animate.json`` (with ``dask`` when the frames ran on Dask).

    Raises
    ------
    ParameterError
        If ``trees`` is given with Dask, or for an invalid ``light``.
    """
    if scheduler is None and workers is None and client is None:
        return animation.run_animate(run_dir, out, trees=trees, **kwargs)
    default_light(kwargs.get("light"), kwargs.get("when"))
    if trees is not None:
        raise ParameterError("trees", "a list of Tree", "None when the frames run on Dask "
                             "(the workers build the scenario's [[render.trees]])",
                             "put the trees in the scenario's [[render.trees]]")
    return animate_on_dask(run_dir, out, scheduler=scheduler, workers=workers, client=client,
                           **kwargs)
