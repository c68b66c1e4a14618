"""Generate the floor of the one-hectare scenario: a rolling ground with logs and rocks lying on
it (:mod:`mitsuba_veg.forest_floor`).

Run ``python scenes/forest_hectare/make_scene.py`` (deterministic) to rewrite, next to this
script:

- ``ground.ply``  a 100 m x 100 m plot (x, z in [-50, 50]; +x east, +z south, +y up; 1 ha) at
                  1 m resolution (20,000 triangles): a 5° south-facing slope with a 0.3 m RMS
                  relief of 15 m wavelength;
- ``log_0.ply`` .. ``log_19.ply``, ``rock_0.ply`` .. ``rock_29.ply``: twenty logs and thirty
                  rocks set on the ground, clear (by 1 m) of the tree bases that the scenario's
                  ``[stand]`` lays out (the same spec and seed);
- ``scene.xml``   the Mitsuba scene (no emitters: the world loop adds the day's sun and sky);

and prints the ``[terrain.soil_depth_mm]`` lines of the floor objects for scenario.toml.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

from mitsuba_veg.forest_floor import rolling_ground, scatter_floor, write_ply
from mitsuba_veg.trees.stand import StandSpec, layout

HERE = Path(__file__).resolve().parent
BOUNDS = (-50.0, -50.0, 50.0, 50.0)
LOGS, ROCKS = 20, 30
#: scenario fields of [stand] that are not StandSpec fields
WORLD_FIELDS = ("generations", "growth", "age", "age_rate", "adapt_yearly", "death_threshold")


def main() -> None:
    ground = rolling_ground(BOUNDS, slope_deg=5.0, aspect_deg=180.0, roughness=0.3,
                            roughness_scale=15.0, seed=4, resolution=1.0)
    stand = tomllib.loads((HERE / "scenario.toml").read_text())["stand"]
    spec = StandSpec.from_dict({k: v for k, v in stand.items() if k not in WORLD_FIELDS})
    bases = layout(spec).positions[:, [0, 2]]
    floor = scatter_floor(ground, logs=LOGS, rocks=ROCKS, seed=6, avoid=bases, clearance=1.0,
                          log_length=(2.0, 6.0), log_radius=(0.12, 0.35),
                          rock_radius=(0.25, 0.7))
    ground.write_ply(HERE / "ground.ply")
    xml = ['<scene version="3.0.0">', '  <shape type="ply" id="ground">',
           '    <string name="filename" value="ground.ply"/>',
           '    <bsdf type="diffuse"><spectrum name="reflectance" value="0.12"/></bsdf>',
           '  </shape>']
    depth = []
    for obj in floor:
        write_ply(HERE / f"{obj.name}.ply", obj.vertices, obj.faces)
        xml += [f'  <shape type="ply" id="{obj.name}">',
                f'    <string name="filename" value="{obj.name}.ply"/>',
                '    <bsdf type="diffuse"><spectrum name="reflectance" value="'
                f'{0.18 if obj.kind == "log" else 0.3}"/></bsdf>', '  </shape>']
        depth.append(f"{obj.name} = {20.0 if obj.kind == 'log' else 2.0}")
    xml.append("</scene>")
    (HERE / "scene.xml").write_text("\n".join(xml) + "\n")
    print(f"wrote ground ({len(ground.mesh()[1])} triangles), {LOGS} logs, {ROCKS} rocks; "
          f"{len(bases)} tree bases kept clear; soil depths:")
    print("\n".join(depth))


if __name__ == "__main__":
    main()
