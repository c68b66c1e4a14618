"""``mitsuba-veg render RUN_DIR`` and ``mitsuba-veg animate RUN_DIR``.

:func:`run_render` renders the last day of a moss run (or ``day``) from one or more camera
presets and writes, per camera, ``render_<camera>.exr`` (RGB + red/far-red bands + R:FR),
``render_<camera>.png`` (sRGB) and ``render_<camera>_rfr.png`` (red:far-red false colour), plus
``render.json`` (settings, counts, timings, files).

:func:`run_animate` renders the run's days (the snapshot days, thinned to ``frames``) at lower
settings, with one light (the last day's, so that the rendering kernel is compiled once) and
writes ``frames/frame_NNNN.png``, ``animation.mp4`` (H.264, ffmpeg), ``animation.gif`` and
``animate.json``.
"""
from __future__ import annotations

import gc
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from ..errors import ParameterError, check_range

RENDER_DEFAULTS = {"width": 800, "height": 450, "spp": 24, "cameras": ("overview", "shelter")}
ANIMATE_DEFAULTS = {"width": 480, "height": 270, "spp": 8, "frames": 31, "fps": 6,
                    "camera": "overview", "gif_width": 360}


from ..outputs import write_json as _write_json  # noqa: E402


def _versions() -> dict:
    from ..variant import versions
    return versions()


def _cameras(camera) -> list[str]:
    if camera is None:
        return list(RENDER_DEFAULTS["cameras"])
    if isinstance(camera, str):
        return [c.strip() for c in camera.split(",") if c.strip()]
    return list(camera)


class WorldLeaves:
    """The leaf state of a world run's trees on a frame's date (from the run's snapshots):
    ``apply(date)`` writes ``autumn_tau``, ``leaf_scale`` and ``fallen`` into the trees'
    leaves, as the daily loop had them that day."""

    def __init__(self, run, trees, offsets):
        self.run, self.trees, self.offsets = run, trees, offsets

    def apply(self, date) -> None:
        day = (date - self.run.start).days + 1
        st = self.run.leaf_state(day)
        for t, (a, b) in zip(self.trees, self.offsets):
            lv = t.leaves
            if st is None or len(st["leaf_tau"]) < b:
                lv.attrs["autumn_tau"] = np.zeros(len(lv))
                lv.attrs["leaf_scale"] = np.ones(len(lv))
                lv.attrs["fallen"] = np.zeros(len(lv), bool)
                continue
            lv.attrs["autumn_tau"] = st["leaf_tau"][a:b].astype(float)
            lv.attrs["leaf_scale"] = st["leaf_grown"][a:b].astype(float)
            lv.attrs["fallen"] = ~st["leaf_on"][a:b].astype(bool)


def world_trees(run):
    """The trees of a world run (``[[trees]]``), rebuilt from its scenario as the run built
    them (same seeds), and their leaves' offsets in the run's leaf arrays. Trees given as
    meshes are drawn by the light scene only (not by the render)."""
    import logging

    from ..world import build_trees
    entries = run.scenario.get("trees") or []
    if not entries:
        return [], []
    base = run.scenario.load_scene(daylight=False)
    built = build_trees(entries, base, run.scenario.root, str(run.scenario.path))
    trees, offsets, n = [], [], 0
    for wt in built:
        m = len(wt.leaf_area)
        if wt.tree is not None:
            trees.append(wt.tree)
            offsets.append((n, n + m))
        else:
            logging.getLogger("mitsuba_veg").warning(
                "tree '%s' (a mesh) is in the run's light but not drawn by the render", wt.name)
        n += m
    return trees, offsets


def _trees_for(run, trees):
    """Trees of the render: ``trees`` if given (a list of Tree; [] for none), else a world
    run's ``[[trees]]`` (in each frame's leaf state) and the scenario's ``[[render.trees]]``
    (decoration, with their calendar phenology)."""
    from .seasons import TreeSeasons
    from .trees import scenario_trees
    world, seasons = [], []
    if trees is None:
        world, offsets = world_trees(run)
        if world:
            seasons.append(WorldLeaves(run, world, offsets))
    tl = scenario_trees(run.scenario) if trees is None else list(trees)
    if tl:
        lat = float(run.scenario.get("site.latitude"))
        cfgs = run.scenario.get("render.trees", []) or []
        if isinstance(cfgs, dict):
            cfgs = [cfgs]
        for i, t in enumerate(tl):
            auto = cfgs[i].get("autumn", True) if i < len(cfgs) else True
            if auto and trees is None and len(t.leaves):
                seasons.append(TreeSeasons(t, lat, run.start, max(run.final_day, 1) + 1, seed=i))
    return world + tl, seasons


def run_render(run_dir, out=None, *, camera=None, width=None, height=None, spp=None,
               day=None, when=None, hour=None, max_depth=None, trees=None, scenario=None,
               seed=0, progress=True) -> dict:
    """Render a moss run (module docstring). ``out`` defaults to ``RUN_DIR/render``;
    ``camera``: preset name(s), comma-separated or a list (default overview and shelter);
    ``day``: the simulated day to show (default: the last); ``when``: ISO date-time of the
    light (default: that day at ``hour``, 10:00 local); ``trees``: a list of Tree to add
    instead of the scenario's ``[[render.trees]]``. Returns the summary written to
    ``render.json``."""
    from . import RenderOptions, load_run
    from .scene import Terrain

    from ..outputs import OutputFolder
    t0 = time.perf_counter()
    _check_image(width, height, spp, max_depth)
    run = load_run(run_dir, scenario)
    out = Path(out) if out is not None else Path(run_dir) / "render"
    last = run.final_day
    day = last if day is None else int(day)
    check_range("day", day, 1, max(last, 1), fix=f"a simulated day of the run (1-{last})")
    frame = run.frame(day)
    folder = OutputFolder(out, "render", info={"run": str(run.dir)})
    opts = dict(width=width or RENDER_DEFAULTS["width"],
                height=height or RENDER_DEFAULTS["height"], spp=spp or RENDER_DEFAULTS["spp"],
                when=when, seed=int(seed))
    if hour is not None:
        opts["hour"] = float(hour)
    if max_depth is not None:
        opts["max_depth"] = int(max_depth)
    tree_list, seasons = _trees_for(run, trees)
    for s in seasons:
        s.apply(frame.date)
    terrain = Terrain.from_scenario(run.scenario)
    cams = _cameras(camera)
    results = {}
    files = {}
    bar = None
    if progress:
        from tqdm.auto import tqdm
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
               "seconds": time.perf_counter() - t0, "versions": _versions()}
    _write_json(out / "render.json", summary)
    folder.release()
    return summary


def _check_image(width, height, spp, max_depth=None, frames=None, every=None, fps=None):
    """Refuse image settings out of range (``None`` = the default)."""
    for name, v, lo, hi in (("--width", width, 16, 16384), ("--height", height, 16, 16384),
                            ("--spp", spp, 1, 65536), ("--max-depth", max_depth, 1, 1000),
                            ("--frames", frames, 2, 10000), ("--every", every, 1, 100_000),
                            ("--fps", fps, 1, 120)):
        if v is not None:
            check_range(name, v, lo, hi)


def _render_cameras(cams, opts, run, frame, tree_list, terrain, tree_cache, out, day, bar,
                    results, files):
    from . import RenderOptions, build_scene, render, write_outputs
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
        results[cam] = {"render_s": images["seconds"], "exposure": w["exposure"],
                        "info": rs.info, "files": w["files"],
                        "r_fr_median": float(np.nanmedian(rfr)) if rfr is not None else None,
                        "mean_rgb": np.nanmean(images["rgb"].reshape(-1, 3), 0).tolist()}
        files[cam] = w["files"]
        del rs, images
        gc.collect()
        if bar is not None:
            bar.update(1)
            bar.set_postfix(camera=cam, s=f"{results[cam]['render_s']:.1f}")


# ---- animation ----------------------------------------------------------------------------------
def _label(img8, text: str):
    from PIL import Image, ImageDraw, ImageFont
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
    return shutil.which("ffmpeg")


def write_mp4(frames_dir: Path, pattern: str, path: Path, fps: int) -> Path | None:
    """H.264 MP4 of numbered PNG frames with ffmpeg (None when ffmpeg is missing)."""
    exe = ffmpeg_path()
    if exe is None:
        return None
    tmp = path.with_name("." + path.stem + ".tmp.mp4")
    cmd = [exe, "-y", "-loglevel", "error", "-framerate", str(int(fps)), "-i",
           str(frames_dir / pattern), "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
           "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "20", "-movflags", "+faststart",
           str(tmp)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        cmd[cmd.index("libx264")] = "mpeg4"
        r = subprocess.run(cmd + [], capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"ffmpeg failed: {r.stderr.strip()[-400:]}")
    os.replace(tmp, path)
    return path


def write_gif(frames: list, path: Path, fps: int, width: int | None = None) -> Path:
    from PIL import Image
    imgs = []
    for f in frames:
        im = Image.open(f).convert("RGB")
        if width and im.size[0] > width:
            im = im.resize((width, round(im.size[1] * width / im.size[0])), Image.LANCZOS)
        imgs.append(im.convert("P", palette=Image.ADAPTIVE, colors=255))
    tmp = path.with_name("." + path.stem + ".tmp.gif")
    durations = [int(1000 / fps)] * len(imgs)
    if durations:
        durations[-1] = 1500      # hold the last day
    imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=durations, loop=0,
                 optimize=True)
    os.replace(tmp, path)
    return path


def prepare_animation(run_dir, out, scenario, *, camera=None, width=None, height=None,
                      spp=None, frames=None, every=None, fps=None, when=None, hour=None,
                      seed=0):
    """What every animation needs first (here or on Dask): the run, its output folder
    (claimed; old frames removed), the frame days, fps and the render options. Returns
    ``(run, out, frames_dir, days, fps, options dict, RenderOptions, OutputFolder)``."""
    from ..outputs import OutputFolder
    from . import RenderOptions, load_run
    _check_image(width, height, spp, None, frames, every, fps)
    run = load_run(run_dir, scenario)
    out = Path(out if out is not None else Path(run_dir) / "animation").resolve()
    n_frames = int(ANIMATE_DEFAULTS["frames"] if frames is None else frames)
    fps = int(ANIMATE_DEFAULTS["fps"] if fps is None else fps)
    days = run.frame_days(count=n_frames, every=every)
    if len(days) < 2:
        raise ParameterError("RUN_DIR", str(run.dir), "a run with at least 2 days to animate",
                             "run more days")
    folder = OutputFolder(out, "animate", info={"run": str(run.dir)})
    fdir = out / "frames"
    fdir.mkdir(parents=True, exist_ok=True)
    for old in fdir.glob("frame_*.png"):
        old.unlink()
    opts = dict(width=width or ANIMATE_DEFAULTS["width"],
                height=height or ANIMATE_DEFAULTS["height"], spp=spp or ANIMATE_DEFAULTS["spp"],
                camera=camera or ANIMATE_DEFAULTS["camera"], seed=int(seed), when=when,
                max_depth=5)
    if hour is not None:
        opts["hour"] = float(hour)
    return run, out, fdir, days, fps, opts, RenderOptions(**opts).validate(), folder


def run_animate(run_dir, out=None, *, camera=None, width=None, height=None, spp=None,
                frames=None, every=None, fps=None, when=None, hour=None, light="fixed",
                trees=None, scenario=None, gif_width=None, seed=0, progress=True,
                scheduler=None, workers=None, client=None) -> dict:
    """Render the days of a moss run to ``animation.mp4`` and ``animation.gif`` (module
    docstring). ``frames``: at most this many frames (default 31), spread over the snapshot
    days (or every ``every`` days); ``light``: ``"fixed"`` (the last day's light for every
    frame: one kernel compile) or ``"daily"`` (each frame's own date; recompiles per frame);
    ``gif_width``: downscale the GIF to this width (default 360 px; 0 keeps the frame width).
    ``scheduler`` (a Dask scheduler address), ``workers`` (worker processes of a local Dask
    cluster) or ``client``: render the frames as Dask tasks
    (:func:`mitsuba_veg.sweeps.frames.animate_on_dask`). Returns the summary written to
    ``animate.json``."""
    if light not in ("fixed", "daily"):
        raise ParameterError("light", light, "'fixed' or 'daily'")
    if scheduler is not None or workers is not None or client is not None:
        if trees is not None:
            raise ParameterError("trees", "a list of Tree", "None when the frames run on Dask "
                                 "(the workers build the scenario's [[render.trees]])",
                                 "put the trees in the scenario's [[render.trees]]")
        from ..sweeps.frames import animate_on_dask
        return animate_on_dask(run_dir, out, scheduler=scheduler, workers=workers,
                               client=client, camera=camera, width=width, height=height,
                               spp=spp, frames=frames, every=every, fps=fps, when=when,
                               hour=hour, light=light, scenario=scenario, gif_width=gif_width,
                               seed=seed, progress=progress)
    from . import build_scene, render
    from .film import to_srgb8, write_png
    from .scene import Terrain, render_time, sky_emitters

    if gif_width is not None:
        check_range("gif_width", gif_width, 0, 16384)
    t0 = time.perf_counter()
    run, out, fdir, days, fps, opts, o, folder = prepare_animation(
        run_dir, out, scenario, camera=camera, width=width, height=height, spp=spp,
        frames=frames, every=every, fps=fps, when=when, hour=hour, seed=seed)
    tree_list, seasons = _trees_for(run, trees)
    terrain = Terrain.from_scenario(run.scenario)
    last = run.frame(days[-1])
    emitters = None
    if light == "fixed":
        emitters = sky_emitters(run.scenario, render_time(run.scenario, last.date, o))
    timings = {"build": 0.0, "update": 0.0, "render": 0.0, "write": 0.0}
    bar = None
    if progress:
        from tqdm.auto import tqdm
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
            for s in seasons:
                s.apply(fr.date)
            t1 = time.perf_counter()
            if rs is None or light == "daily":
                rs = None
                gc.collect()
                rs = build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=tree_list,
                                 date=fr.date, options=o, terrain=terrain, emitters=emitters,
                                 species=run.species)
                timings["build"] += time.perf_counter() - t1
            else:
                rs.update(fr.moss, tree_list if tree_list else None)
                timings["update"] += time.perf_counter() - t1
            images = render(rs, seed=int(seed) + k)
            timings["render"] += images["seconds"]
            t2 = time.perf_counter()
            img8, exp = to_srgb8(images["rgb"], exposure)
            exposure = exp if exposure is None else exposure
            text = f"day {day:3d}  {fr.date.isoformat()}  {len(fr.moss):,d} moss"
            p = write_png(fdir / f"frame_{k:04d}.png", _label(img8, text))
            paths[k] = p
            records[k] = {"day": day, "date": fr.date.isoformat(), "moss": len(fr.moss),
                          "exact": fr.exact, "render_s": images["seconds"]}
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
               "versions": _versions()}
    if mp4 is None:
        summary["warning"] = "ffmpeg not found: no MP4 written (install ffmpeg)"
    _write_json(out / "animate.json", summary)
    folder.release()
    return summary


# ---- argparse -----------------------------------------------------------------------------------
def add_parsers(subparsers) -> None:
    """Add ``render`` and ``animate`` to the ``mitsuba-veg`` sub-command parsers."""
    from ..cliargs import add_quiet, iso_datetime, ranged

    def common(p, what, spp):
        p.add_argument("run_dir", help="a run folder (mitsuba-veg run ... --out DIR)")
        p.add_argument("--out", metavar="DIR", help=f"output folder (default RUN_DIR/{what})")
        p.add_argument("--scenario", metavar="TOML",
                       help="scenario file of the run (default: the one summary.json names)")
        p.add_argument("--width", type=ranged(int, 16, 16384, "pixels"),
                       help="image width [pixels] (default "
                            f"{(RENDER_DEFAULTS if what == 'render' else ANIMATE_DEFAULTS)['width']})")
        p.add_argument("--height", type=ranged(int, 16, 16384, "pixels"),
                       help="image height [pixels] (default "
                            f"{(RENDER_DEFAULTS if what == 'render' else ANIMATE_DEFAULTS)['height']})")
        p.add_argument("--spp", type=ranged(int, 1, 65536, "samples"),
                       help=f"samples per pixel (default {spp})")
        p.add_argument("--hour", type=ranged(float, 0, 24, "h"),
                       help="local hour of the daylight [h] (default 10)")
        add_quiet(p)

    r = subparsers.add_parser("render", help="spectral render of a moss run (EXR, PNG, R:FR)")
    common(r, "render", RENDER_DEFAULTS["spp"])
    r.add_argument("--camera", help="camera preset(s), comma-separated: overview, shelter, top, "
                   "scene or a [render.cameras.NAME] of the scenario (default overview,shelter)")
    r.add_argument("--day", type=ranged(int, 1, 100_000, "day"),
                   help="simulated day to show (default: the last)")
    r.add_argument("--when", metavar="ISO-DATETIME", type=iso_datetime,
                   help="date-time of the daylight, e.g. 2026-06-21T10:00:00+09:00 (default: "
                        "the day shown at --hour)")
    r.add_argument("--max-depth", type=ranged(int, 1, 1000, "bounces"),
                   help="path length of the render (default 8)")
    r.set_defaults(func=_cmd_render)
    a = subparsers.add_parser("animate", help="animate the days of a moss run (MP4 + GIF)")
    common(a, "animation", ANIMATE_DEFAULTS["spp"])
    a.add_argument("--camera", help=f"camera preset (default {ANIMATE_DEFAULTS['camera']})")
    a.add_argument("--frames", type=ranged(int, 2, 10000, "frames"),
                   help=f"at most this many frames (default {ANIMATE_DEFAULTS['frames']})")
    a.add_argument("--every", type=ranged(int, 1, 100_000, "days"),
                   help="a frame every N days of the snapshot days (default: spread --frames "
                        "over the run)")
    a.add_argument("--fps", type=ranged(int, 1, 120, "frames/s"),
                   help=f"frames per second (default {ANIMATE_DEFAULTS['fps']})")
    a.add_argument("--light", choices=("fixed", "daily"), default="fixed",
                   help="fixed: the last day's light in every frame (fast); daily: each "
                        "frame's date (slower)")
    a.add_argument("--scheduler", metavar="ADDRESS",
                   help="render the frames as Dask tasks on this scheduler (tcp://host:8786)")
    a.add_argument("--workers", type=ranged(int, 1, 1024, "processes"), metavar="N",
                   help="render the frames as Dask tasks on a local cluster of N processes")
    a.set_defaults(func=_cmd_animate)


def _cmd_render(a) -> int:
    s = run_render(a.run_dir, a.out, camera=a.camera, width=a.width, height=a.height, spp=a.spp,
                   day=a.day, when=a.when, hour=a.hour, max_depth=a.max_depth,
                   scenario=a.scenario, progress=not a.quiet)
    print(f"rendered day {s['day']} ({s['date']}): {s['moss']:,d} moss, {s['trees']} trees, "
          f"{s['seconds']:.1f} s")
    print("wrote:")
    for cam, f in s["files"].items():
        for p in f.values():
            print(f"  {p}")
    print(f"  {Path(next(iter(s['files'].values()))['png']).parent / 'render.json'}")
    return 0


def _cmd_animate(a) -> int:
    s = run_animate(a.run_dir, a.out, camera=a.camera, width=a.width, height=a.height,
                    spp=a.spp, frames=a.frames, every=a.every, fps=a.fps, light=a.light,
                    hour=a.hour, scenario=a.scenario, progress=not a.quiet,
                    scheduler=a.scheduler, workers=a.workers)
    t = s["timings_s"]
    print(f"animated {len(s['frames'])} days in {t['total']:.1f} s (render {t['render']:.1f} s)"
          + ("" if s["exact"] else "; moss of past days approximated from the last checkpoint "
             "(no snapshots in the run)"))
    if s.get("warning"):
        print(f"warning: {s['warning']}")
    print("wrote:")
    for k in ("mp4", "gif", "frames"):
        if s["files"].get(k):
            print(f"  {s['files'][k]}")
    return 0
