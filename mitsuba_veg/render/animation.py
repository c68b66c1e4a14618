"""Animations of a run: :func:`run_animate` renders the run's days (the snapshot days, thinned
to ``frames``) at lower settings, each in its day's daylight moved into one scene (or one fixed
light), so that the rendering kernel is compiled once, and writes ``frames/frame_NNNN.png``,
``animation.mp4`` (H.264, ffmpeg), ``animation.gif`` and ``animate.json``. The same frames as
Dask tasks: :mod:`mitsuba_veg.sweeps.frames`.
"""
from __future__ import annotations

import gc
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont
from tqdm.auto import tqdm

from ..errors import ParameterError, check_range
from ..outputs import OutputFolder, atomic_write, write_json
from ..backend import versions
from .film import to_srgb8, write_gif, write_png
from .history import load_run
from .scene import RenderOptions, Terrain, build_scene, render_time, sky_emitters
from .still import check_image, render
from .world import tree_version, trees_for_run

__all__ = ["ANIMATE_DEFAULTS", "label_frame", "ffmpeg_path", "write_mp4", "default_light",
           "prepare_animation", "run_animate"]

#: defaults of ``animate`` (image size [px], samples per pixel, frames, frames per second,
#: camera, GIF width [px])
ANIMATE_DEFAULTS = {"width": 480, "height": 270, "spp": 8, "frames": 31, "fps": 6,
                    "camera": "overview", "gif_width": 360}



def label_frame(img8, text: str):
    """A frame with ``text`` in a black box at its top left.

    Parameters
    ----------
    img8 : numpy.ndarray
        (height, width, 3) uint8 sRGB.
    text : str
        The label (white, font size 1/22 of the image height, at least 11 px).

    Returns
    -------
    numpy.ndarray
        The labelled image (uint8).
    """
    im = Image.fromarray(img8)
    d = ImageDraw.Draw(im)
    size = max(11, im.size[1] // 22)
    try:
        font = ImageFont.load_default(size=size)
    except TypeError:  # pragma: no cover - old Pillow
        font = ImageFont.load_default()
    x, y = 8, 6
    box = d.textbbox((x, y), text, font=font)
    d.rectangle((box[0] - 4, box[1] - 3, box[2] + 4, box[3] + 3), fill=(0, 0, 0))
    d.text((x, y), text, fill=(255, 255, 255), font=font)
    return np.asarray(im)


def ffmpeg_path() -> str | None:
    """The ``ffmpeg`` executable on ``PATH``, or None.

    Returns
    -------
    str or None
        Path of ``ffmpeg``, or None when it is not installed.
    """
    return shutil.which("ffmpeg")


def write_mp4(frames_dir: Path, pattern: str, path: Path, fps: int) -> Path | None:
    """An H.264 MP4 of numbered PNG frames with ffmpeg (MPEG-4 part 2 when libx264 is missing).

    Parameters
    ----------
    frames_dir : Path
        The folder of the frames.
    pattern : str
        Their names, e.g. ``frame_%04d.png``.
    path : Path
        The MP4 (written atomically).
    fps : int
        Frames per second.

    Returns
    -------
    Path or None
        ``path``, or None when ffmpeg is missing.
    """
    exe = ffmpeg_path()
    if exe is None:
        return None
    with atomic_write(path) as tmp:
        cmd = [exe, "-y", "-loglevel", "error", "-framerate", str(int(fps)), "-i",
               str(frames_dir / pattern), "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
               "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "20", "-movflags",
               "+faststart", str(tmp)]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            cmd[cmd.index("libx264")] = "mpeg4"
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"ffmpeg failed: {r.stderr.strip()[-400:]}")
    return path


def default_light(light, when) -> str:
    """The animation's light: ``light`` checked, or the default.

    Parameters
    ----------
    light : {"fixed", "daily"} or None
        The light asked for; None: ``"fixed"`` when a time ``when`` is given, else ``"daily"``.
    when : str or None
        ISO date-time of a fixed light, if any.

    Returns
    -------
    str
        ``"fixed"`` or ``"daily"``.

    Raises
    ------
    ParameterError
        If ``light`` is neither ``"fixed"`` nor ``"daily"``.
    """
    if light is None:
        return "fixed" if when is not None else "daily"
    if light not in ("fixed", "daily"):
        raise ParameterError("light", light, "'fixed' or 'daily'")
    return light


def prepare_animation(run_dir, out, scenario, *, camera=None, width=None, height=None,
                      spp=None, frames=None, every=None, fps=None, when=None, hour=None,
                      seed=0, denoise=True):
    """What every animation needs first (here or on Dask).

    The run, its output folder (claimed; old frames removed), the frame days, fps and the render
    options (``max_depth`` 5).

    Parameters
    ----------
    run_dir, out : path-like
        The run folder and the output folder (default ``RUN_DIR/animation``).
    scenario : path-like or None
        The run's scenario file (default: the one its summary names).
    camera : str, optional
        Camera preset (default ``overview``).
    width, height : int, optional
        Image size [pixels] (default 480 x 270).
    spp : int, optional
        Samples per pixel (default 8).
    frames : int, optional
        At most this many frames (default 31).
    every : int, optional
        One frame every ``every`` days [days].
    fps : int, optional
        Frames per second (default 6).
    when : str, optional
        ISO date-time of a fixed light.
    hour : float, optional
        Local hour of the light [h] (default 10).
    seed : int, optional
        Sampler seed (default 0).
    denoise : bool, optional
        Denoise the frames (default True).

    Returns
    -------
    tuple
        ``(run, out, frames_dir, days, fps, options dict, RenderOptions, OutputFolder)``.

    Raises
    ------
    ParameterError
        If a setting is out of range or the run has fewer than 2 days to animate.
    """
    check_image(width, height, spp, None, frames, every, fps)
    run = load_run(run_dir, scenario)
    out = Path(out if out is not None else Path(run_dir) / "animation").resolve()
    n_frames = int(ANIMATE_DEFAULTS["frames"] if frames is None else frames)
    fps = int(ANIMATE_DEFAULTS["fps"] if fps is None else fps)
    days = run.frame_days(count=n_frames, every=every)
    if len(days) < 2:
        raise ParameterError("RUN_DIR", str(run.dir), "a run with at least 2 days to animate",
                             "run more days")
    folder = OutputFolder(out, "animate", info={"run": str(run.dir)}, reads=run.dir)
    fdir = out / "frames"
    folder.clear(["frames"])        # the frames of an earlier animation (the package's only)
    fdir.mkdir(parents=True, exist_ok=True)
    opts = dict(width=width or ANIMATE_DEFAULTS["width"],
                height=height or ANIMATE_DEFAULTS["height"], spp=spp or ANIMATE_DEFAULTS["spp"],
                camera=camera or ANIMATE_DEFAULTS["camera"], seed=int(seed), when=when,
                max_depth=5, denoise=bool(denoise))
    if hour is not None:
        opts["hour"] = float(hour)
    return run, out, fdir, days, fps, opts, RenderOptions(**opts).validate(), folder


def run_animate(run_dir, out=None, *, camera=None, width=None, height=None, spp=None,
                frames=None, every=None, fps=None, when=None, hour=None, light=None,
                trees=None, scenario=None, gif_width=None, seed=0, denoise=True,
                progress=True) -> dict:
    """Render the days of a run to ``animation.mp4`` and ``animation.gif`` in this process.

    The last day is rendered first: its exposure is used for every frame (no flicker). Frames go to
    ``frames/frame_NNNN.png``, the summary to ``animate.json``. The same frames as Dask tasks:
    :func:`mitsuba_veg.sweeps.frames.run_animate`.

    Parameters
    ----------
    run_dir, out : path-like
        The run folder and the output folder (default ``RUN_DIR/animation``).
    camera : str, optional
        Camera preset (default ``overview``).
    width, height : int, optional
        Image size [pixels] (default 480 x 270).
    spp : int, optional
        Samples per pixel (default 8).
    frames, every : int, optional
        At most ``frames`` frames (default 31) spread over the snapshot days, or one every
        ``every`` days.
    fps : int, optional
        Frames per second (default 6).
    when : str, optional
        ISO date-time of a fixed light.
    hour : float, optional
        Local hour of the light [h] (default 10).
    light : {"daily", "fixed"}, optional
        ``"daily"`` (the default without ``when``): each frame's own date, moved into the one
        scene (:meth:`RenderScene.set_light`, ~0.1 s a frame, no recompile); ``"fixed"`` (the
        default with ``when``): the light of ``when`` or of the last day in every frame.
    trees : list of Tree, optional
        Trees instead of the scenario's.
    scenario : path-like, optional
        The run's scenario file (default: the one its summary names).
    gif_width : int, optional
        Downscale the GIF to this width [pixels] (default 360; 0 keeps the frame width).
    seed : int, optional
        Sampler seed (default 0); frame k renders with ``seed + k``.
    denoise : bool, optional
        Denoise the frames (default True).
    progress : bool, optional
        Show a progress bar over the frames (default True).

    Returns
    -------
    dict
        The summary written to ``animate.json``.
    """
    light = default_light(light, when)
    if gif_width is not None:
        check_range("gif_width", gif_width, 0, 16384)
    t0 = time.perf_counter()
    run, out, fdir, days, fps, opts, o, folder = prepare_animation(
        run_dir, out, scenario, camera=camera, width=width, height=height, spp=spp,
        frames=frames, every=every, fps=fps, when=when, hour=hour, seed=seed, denoise=denoise)
    version = tree_version(run, days[-1]) if trees is None else 0
    tree_list, seasons = trees_for_run(run, trees, days[-1])
    terrain = Terrain.from_scenario(run.scenario)
    last = run.frame(days[-1])
    emitters = None
    if light == "fixed":
        emitters = sky_emitters(run.scenario, render_time(run.scenario, last.date, o))
    timings = {"build": 0.0, "update": 0.0, "render": 0.0, "write": 0.0}
    bar = None
    if progress:
        bar = tqdm(total=len(days), unit="frame", desc="animate")
    # the last frame first: it sets the exposure of every frame (no flicker)
    order = [len(days) - 1] + list(range(len(days) - 1))
    rs = None
    exposure = None
    paths = [None] * len(days)
    records = [None] * len(days)
    try:
        for k in order:
            day = days[k]
            fr = last if k == len(days) - 1 else run.frame(day)
            if trees is None and tree_version(run, day) != version:
                # the world's trees grew at a year's end: this frame's trees, a new scene
                version = tree_version(run, day)
                tree_list, seasons = trees_for_run(run, trees, day)
                rs = None
            for s in seasons:
                s.apply(fr.date)
            t1 = time.perf_counter()
            if rs is None:
                gc.collect()
                rs = build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=tree_list,
                                 date=fr.date, options=o, terrain=terrain, emitters=emitters,
                                 species=run.species)
                timings["build"] += time.perf_counter() - t1
            else:
                rs.update(fr.moss, tree_list if tree_list else None)
                if light == "daily":
                    # the frame's daylight moved into the same scene: no rebuild, no recompile
                    when_k = render_time(run.scenario, fr.date, o)
                    rs.set_light(sky_emitters(run.scenario, when_k), when_k)
                timings["update"] += time.perf_counter() - t1
            # one sampler seed for every frame: what does not change between frames keeps its
            # noise (denoised), so a still scene does not flicker (benchmarks/render_noise.py)
            images = render(rs, seed=int(seed))
            timings["render"] += images["seconds"]
            t2 = time.perf_counter()
            img8, exp = to_srgb8(images["display"], exposure)
            exposure = exp if exposure is None else exposure
            text = f"day {day:3d}  {fr.date.isoformat()}  {len(fr.moss):,d} moss"
            p = write_png(fdir / f"frame_{k:04d}.png", label_frame(img8, text))
            paths[k] = p
            records[k] = {"day": day, "date": fr.date.isoformat(), "moss": len(fr.moss),
                          "exact": fr.exact, "render_s": images["seconds"],
                          "light": rs.info.get("when")}
            timings["write"] += time.perf_counter() - t2
            if bar is not None:
                bar.update(1)
                # the first frame rendered is the last day's (it fixes the exposure): say so
                bar.set_postfix(day=day, moss=len(fr.moss),
                                **({"frame": "last, for the exposure"} if k == order[0] else {}))
    finally:
        if bar is not None:
            bar.close()
    t3 = time.perf_counter()
    mp4 = write_mp4(fdir, "frame_%04d.png", out / "animation.mp4", fps)
    gif = write_gif(paths, out / "animation.gif", fps,
                    ANIMATE_DEFAULTS["gif_width"] if gif_width is None else gif_width)
    timings["encode"] = time.perf_counter() - t3
    summary = {"command": "animate", "run": str(run.dir), "frames": records,
               "exact": all(r["exact"] for r in records),
               "settings": {**opts, "fps": fps, "light": light, "when": rs.info.get("when")},
               "trees": len(tree_list),
               "files": {"mp4": str(mp4) if mp4 else None, "gif": str(gif),
                         "frames": str(fdir)},
               "timings_s": {**timings, "total": time.perf_counter() - t0},
               "versions": versions()}
    if mp4 is None:
        summary["warning"] = "ffmpeg not found: no MP4 written (install ffmpeg)"
    write_json(out / "animate.json", summary)
    folder.release()
    return summary
