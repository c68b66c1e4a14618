"""Generate the forest floor of the forest-stand scenario: a sloped, rolling ground with logs
and rocks lying on it (:mod:`mitsuba_veg.forest_floor`).

Run ``python scenes/forest_stand/make_scene.py`` (deterministic) to rewrite, next to this
script:

- ``ground.ply``  a 32 m x 32 m plot (x, z in [-16, 16]; +x east, +z south, +y up; 0.1 ha) at
                  0.5 m resolution (8,192 triangles): an 8° south-facing slope with a 0.3 m RMS
                  relief of 12 m wavelength;
- ``log_0.ply`` .. ``log_5.ply``, ``rock_0.ply`` .. ``rock_9.ply``: six logs and ten rocks
                  set on the ground, clear (by 1 m) of the tree bases that the scenario's
                  ``[stand]`` lays out (the same spec and seed);
- ``scene.xml``   the Mitsuba scene (no emitters: the world loop adds the day's sun and sky).
"""
from __future__ import annotations

import tomllib
from pathlib import Path

from mitsuba_veg.forest_floor import rolling_ground, scatter_floor, write_ply
from mitsuba_veg.trees.stand import StandSpec, layout

HERE = Path(__file__).resolve().parent
BOUNDS = (-16.0, -16.0, 16.0, 16.0)
LOGS, ROCKS = 6, 10


def main() -> None:
    ground = rolling_ground(BOUNDS, slope_deg=8.0, aspect_deg=180.0, roughness=0.3,
                            roughness_scale=12.0, seed=3, resolution=0.5)
    stand = tomllib.loads((HERE / "scenario.toml").read_text())["stand"]
    spec = StandSpec.from_dict({k: v for k, v in stand.items()
                                if k not in ("generations", "growth")})
    bases = layout(spec).positions[:, [0, 2]]
    floor = scatter_floor(ground, logs=LOGS, rocks=ROCKS, seed=5, avoid=bases, clearance=1.0,
                          log_length=(2.0, 5.0), log_radius=(0.12, 0.3),
                          rock_radius=(0.25, 0.6))
    ground.write_ply(HERE / "ground.ply")
    xml = ['<scene version="3.0.0">',
           '  <shape type="ply" id="ground">',
           '    <string name="filename" value="ground.ply"/>',
           '    <bsdf type="diffuse"><spectrum name="reflectance" value="0.12"/></bsdf>',
           '  </shape>']
    for obj in floor:
        write_ply(HERE / f"{obj.name}.ply", obj.vertices, obj.faces)
        albedo = 0.18 if obj.kind == "log" else 0.3
        xml += [f'  <shape type="ply" id="{obj.name}">',
                f'    <string name="filename" value="{obj.name}.ply"/>',
                f'    <bsdf type="diffuse"><spectrum name="reflectance" value="{albedo}"/>'
                '</bsdf>',
                '  </shape>']
    xml.append("</scene>")
    (HERE / "scene.xml").write_text("\n".join(xml) + "\n")
    print(f"wrote ground ({len(ground.mesh()[1])} triangles), {LOGS} logs, {ROCKS} rocks; "
          f"{len(bases)} tree bases kept clear")


if __name__ == "__main__":
    main()
