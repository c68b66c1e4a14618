"""Generate the moss-garden test scene of paper 000 (§4): ground, roof, back wall, geology texture.

Run ``python scenes/moss_garden/make_scene.py`` (deterministic: numpy + trimesh + pillow, no
randomness) to rewrite, next to this script:

- ``ground.ply``   heightfield 2 m x 2 m (x in [-1, 1] east, z in [-1, 1] south, +y up), a 40 x 40
                   grid (3200 triangles), normals up, per-vertex UVs ``u = (x+1)/2``,
                   ``v = (z+1)/2`` (PLY vertex properties ``u``, ``v``; Mitsuba's PLY loader keeps
                   them as they are).
- ``roof.ply``     closed slab (box) over the back (north, -z) part: x in [-1, 1],
                   y in [0.75, 0.80], z in [-0.95, 0.15]; faces subdivided into <= 10 cm cells so
                   that per-triangle light has some resolution; outward normals (the underside
                   faces point down, -y). Its back end is embedded in the wall.
- ``wall.ply``     closed box, the back wall carrying the roof: x in [-1, 1], y in [-0.05, 1.5],
                   z in [-1, -0.9]; outward normals.
- ``geology.png``  512 x 512 ground texture (nearest-colour classes, see
                   :mod:`mitsuba_veg.terrain`): humus (70, 50, 35), sand (200, 160, 80),
                   asphalt (110, 110, 110). Row 0 of the image is v = 0, i.e. the north (back) edge
                   z = -1 (Mitsuba's bitmap convention: v = 0 is the first, top row; the PLY
                   loader does not flip v), column 0 is u = 0, the west edge x = -1. So the image
                   reads like a map with north up.
- ``scene.xml``    the Mitsuba 3 scene (see the comments in it).

Layout (plan, metres): humus everywhere except a sand patch in the sunny front-east
(x >= 0.1, z >= -0.1, with a 12 cm mound on it) and an asphalt path running north from the
front edge into the shelter (x in [-0.4, -0.1], z >= -0.65). A 6 cm hollow lies in the humus
under the roof (back-east). All region edges are multiples of 5 cm, i.e. ground-grid lines, so
every ground triangle lies in exactly one geology class.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

HERE = Path(__file__).resolve().parent

# --- dimensions [m] -------------------------------------------------------------------------
GROUND_HALF = 1.0          # ground spans [-1, 1] in x and z
GROUND_CELLS = 40          # 40 x 40 cells of 5 cm -> 3200 triangles
MOUND = dict(x=0.55, z=0.50, height=0.12, sigma=0.22)    # low mound (sand, open)
HOLLOW = dict(x=0.45, z=-0.50, depth=0.06, sigma=0.18)   # shallow hollow (humus, sheltered)
ROOF_LO, ROOF_HI = (-1.0, 0.75, -0.95), (1.0, 0.80, 0.15)
WALL_LO, WALL_HI = (-1.0, -0.05, -1.0), (1.0, 1.50, -0.90)
BOX_CELL = 0.10            # max cell size on the box faces [m]

# --- geology texture --------------------------------------------------------------------------
TEX_SIZE = 512
HUMUS, SAND, ASPHALT = (70, 50, 35), (200, 160, 80), (110, 110, 110)
SAND_RECT = dict(x0=0.10, x1=1.00, z0=-0.10, z1=1.00)
PATH_RECT = dict(x0=-0.40, x1=-0.10, z0=-0.65, z1=1.00)

# --- light ------------------------------------------------------------------------------------
SUN_ELEVATION_DEG = 55.0
SUN_AZIMUTH_DEG = 170.0    # clockwise from north (-z): 180 = due south (+z); 170 = a little east
SUN_IRRADIANCE = 1.0       # W m-2 nm-1, uniform over wavelength (perpendicular to the beam)
SKY_RADIANCE = 0.05        # W m-2 sr-1 nm-1, uniform (horizontal irradiance pi*0.05 = 0.16)


def ground_height(x, z):
    """Ground height y [m] at (x, z) [m]: a Gaussian mound and a Gaussian hollow on y = 0."""
    m = MOUND["height"] * np.exp(-((x - MOUND["x"]) ** 2 + (z - MOUND["z"]) ** 2)
                                 / (2 * MOUND["sigma"] ** 2))
    h = HOLLOW["depth"] * np.exp(-((x - HOLLOW["x"]) ** 2 + (z - HOLLOW["z"]) ** 2)
                                 / (2 * HOLLOW["sigma"] ** 2))
    return m - h


def make_ground():
    """Heightfield mesh: vertices (V,3), faces (F,3) with up-facing normals, uv (V,2)."""
    n = GROUND_CELLS
    s = np.linspace(-GROUND_HALF, GROUND_HALF, n + 1)
    x, z = np.meshgrid(s, s, indexing="xy")        # x varies along columns, z along rows
    y = ground_height(x, z)
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    uv = np.stack([(x + GROUND_HALF) / (2 * GROUND_HALF),
                   (z + GROUND_HALF) / (2 * GROUND_HALF)], axis=-1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")   # i: x index, j: z index
    a = (j * (n + 1) + i).ravel()          # (x_i, z_j)
    b = a + 1                              # (x_i+1, z_j)
    c = a + (n + 1)                        # (x_i, z_j+1)
    d = c + 1                              # (x_i+1, z_j+1)
    # With +x east, +z south, +y up, the counter-clockwise order seen from above (+y) is
    # a -> c -> b (x right, z towards the viewer): normal (c-a) x (b-a) = (+z) x (+x) = +y.
    # Alternate the diagonal in a checkerboard so the relief is not biased in one direction.
    flip = ((i + j) % 2 == 1).ravel()
    t1 = np.where(flip[:, None], np.stack([a, c, d], 1), np.stack([a, c, b], 1))
    t2 = np.where(flip[:, None], np.stack([a, d, b], 1), np.stack([b, c, d], 1))
    faces = np.concatenate([t1, t2], axis=0)
    return vertices, faces, uv


def _grid_face(origin, du, dv, nu, nv):
    """A planar grid of nu x nv cells spanned by du, dv from origin; normal = du x dv."""
    a = np.linspace(0.0, 1.0, nu + 1)
    b = np.linspace(0.0, 1.0, nv + 1)
    A, B = np.meshgrid(a, b, indexing="xy")
    verts = (np.asarray(origin)[None, :] + A.reshape(-1, 1) * np.asarray(du)[None, :]
             + B.reshape(-1, 1) * np.asarray(dv)[None, :])
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="xy")
    p00 = (j * (nu + 1) + i).ravel()
    p10, p01 = p00 + 1, p00 + (nu + 1)
    p11 = p01 + 1
    faces = np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])
    return verts, faces


def make_box(lo, hi, cell=BOX_CELL):
    """Watertight box [lo, hi] with outward normals, faces split into cells of <= ``cell``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ext = hi - lo
    n = np.maximum(1, np.ceil(ext / cell - 1e-9).astype(int))
    ex, ey, ez = np.diag(ext)                       # edge vectors along x, y, z
    parts = [
        # (origin, du, dv, nu, nv) with du x dv pointing outwards
        (lo, ez, ey, n[2], n[1]),                 # -x
        (lo + ex, ey, ez, n[1], n[2]),            # +x
        (lo, ex, ez, n[0], n[2]),                 # -y  (underside: normal down)
        (lo + ey, ez, ex, n[2], n[0]),            # +y
        (lo, ey, ex, n[1], n[0]),                 # -z
        (lo + ez, ex, ey, n[0], n[1]),            # +z
    ]
    vs, fs, off = [], [], 0
    for origin, du, dv, nu, nv in parts:
        v, f = _grid_face(origin, du, dv, nu, nv)
        vs.append(v)
        fs.append(f + off)
        off += len(v)
    mesh = trimesh.Trimesh(np.concatenate(vs), np.concatenate(fs), process=False)
    mesh.merge_vertices(digits_vertex=9)
    mesh.remove_unreferenced_vertices()
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, "bad box"
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def write_ply(path, vertices, faces, uv=None):
    """Binary little-endian PLY: float32 x y z [u v], faces as uchar-count int32 index lists."""
    header = ["ply", "format binary_little_endian 1.0",
              "comment mitsuba-veg moss_garden (scenes/moss_garden/make_scene.py)",
              f"element vertex {len(vertices)}",
              "property float x", "property float y", "property float z"]
    cols = [np.asarray(vertices, float)]
    if uv is not None:
        header += ["property float u", "property float v"]
        cols.append(np.asarray(uv, float))
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices",
               "end_header"]
    vdata = np.hstack(cols).astype("<f4")
    fdata = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    fdata["n"] = 3
    fdata["i"] = faces
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(vdata.tobytes())
        fh.write(fdata.tobytes())


def make_geology_texture(size=TEX_SIZE):
    """RGB uint8 image (size, size, 3); row r <-> v = (r+0.5)/size <-> z, column c <-> u <-> x."""
    c = (np.arange(size) + 0.5) / size                 # texel centres in [0, 1]
    x = -GROUND_HALF + 2 * GROUND_HALF * c             # per column
    z = -GROUND_HALF + 2 * GROUND_HALF * c             # per row
    X, Z = np.meshgrid(x, z, indexing="xy")
    img = np.empty((size, size, 3), np.uint8)
    img[...] = HUMUS
    sand = ((X >= SAND_RECT["x0"]) & (X <= SAND_RECT["x1"])
            & (Z >= SAND_RECT["z0"]) & (Z <= SAND_RECT["z1"]))
    path = ((X >= PATH_RECT["x0"]) & (X <= PATH_RECT["x1"])
            & (Z >= PATH_RECT["z0"]) & (Z <= PATH_RECT["z1"]))
    img[sand] = SAND
    img[path] = ASPHALT
    return img


def sun_light_direction(elevation_deg=SUN_ELEVATION_DEG, azimuth_deg=SUN_AZIMUTH_DEG):
    """Direction the sunlight travels (unit, world frame) for a sun at (elevation, azimuth).

    Azimuth is clockwise from north (-z) towards east (+x); the direction *towards* the sun is
    (sin az cos el, sin el, -cos az cos el); the light travels the opposite way.
    """
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    to_sun = np.array([math.sin(az) * math.cos(el), math.sin(el), -math.cos(az) * math.cos(el)])
    return -to_sun


SCENE_XML = """<?xml version="1.0" encoding="utf-8"?>
<!-- mitsuba-veg: the test scene of paper 000 (moss grown by photon-mapped light), written by
     scenes/moss_garden/make_scene.py - edit that script, not this file.
     World frame: +y up, +x east, +z south; metres. Ground 2 m x 2 m at y ~ 0 (mound +12 cm,
     hollow -6 cm); roof slab y 0.75-0.80 m over z -0.95..0.15 (north/back part) carried by the
     back wall (z -1..-0.9, up to y = 1.5 m). Scene box: 2 m x 2 m x 1.55 m.
     All spectra are explicit and uniform over wavelength: in spectral variants a plain <float>
     or <rgb> emitter value would become a D65-shaped spectrum. -->
<scene version="3.0.0">
    <integrator type="path">
        <integer name="max_depth" value="8"/>
    </integrator>

    <!-- Default sun: {elev:g} deg elevation, azimuth {azim:g} deg (clockwise from north),
         i.e. from the south, slightly east. irradiance in W m-2 nm-1 perpendicular to the beam;
         `direction` is where the light travels. -->
    <emitter type="directional" id="sun">
        <vector name="direction" x="{dx:.6f}" y="{dy:.6f}" z="{dz:.6f}"/>
        <spectrum name="irradiance" type="uniform">
            <float name="value" value="{sun:g}"/>
        </spectrum>
    </emitter>

    <!-- Uniform sky over the upper hemisphere only (mitsuba-veg's `veg_sky`, registered by
         `import mitsuba_veg`): radiance in W m-2 sr-1 nm-1, horizontal irradiance = pi *
         radiance. Mitsuba's `constant` would also light the roof's underside from below the
         horizon, which in a real garden is ground, not sky. -->
    <emitter type="veg_sky" id="sky">
        <string name="distribution" value="uniform"/>
        <spectrum name="radiance" type="uniform">
            <float name="value" value="{sky:g}"/>
        </spectrum>
    </emitter>

    <!-- Ground: soil albedo ref = 0.2 (paper 000 eq 3.4). Geology lives in geology.png (UVs). -->
    <shape type="ply" id="ground">
        <string name="filename" value="ground.ply"/>
        <bsdf type="diffuse" id="ground_bsdf">
            <spectrum name="reflectance" value="0.2"/>
        </bsdf>
    </shape>

    <!-- Roof slab (closed box, outward normals: the underside faces point down). -->
    <shape type="ply" id="roof">
        <string name="filename" value="roof.ply"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="diffuse" id="roof_bsdf">
            <spectrum name="reflectance" value="0.35"/>
        </bsdf>
    </shape>

    <!-- Back wall (closed box). -->
    <shape type="ply" id="wall">
        <string name="filename" value="wall.ply"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="diffuse" id="wall_bsdf">
            <spectrum name="reflectance" value="0.3"/>
        </bsdf>
    </shape>

    <!-- Camera from the south-east, above (only needed for mi.render). -->
    <sensor type="perspective" id="camera">
        <float name="fov" value="50"/>
        <transform name="to_world">
            <lookat origin="2.6, 1.9, 2.9" target="-0.05, 0.25, -0.25" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="64"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="640"/>
            <integer name="height" value="480"/>
            <rfilter type="gaussian"/>
        </film>
    </sensor>
</scene>
"""


def main(out_dir: Path = HERE) -> None:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    v, f, uv = make_ground()
    write_ply(out_dir / "ground.ply", v, f, uv)
    rv, rf = make_box(ROOF_LO, ROOF_HI)
    write_ply(out_dir / "roof.ply", rv, rf)
    wv, wf = make_box(WALL_LO, WALL_HI)
    write_ply(out_dir / "wall.ply", wv, wf)
    Image.fromarray(make_geology_texture()).save(out_dir / "geology.png", optimize=True)
    d = sun_light_direction()
    (out_dir / "scene.xml").write_text(SCENE_XML.format(
        elev=SUN_ELEVATION_DEG, azim=SUN_AZIMUTH_DEG, dx=d[0], dy=d[1], dz=d[2],
        sun=SUN_IRRADIANCE, sky=SKY_RADIANCE))
    print(f"ground: {len(f)} triangles, roof: {len(rf)}, wall: {len(wf)} -> {out_dir}")


if __name__ == "__main__":
    main()
