"""``mitsuba-veg render RUN_DIR``, ``mitsuba-veg animate RUN_DIR`` and
``mitsuba-veg export-gltf RUN_DIR``.

:func:`run_render` renders the last day of a moss run (or ``day``) from one or more camera
presets and writes, per camera, ``render_<camera>.exr`` (RGB + red/far-red bands + R:FR),
``render_<camera>.png`` (sRGB) and ``render_<camera>_rfr.png`` (red:far-red false colour), plus
``render.json`` (settings, counts, timings, files).

:func:`run_animate` renders the run's days (the snapshot days, thinned to ``frames``) at lower
settings, with one light (the last day's, so that the rendering kernel is compiled once) and
writes ``frames/frame_NNNN.png``, ``animation.mp4`` (H.264, ffmpeg), ``animation.gif`` and
``animate.json``.

The work is done by :func:`mitsuba_veg.render.still.run_render` and
:func:`mitsuba_veg.sweeps.frames.run_animate` (in this process or on Dask).
"""
from __future__ import annotations

from pathlib import Path

from ..render.animation import ANIMATE_DEFAULTS
from ..render.gltf_day import export_day
from ..render.still import RENDER_DEFAULTS, run_render, run_render_years
from ..sweeps.frames import run_animate
from .args import add_out, add_quiet, iso_datetime, ranged

__all__ = ["add_parsers", "run_render", "run_animate", "export_day"]


def add_parsers(subparsers) -> None:
    """Add ``render`` and ``animate`` to the ``mitsuba-veg`` sub-command parsers.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``mitsuba-veg`` parser (``add_subparsers()``).
    """

    def common(p, what, spp):
        p.add_argument("run_dir", help="a run folder (mitsuba-veg run ... --out DIR)")
        add_out(p, None, f"the {what} (default RUN_DIR/{what})")
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
        p.add_argument("--no-denoise", dest="denoise", action="store_false",
                       help="no denoiser on the PNG's image (the EXR is never denoised)")
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
    r.add_argument("--years", action="store_true",
                   help="render the last snapshot day of every year of the run (a stand year "
                        "by year) into RUN_DIR/render_<year> (or <--out>_<year>), and the "
                        "years as a GIF per camera into RUN_DIR/render_years")
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
    a.add_argument("--light", choices=("daily", "fixed"), default=None,
                   help="daily (default without --when): each frame's date, moved into one "
                        "scene (~0.1 s a frame); fixed (default with --when): one light for "
                        "every frame")
    a.add_argument("--scheduler", metavar="ADDRESS",
                   help="render the frames as Dask tasks on this scheduler (tcp://host:8786)")
    a.add_argument("--workers", type=ranged(int, 1, 1024, "processes"), metavar="N",
                   help="render the frames as Dask tasks on a local cluster of N processes")
    a.set_defaults(func=_cmd_animate)
    g = subparsers.add_parser("export-gltf", help="a day of a run as glTF (.glb): terrain with "
                              "its moss cover, the trees with their leaves' colours")
    g.add_argument("run_dir", help="a run folder (mitsuba-veg run ... --out DIR)")
    g.add_argument("--day", type=ranged(int, 1, 100_000, "day"),
                   help="simulated day (default: the last with a snapshot)")
    g.add_argument("--out", metavar="FILE.glb",
                   help="the file (default RUN_DIR/gltf/day_NNNN.glb)")
    g.add_argument("--scenario", metavar="TOML",
                   help="scenario file of the run (default: the one summary.json names)")
    add_quiet(g)
    g.set_defaults(func=_cmd_export_gltf)


def _cmd_export_gltf(a) -> int:
    info = export_day(a.run_dir, a.day, a.out, a.scenario)
    if not a.quiet:
        tris = sum(m["triangles"] for m in info["meshes"])
        print(f"day {info['day']} ({info['date']}): {len(info['meshes'])} meshes, {tris:,d} "
              f"triangles, {info['leaves_on_trees']:,d} leaves on the trees, moss cover "
              f"{info['moss_cover_m2']:.3f} m2 -> {info['path']}")
    return 0


def _cmd_render(a) -> int:
    if a.years:
        res = run_render_years(a.run_dir, a.out, camera=a.camera, width=a.width,
                               height=a.height, spp=a.spp, day=a.day, when=a.when,
                               hour=a.hour, max_depth=a.max_depth, scenario=a.scenario,
                               denoise=a.denoise, progress=not a.quiet)
        for year, y in res["years"].items():
            print(f"{year}: day {y['day']} ({y['date']})")
            for f in y["files"].values():
                for p in f.values():
                    print(f"  {p}")
        for cam, gif in res["animations"].items():
            print(f"the years, {cam}: {gif}")
        return 0
    s = run_render(a.run_dir, a.out, camera=a.camera, width=a.width, height=a.height, spp=a.spp,
                   day=a.day, when=a.when, hour=a.hour, max_depth=a.max_depth,
                   scenario=a.scenario, denoise=a.denoise, progress=not a.quiet)
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
                    hour=a.hour, scenario=a.scenario, denoise=a.denoise, progress=not a.quiet,
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
