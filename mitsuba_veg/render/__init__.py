"""The final spectral render: scene assembly, images and animations of a run.

Example::

    import mitsuba_veg as mv
    from mitsuba_veg import render as mr
    run = mr.load_run("out/demo/moss")                  # a moss run folder
    rs = mr.build_scene(run.scenario, run.final_moss(), moss_size=run.moss_size,
                        date=run.date(run.final_day), options=mr.RenderOptions(spp=64))
    images = mr.render(rs)          # XYZ, linear sRGB, red / far-red bands, R:FR ratio
    mr.write_outputs(images, "out/render")               # render.exr, render.png, render_rfr.png
    mr.run_render("out/demo/moss"); mr.run_animate("out/demo/moss")   # the CLI's work

See docs/render.md.
"""
from __future__ import annotations

from . import carpet, denoise, fidelity, materials  # noqa: F401
from .film import BANDS, develop, read_exr, rfr_false_colour, to_srgb8, write_exr  # noqa: F401
from ..outputs import SnapshotWriter, write_snapshot  # noqa: F401
from .history import Frame, Run, load_run  # noqa: F401
from .moss import MossSet, live_moss, place_tufts  # noqa: F401
from .scene import RenderOptions, RenderScene, Terrain, build_scene, make_mesh  # noqa: F401
from .still import render, run_render, write_outputs  # noqa: F401
from .animation import run_animate  # noqa: F401
from .trees import make_tree, scenario_trees, simple_tree  # noqa: F401
from .tufts import tuft_models  # noqa: F401


__all__ = ["BANDS", "develop", "read_exr", "rfr_false_colour", "to_srgb8", "write_exr", "Frame",
           "Run", "SnapshotWriter", "load_run", "write_snapshot", "MossSet", "live_moss",
           "place_tufts", "RenderOptions", "RenderScene", "Terrain", "build_scene", "make_mesh",
           "render", "write_outputs", "make_tree", "scenario_trees", "simple_tree", "tuft_models",
           "run_render", "run_animate", "materials", "carpet", "denoise", "fidelity"]
