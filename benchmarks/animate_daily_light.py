"""Cost of an animation's daily light: moving a frame's daylight into the built scene
(``RenderScene.set_light``) against rendering a frame and against rebuilding the scene.

    python benchmarks/animate_daily_light.py [--width 480 --height 270 --spp 8]

Prints seconds per frame for render, set_light and rebuild + render, their ratios, and whether
every kernel after set_light came from the cache (no recompile). docs/render.md quotes it.
"""
import argparse
import time
from pathlib import Path

import drjit as dr

import mitsuba_veg  # noqa: F401  (variant, plugins)
from mitsuba_veg.render import RenderOptions, Terrain, build_scene, render
from mitsuba_veg.render.scene import sky_emitters
from mitsuba_veg.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=270)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    scn = load_scenario(ROOT / "scenes" / "moss_garden" / "scenario.toml")
    terrain = Terrain.from_scenario(scn)
    o = RenderOptions(width=a.width, height=a.height, spp=a.spp, camera="overview",
                      when="2026-06-21T12:00+09:00")
    rs = build_scene(scn, None, options=o, terrain=terrain)
    render(rs, seed=0)
    first = "2026-02-15T10:00+09:00"
    rs.set_light(sky_emitters(scn, first), first)   # set_light's own small kernels, once
    render(rs, seed=0)
    t = time.perf_counter()
    for i in range(a.reps):
        render(rs, seed=i)
    t_render = (time.perf_counter() - t) / a.reps
    t_set, hits = 0.0, []
    for m in range(3, 3 + a.reps):
        when = f"2026-{m:02d}-15T10:00+09:00"
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
            t = time.perf_counter()
            rs.set_light(sky_emitters(scn, when), when)
            dr.sync_thread()     # set_light's kernels in its time, not in the render's
            t_set += time.perf_counter() - t
            render(rs, seed=m)
            hits += [h["cache_hit"] for h in dr.kernel_history([dr.KernelType.JIT])]
    t_set /= a.reps
    t = time.perf_counter()
    for m in range(a.reps):
        b = build_scene(scn, None, options=o, terrain=terrain,
                        emitters=sky_emitters(scn, f"2026-{m + 6:02d}-15T10:00+09:00"))
        render(b, seed=m)
        del b
    t_rebuild = (time.perf_counter() - t) / a.reps
    print(f"{a.width}x{a.height}, {a.spp} spp, moss garden overview")
    print(f"render             {t_render:.3f} s/frame")
    print(f"set_light          {t_set:.3f} s/frame ({t_set / t_render:.2f} of a render)")
    print(f"rebuild + render   {t_rebuild:.3f} s/frame ({t_rebuild / (t_render + t_set):.1f}x "
          f"set_light + render)")
    print(f"kernels after set_light from the cache: {sum(hits)}/{len(hits)}")


if __name__ == "__main__":
    main()
