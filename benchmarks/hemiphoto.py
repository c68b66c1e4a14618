"""A hemispherical photograph of a stand's floor: its time once the scene is loaded (target:
1024 x 1024 of the hectare's floor in <= 30 s on the 2-core machine), the loading apart.

    nice -n 5 python benchmarks/hemiphoto.py [--scenario scenes/forest_hectare/scenario.toml]
        [--at X,Z ...] [--size 1024] [--colour-spp 0]

Builds the scenario's trees as a run builds them at set-up (``world.trees.scenario_trees``),
in full green leaf (every leaf shown: the densest canopy of the year), the camera's scene of
the scenario's shapes and the trees (``world.visible_canopy``), and prints:

- loading: the trees, the visible canopy, the scene (Mitsuba's acceleration structure) [s],
  leaves and triangles, resident memory;
- per point: the ray-cast photograph (one ray per pixel, ``light.fisheye.gap_image``), its
  analysis (``light.gap_fraction.analyse``: rings, LAI, site factors with the year's sun
  paths, the first point paying for that year's sun positions), the true area index in the view
  cone, and the photograph's total against the 30 s target as a ratio;
- with ``--colour-spp N``: a colour photograph of the first point at that many samples per
  pixel (its own scene with the optics and the sky), timed apart;
- the peak resident memory.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import resource
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET_S = 30.0


def rss() -> float:
    """Resident memory of the process now [GB]."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return float(line.split()[1]) / 1e6
    return float("nan")


def peak() -> float:
    """Peak resident memory of the process so far [GB]."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenes" / "forest_hectare" /
                                              "scenario.toml"))
    ap.add_argument("--at", action="append", default=None, metavar="X,Z")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--colour-spp", type=int, default=0)
    ap.add_argument("--date", default="2026-07-15")
    a = ap.parse_args(argv)

    import mitsuba_veg as mv  # noqa: F401
    from mitsuba_veg.daily.hemiphotos import points_at, take_photos
    from mitsuba_veg.light.fisheye import Lens
    from mitsuba_veg.scenario import load_scenario
    from mitsuba_veg.world.trees import scenario_trees
    from mitsuba_veg.world.visible_canopy import LeafState, VisibleCanopy

    at = [tuple(float(v) for v in s.split(",")) for s in (a.at or ["0,0", "10,-10"])]
    date = _dt.date.fromisoformat(a.date)
    print(f"scenario {a.scenario}, photographs {a.size} x {a.size} at {at}, {date}")
    t0 = time.perf_counter()
    scn = load_scenario(a.scenario)
    base = scn.load_scene(daylight=False)
    trees = scenario_trees(scn, base)
    t1 = time.perf_counter()
    canopy = VisibleCanopy(trees, int((scn.get("phenology") or {}).get("stage_bins", 4)))
    state = LeafState.green(canopy.n_leaves)
    t2 = time.perf_counter()
    scene = canopy.scene(list(base.shapes()), state, optics=False)
    t3 = time.perf_counter()
    tris = sum(s.face_count() for s in scene.shapes() if s.is_mesh())
    print(f"loading: trees {t1 - t0:.1f} s ({len(trees)} trees, {canopy.n_leaves:,d} leaves), "
          f"visible canopy {t2 - t1:.1f} s, scene {t3 - t2:.1f} s ({tris:,d} triangles); "
          f"{t3 - t0:.1f} s in all; resident {rss():.1f} GB")
    points = points_at(base, scn.get("terrain.ground", "ground"), at, 1.0)
    lat, lon = float(scn.get("site.latitude")), float(scn.get("site.longitude"))
    lens = Lens(int(a.size))
    for p in points:
        t4 = time.perf_counter()
        ph = take_photos(scene, [p], date, canopy, state, lat, lon, lens)[0]
        t5 = time.perf_counter()
        v, t = ph.analysis.values, ph.truth
        print(f"point {p.name} ({p.x:g}, {p.z:g}): ray cast {ph.image.seconds:.2f} s, analysis "
              f"and truth {t5 - t4 - ph.image.seconds:.2f} s, photograph {t5 - t4:.2f} s -> "
              f"ratio to the {TARGET_S:.0f} s target {(t5 - t4) / TARGET_S:.3f}; openness "
              f"{v['openness']:.3f}, LAI-2000 Le {v['lai_lai2000']:.2f}, true LAI "
              f"{t['lai_true']:.2f}, DSF {v['site_factor_diffuse']:.3f}")
    if a.colour_spp > 0:
        from mitsuba_veg.canopy_photo.colour import colour_photo
        t6 = time.perf_counter()
        _, info = colour_photo(canopy, list(base.shapes()), state, points[0].position, date,
                               scn, lens, spp=a.colour_spp)
        print(f"colour photograph {a.size} x {a.size} at {a.colour_spp} spp: scene "
              f"{info['seconds']['load']:.1f} s, render {info['seconds']['render']:.1f} s "
              f"({time.perf_counter() - t6:.1f} s with developing)")
    print(f"peak resident memory {peak():.1f} GB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
