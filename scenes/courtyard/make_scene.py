"""Generate the courtyard scene of the world scenario: ground, a house wall, a low garden wall,
geology texture.

Run ``python scenes/courtyard/make_scene.py`` (deterministic) to rewrite, next to this script:

- ``ground.ply``   8 m x 8 m (x in [-4, 4] east, z in [-4, 4] south, +y up), a 40 x 40 grid of
                   20 cm cells (3200 triangles), a gentle swale (-5 cm) along the bed, UVs
                   ``u = (x+4)/8``, ``v = (z+4)/8``;
- ``house.ply``    closed box along the west edge: x in [-4.6, -4.0], y in [0, 4.5], z in
                   [-4, 4] (a house wall facing east, 4.5 m high); faces cut into <= 0.5 m cells;
- ``wall.ply``     a low garden wall along the north edge: x in [-4, 4], y in [0, 1.2], z in
                   [-4.3, -4.0];
- ``geology.png``  ground classes: humus (70, 50, 35) in the planted bed, sand (200, 160, 80)
                   in the east, paving (asphalt, 110, 110, 110) along the south path;
- ``scene.xml``    the Mitsuba scene (no emitters: the world loop adds the day's sun and sky).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

HERE = Path(__file__).resolve().parent
HALF, CELLS = 4.0, 40
HOUSE_LO, HOUSE_HI = (-4.6, 0.0, -4.0), (-4.0, 4.5, 4.0)
WALL_LO, WALL_HI = (-4.0, 0.0, -4.3), (4.0, 1.2, -4.0)
TEX = 256
HUMUS, SAND, ASPHALT = (70, 50, 35), (200, 160, 80), (110, 110, 110)
SAND_RECT = (1.6, 4.0, -4.0, 1.6)      # x0, x1, z0, z1 [m]
PATH_RECT = (-4.0, 4.0, 2.8, 4.0)


def ground():
    n = CELLS + 1
    x = np.linspace(-HALF, HALF, n)
    X, Z = np.meshgrid(x, x)
    Y = -0.05 * np.exp(-((X + 1.0) ** 2) / 2.0) * (np.abs(Z) < 3.0)
    V = np.stack([X, Y, Z], -1).reshape(-1, 3)
    i = np.arange(CELLS)
    a = (i[:, None] * n + i[None, :]).ravel()
    F = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    uv = np.stack([(V[:, 0] + HALF) / (2 * HALF), (V[:, 2] + HALF) / (2 * HALF)], 1)
    return V, F, uv


def box(lo, hi, cell=0.5):
    m = trimesh.creation.box(bounds=np.array([lo, hi]))
    while np.max(m.edges_unique_length) > cell:
        m = m.subdivide()
    return np.asarray(m.vertices), np.asarray(m.faces)


def write_ply(path, V, F, uv=None):
    """Binary little-endian PLY: float32 x y z [u v], faces as uchar-count int32 index lists.

    Coordinates are rounded to 6 decimals [m] before the float32 conversion (the courtyard's
    geometry as first defined: the same float32 values Mitsuba read from that text).
    """
    header = ["ply", "format binary_little_endian 1.0",
              "comment mitsuba-veg courtyard (scenes/courtyard/make_scene.py)",
              f"element vertex {len(V)}",
              "property float x", "property float y", "property float z"]
    cols = [np.asarray(V, float)]
    if uv is not None:
        header += ["property float u", "property float v"]
        cols.append(np.asarray(uv, float))
    header += [f"element face {len(F)}", "property list uchar int vertex_indices",
               "end_header"]
    # decimal text -> float32, as a PLY reader does (float() of the 6-decimal string)
    vdata = np.array([[float(f"{c:.6f}") for c in row] for row in np.hstack(cols)],
                     np.float64).astype("<f4")
    fdata = np.zeros(len(F), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    fdata["n"] = 3
    fdata["i"] = F
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(vdata.tobytes())
        fh.write(fdata.tobytes())


def texture():
    img = np.zeros((TEX, TEX, 3), np.uint8)
    img[:] = HUMUS
    c = (np.arange(TEX) + 0.5) / TEX * 2 * HALF - HALF      # pixel centres [m]
    X, Z = np.meshgrid(c, c)                                 # row = v (north first)
    for rect, col in ((SAND_RECT, SAND), (PATH_RECT, ASPHALT)):
        x0, x1, z0, z1 = rect
        img[(X >= x0) & (X <= x1) & (Z >= z0) & (Z <= z1)] = col
    Image.fromarray(img).save(HERE / "geology.png")


SCENE = """<?xml version="1.0" encoding="utf-8"?>
<!-- mitsuba-veg: the courtyard of the world scenario, written by scenes/courtyard/make_scene.py
     - edit that script, not this file. +y up, +x east, +z south; metres. Ground 8 m x 8 m,
     a 4.5 m house wall along the west edge, a 1.2 m garden wall along the north edge.
     No emitters: the daily loop adds the day's sun path and sky. -->
<scene version="3.0.0">
    <shape type="ply" id="ground">
        <string name="filename" value="ground.ply"/>
        <bsdf type="diffuse"><spectrum name="reflectance" value="0.2"/></bsdf>
    </shape>
    <shape type="ply" id="house">
        <string name="filename" value="house.ply"/>
        <bsdf type="diffuse"><spectrum name="reflectance" value="0.35"/></bsdf>
    </shape>
    <shape type="ply" id="wall">
        <string name="filename" value="wall.ply"/>
        <bsdf type="diffuse"><spectrum name="reflectance" value="0.3"/></bsdf>
    </shape>
</scene>
"""


def main():
    V, F, uv = ground()
    write_ply(HERE / "ground.ply", V, F, uv)
    write_ply(HERE / "house.ply", *box(HOUSE_LO, HOUSE_HI))
    write_ply(HERE / "wall.ply", *box(WALL_LO, WALL_HI))
    texture()
    (HERE / "scene.xml").write_text(SCENE)
    print("wrote", ", ".join(p.name for p in sorted(HERE.iterdir()) if p.suffix != ".py"))


if __name__ == "__main__":
    main()
