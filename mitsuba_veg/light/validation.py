"""Independent references for the photon pass and the small scenes used to validate it.

- :func:`grid_mesh` / :func:`box_mesh`: vertices and faces of meshes built in memory (no
  files), made into Mitsuba meshes with ids by :func:`mitsuba_veg.meshes.make_mesh`.
- :func:`roof_wall_scene`: ground + roof slab + wall, sun + uniform sky, spectrally flat.
- :func:`path_reference`: per-triangle irradiance from Mitsuba's own ``path`` integrator with one
  ``irradiancemeter`` per triangle (each selected triangle becomes its own mesh carrying the
  sensor, so the geometry is unchanged), plus the direct irradiance of delta emitters
  (suns, point and spot lights) added by shadow rays, because an irradiancemeter never samples
  a delta emitter at its own surface.
- :func:`as_meshes`: a scene dict whose mesh shapes (``rectangle``, ``cube``, ``obj``, ``ply``)
  are replaced by in-memory meshes with the same ids, so that :func:`path_reference` can cut
  triangles out of them (e.g. Mitsuba's ``mi.cornell_box()``).

The irradiancemeter's film is a ``specfilm`` whose sensitivity is 1 over the band, so the
reference is the band-integrated irradiance [W m-2] for any emitter and reflectance spectra.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import SceneError
from mitsuba_veg.meshes import make_mesh


__all__ = ["grid_mesh", "box_mesh", "sun_vector", "roof_wall_scene", "path_reference", "as_meshes",
           "plant_mesh", "plant_scene"]

def grid_mesh(nx: int, nz: int, x=(-1.0, 1.0), z=(-1.0, 1.0), y=0.0, height=None, up=True):
    """Vertices/faces of a grid in the x-z plane at height ``y`` (normals +y when ``up``).

    Parameters
    ----------
    nx, nz : int
        Cells along x and z (2 nx nz triangles).
    x, z : tuple of float, optional
        Extent ``(min, max)`` along x and z [m]; default ``(-1, 1)``.
    y : float, optional
        Height of the grid [m]; default 0.
    height : callable, optional
        ``height(X, Z)`` adds relief [m] to ``y`` (X, Z: arrays of the vertex coordinates [m]);
        default None (flat).
    up : bool, optional
        Normals towards +y (True, default) or -y.

    Returns
    -------
    vertices : numpy.ndarray
        ((nx+1)(nz+1), 3) positions [m].
    faces : numpy.ndarray
        (2 nx nz, 3) vertex indices.
    """
    xs = np.linspace(x[0], x[1], nx + 1)
    zs = np.linspace(z[0], z[1], nz + 1)
    X, Z = np.meshgrid(xs, zs)
    Y = np.full_like(X, y) if height is None else y + height(X, Z)
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    a = (np.arange(nz)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    # (a, a+nx+1, a+1): with x right and z towards the viewer this winds so the normal is +y
    F = np.concatenate([np.stack([a, a + nx + 1, a + 1], 1),
                        np.stack([a + 1, a + nx + 1, a + nx + 2], 1)])
    if not up:
        F = F[:, ::-1]
    return V, F


def box_mesh(lo, hi):
    """Vertices/faces of an axis-aligned box with outward normals (12 triangles).

    Parameters
    ----------
    lo, hi : array_like
        Lower and upper corners ``[x, y, z]`` [m].

    Returns
    -------
    vertices : numpy.ndarray
        (8, 3) corner positions [m].
    faces : numpy.ndarray
        (12, 3) vertex indices, wound so that the normals point outwards.
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    V = lo + c * (hi - lo)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    F = []
    for a, b, cc, d in quads:
        F += [[a, b, cc], [a, cc, d]]
    F = np.array(F)
    # orient outwards
    cen = V.mean(0)
    for i, (a, b, cc) in enumerate(F):
        n = np.cross(V[b] - V[a], V[cc] - V[a])
        if np.dot(n, (V[a] + V[b] + V[cc]) / 3 - cen) < 0:
            F[i] = [a, cc, b]
    return V, F


def sun_vector(elevation_deg: float, azimuth_deg: float = 180.0) -> np.ndarray:
    """Unit vector towards the sun (+y up, +x east, +z south; azimuth clockwise from north).

    Parameters
    ----------
    elevation_deg : float
        Solar elevation above the horizon [degrees].
    azimuth_deg : float, optional
        Solar azimuth, clockwise from north [degrees]; default 180 (south).

    Returns
    -------
    numpy.ndarray
        (3,) unit vector towards the sun [-].
    """
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.sin(a) * math.cos(e), math.sin(e), -math.cos(a) * math.cos(e)])


def roof_wall_scene(sun_elevation=50.0, sun_azimuth=180.0, sun_irradiance=1.0, sky_radiance=0.05,
                    ground_albedo=0.3, roof_albedo=0.5, wall_albedo=0.5, n=12):
    """Scene dict: 2 m x 2 m ground grid, a roof slab over its north half, a wall at the north.

    Emitters: a ``directional`` sun [W m-2 nm-1, uniform spectrum] and a ``constant`` sky
    [W m-2 sr-1 nm-1]; meshes are given as ``mi.Mesh`` objects with ids ground/roof/wall and
    diffuse, spectrally flat BSDFs. The roof slab spans y 0.60-0.66 m over z in [-1, 0] m; the
    wall is 0.6 m high at z in [-1.3, -1.0] m.

    Parameters
    ----------
    sun_elevation : float, optional
        Solar elevation [degrees]; default 50.
    sun_azimuth : float, optional
        Solar azimuth clockwise from north [degrees]; default 180 (south).
    sun_irradiance : float, optional
        Sun irradiance on a plane normal to the beam [W m-2 nm-1]; <= 0: no sun; default 1.
    sky_radiance : float, optional
        Uniform sky radiance [W m-2 sr-1 nm-1]; <= 0: no sky; default 0.05.
    ground_albedo, roof_albedo, wall_albedo : float, optional
        Diffuse reflectances [-]; defaults 0.3, 0.5, 0.5.
    n : int, optional
        Ground grid cells per side (2 n^2 triangles); default 12.

    Returns
    -------
    dict
        The scene dict for ``mi.load_dict(d, optimize=False)``.
    """
    gv, gf = grid_mesh(n, n)
    rv, rf = box_mesh((-1.0, 0.6, -1.0), (1.0, 0.66, 0.0))
    wv, wf = box_mesh((-1.0, 0.0, -1.3), (1.0, 0.6, -1.0))
    sun = sun_vector(sun_elevation, sun_azimuth)
    d = {"type": "scene",
         "ground": make_mesh("ground", gv, gf, ground_albedo),
         "roof": make_mesh("roof", rv, rf, roof_albedo),
         "wall": make_mesh("wall", wv, wf, wall_albedo)}
    if sun_irradiance > 0:
        d["sun"] = {"type": "directional", "id": "sun", "direction": (-sun).tolist(),
                    "irradiance": {"type": "uniform", "value": float(sun_irradiance)}}
    if sky_radiance > 0:
        d["sky"] = {"type": "constant", "id": "sky",
                    "radiance": {"type": "uniform", "value": float(sky_radiance)}}
    return d


def path_reference(scene_dict: dict, shape_id: str, triangles, spp: int = 4096,
                   max_depth: int = 16, band=(360.0, 830.0), seed: int = 0):
    """Per-triangle front irradiance [W m-2] of ``shape_id`` by Mitsuba's path tracer.

    Each triangle in ``triangles`` is cut out of its mesh (an in-memory ``mi.Mesh`` of the dict,
    see :func:`as_meshes`) into its own mesh carrying an ``irradiancemeter`` whose ``specfilm``
    integrates the band ``band`` [nm]; the scene is otherwise identical. The direct irradiance
    of delta emitters is added with shadow rays (``spp`` points per triangle, at least 4096, from
    ``seed``). Each triangle is rendered in 4 batches of ``spp / 4`` samples.

    Parameters
    ----------
    scene_dict : dict
        Scene dict whose shape ``shape_id`` is an in-memory ``mi.Mesh`` (not modified).
    shape_id : str
        Id of the mesh.
    triangles : iterable of int
        Indices of the triangles of the mesh to measure.
    spp : int, optional
        Samples per pixel of each irradiancemeter; default 4096.
    max_depth : int, optional
        ``max_depth`` of the ``path`` integrator; default 16.
    band : tuple of float, optional
        Band ``(lo, hi)`` [nm] the irradiance is integrated over; default (360, 830).
    seed : int, optional
        Seed of the renders and of the shadow-ray points; default 0.

    Returns
    -------
    irradiance : numpy.ndarray
        (len(triangles),) band-integrated front irradiance [W m-2].
    std_error : numpy.ndarray
        (len(triangles),) standard error [W m-2]: the path-traced part's (from the 4 batches)
        and the shadow-ray part's (from its points) in quadrature.

    Raises
    ------
    SceneError
        If the dict holds no in-memory mesh with id ``shape_id``.
    """
    key = None
    for k, v in scene_dict.items():
        if isinstance(v, mi.Mesh) and v.id() == shape_id:
            key = k
    if key is None:
        raise SceneError(f"path_reference: no in-memory mesh with id '{shape_id}' in the scene "
                         "dict (build meshes with mitsuba_veg.meshes.make_mesh, or "
                         "convert the dict with validation.as_meshes)")
    mesh = scene_dict[key]
    V = np.asarray(mesh.vertex_positions_buffer()).reshape(-1, 3)
    F = np.asarray(mesh.faces_buffer()).reshape(-1, 3)
    tris = [int(t) for t in triangles]
    keep = np.ones(len(F), bool)
    keep[tris] = False
    d = {k: v for k, v in scene_dict.items() if k != key}
    if keep.any():  # (a mesh with no faces left would be an empty shape)
        d[key] = make_mesh(shape_id, V, F[keep], bsdf=mesh.bsdf())
    lo, hi = float(band[0]), float(band[1])
    for t in tris:
        props = mi.Properties()
        props["bsdf"] = mesh.bsdf()
        props["sensor"] = mi.load_dict({
            "type": "irradiancemeter",
            "film": {"type": "specfilm", "width": 1, "height": 1, "rfilter": {"type": "box"},
                     "band": {"type": "regular", "wavelength_min": lo, "wavelength_max": hi,
                              "values": "1, 1"}}})
        m = mi.Mesh(f"{shape_id}__ref{t}", 3, 1, props=props)
        p = mi.traverse(m)
        p["vertex_positions"] = mi.Float(V[F[t]].astype(np.float32).ravel())
        p["faces"] = mi.UInt32([0, 1, 2])
        p.update()
        d[f"{key}__ref{t}"] = m
    scene = mi.load_dict(d, optimize=False)
    integrator = mi.load_dict({"type": "path", "max_depth": int(max_depth), "hide_emitters": False})
    by_shape = {}
    for s in scene.sensors():
        sh = s.get_shape() if hasattr(s, "get_shape") else s.shape()
        if sh is not None:
            by_shape[sh.id()] = s
    out = np.zeros(len(tris))
    err = np.zeros(len(tris))
    batches = 4
    for j, t in enumerate(tris):
        sensor = by_shape[f"{shape_id}__ref{t}"]
        vals = []
        for b in range(batches):
            img = mi.render(scene, sensor=sensor, integrator=integrator,
                            spp=max(1, spp // batches), seed=seed * 7919 + t * batches + b)
            vals.append(float(np.asarray(img).ravel()[0]))
        out[j] = np.mean(vals)
        err[j] = np.std(vals, ddof=1) / math.sqrt(batches)
    # direct light of delta emitters, which the irradiancemeter never samples; its
    # Monte-Carlo error adds to the path-traced batches' in quadrature
    direct, direct_err = _delta_direct(scene, F[tris], V, (lo, hi),
                                      samples_per_tri=min(max(int(spp), 4096), 1 << 20),
                                      seed=seed)
    return out + direct, np.sqrt(err**2 + direct_err**2)


def _delta_direct(scene: mi.Scene, faces, V, band, samples_per_tri: int = 4096, seed: int = 0):
    """Direct irradiance [W m-2] of delta emitters (directional, point, spot, projector: the
    ones an ``irradiancemeter`` never samples) on triangles, integrated over ``band`` [nm]
    (wavelengths drawn uniformly in the band), with shadow rays; and its standard error
    [W m-2] (points and wavelengths from ``seed``)."""
    faces = np.asarray(faces)
    res = np.zeros(len(faces))
    se = np.zeros(len(faces))
    emitters = [e for e in scene.emitters()
                if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaDirection)
                or mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition)]
    if not emitters:
        return res, se
    lo, hi = band
    rng = np.random.default_rng([int(seed), 1])
    for i, f in enumerate(faces):
        p0, p1, p2 = V[f[0]], V[f[1]], V[f[2]]
        n = np.cross(p1 - p0, p2 - p0)
        n /= np.linalg.norm(n)
        u = rng.random((samples_per_tri, 2))
        flip = u.sum(1) > 1
        u[flip] = 1 - u[flip]
        pts = p0 + u[:, :1] * (p1 - p0) + u[:, 1:] * (p2 - p0)
        lam = lo + (hi - lo) * rng.random((4, samples_per_tri))
        per_sample = np.zeros(samples_per_tri)
        for e in emitters:
            it = dr.zeros(mi.Interaction3f, samples_per_tri)
            it.p = mi.Point3f(*[mi.Float(pts[:, k].astype(np.float32)) for k in range(3)])
            it.wavelengths = mi.Spectrum(*[mi.Float(lam[k].astype(np.float32)) for k in range(4)])
            ds, w = e.sample_direction(it, mi.Point2f(0.5, 0.5))
            cos = ds.d.x * float(n[0]) + ds.d.y * float(n[1]) + ds.d.z * float(n[2])
            # (a point-like light: the shadow ray stops at it; a sun's distance is infinite)
            ray = mi.Ray3f(it.p + mi.Vector3f(*[float(c) * 1e-4 for c in n]), ds.d,
                           dr.minimum(ds.dist * (1.0 - 1e-4), dr.largest(mi.Float)))
            vis = ~scene.ray_test(ray)
            val = (w[0] + w[1] + w[2] + w[3]) * 0.25
            val = dr.select(vis & (cos > 0), val * cos, 0.0)
            per_sample += np.asarray(val, dtype=np.float64) * (hi - lo)
        res[i] = per_sample.mean()
        se[i] = per_sample.std(ddof=1) / math.sqrt(samples_per_tri)
    return res, se


def as_meshes(scene_dict: dict) -> dict:
    """A copy of a scene dict with its mesh shapes loaded as in-memory meshes (same ids).

    ``rectangle``, ``cube``, ``obj`` and ``ply`` shapes without an emitter become ``mi.Mesh``
    objects with their world-space vertices [m] and their BSDF (``ref`` entries resolved to the dict's
    BSDFs), which :func:`path_reference` can cut triangles out of. Shapes with an area emitter
    and everything else are kept as they are.

    Parameters
    ----------
    scene_dict : dict
        A Mitsuba scene dict (not modified), e.g. ``mi.cornell_box()``.

    Returns
    -------
    dict
        The converted copy (same keys).

    Raises
    ------
    SceneError
        If a BSDF ``ref`` names no entry of the dict.
    """
    loaded = {}

    def resolve(b):
        if isinstance(b, dict) and b.get("type") == "ref":
            rid = b["id"]
            if rid not in loaded:
                if rid not in scene_dict:
                    raise SceneError(f"as_meshes: BSDF reference '{rid}' not found in the dict")
                loaded[rid] = mi.load_dict(scene_dict[rid])
            return loaded[rid]
        return b
    out = {}
    for k, v in scene_dict.items():
        if isinstance(v, dict) and v.get("type") in ("rectangle", "cube", "obj", "ply") \
                and "emitter" not in v:
            sh = mi.load_dict({kk: vv for kk, vv in v.items() if kk not in ("bsdf", "id")})
            V = np.asarray(sh.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
            F = np.asarray(sh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
            out[k] = make_mesh(v.get("id", k), V, F, bsdf=resolve(v.get("bsdf",
                                                                         {"type": "diffuse"})))
        else:
            out[k] = v
    return out


def plant_mesh(kind: int = 0):
    """Vertices [m] and faces of a small plant: 4 + ``kind`` leaf quads (8-14 triangles).

    The leaves spiral up a 5-20 cm stem, one leaf every 3 cm from 5 cm up, each about 6 cm
    long; the stem itself is not part of the mesh (see :func:`plant_scene`).

    Parameters
    ----------
    kind : int, optional
        Plant kind; it has ``4 + kind`` leaves; default 0.

    Returns
    -------
    vertices : numpy.ndarray
        (4 (4 + kind), 3) positions [m], stem on the y axis.
    faces : numpy.ndarray
        (2 (4 + kind), 3) vertex indices (int64).
    """
    verts, faces = [], []
    n = 4 + int(kind)
    for j in range(n):
        a = 2 * math.pi * j / n
        h = 0.05 + 0.03 * j
        c, s = math.cos(a), math.sin(a)
        b = len(verts)
        verts += [[0.0, h, 0.0], [0.06 * c, h + 0.02, 0.06 * s],
                  [0.05 * c - 0.02 * s, h + 0.04, 0.05 * s + 0.02 * c],
                  [-0.02 * s, h + 0.02, 0.02 * c]]
        faces += [[b, b + 1, b + 2], [b, b + 2, b + 3]]
    return np.array(verts, dtype=float), np.array(faces, dtype=np.int64)


def plant_scene(n_plants: int = 1000, kinds: int = 3, instanced: bool = True, size: float = 4.0,
                leaf_albedo: float = 0.4, stem_albedo: float = 0.1, ground_albedo: float = 0.2,
                seed: int = 0, sun_elevation: float = 55.0, sky_radiance: float = 0.05) -> dict:
    """Scene dict: ``n_plants`` small plants on a ``size`` x ``size`` m ground, sun + uniform sky.

    Spectrally flat (sun 1 W m-2 nm-1 at azimuth 160 deg, sky ``sky_radiance``
    W m-2 sr-1 nm-1). A plant is two meshes: leaves (:func:`plant_mesh`, albedo ``leaf_albedo``)
    and a 1 cm stem (a box, ``stem_albedo``) standing 2 mm above the ground (no coplanar faces),
    placed at random within 0.47 ``size`` of the centre and turned at random about +y.
    ``instanced=True`` writes ``kinds`` shapegroups (``plant0``, ..., meshes ``leaves{k}`` and
    ``stem{k}``) and one ``instance`` per plant (ids ``p0000``, ...), as exporters and scatterers
    do; ``instanced=False`` writes the same geometry as plain meshes ``p0000_leaves`` and
    ``p0000_stem``. Load with ``optimize=False``.

    Parameters
    ----------
    n_plants : int, optional
        Number of plants; default 1000.
    kinds : int, optional
        Number of plant kinds (plant i is of kind ``i % kinds``); default 3.
    instanced : bool, optional
        Shapegroups and instances (True, default) or plain meshes.
    size : float, optional
        Side of the square ground [m]; default 4.
    leaf_albedo, stem_albedo, ground_albedo : float, optional
        Diffuse reflectances [-]; defaults 0.4, 0.1, 0.2.
    seed : int, optional
        Seed of the plant positions and rotations; default 0.
    sun_elevation : float, optional
        Solar elevation [degrees]; default 55.
    sky_radiance : float, optional
        Uniform sky radiance [W m-2 sr-1 nm-1]; <= 0: no sky; default 0.05.

    Returns
    -------
    dict
        The scene dict for ``mi.load_dict(d, optimize=False)``.
    """
    rng = np.random.default_rng(seed)
    gv, gf = grid_mesh(20, 20, x=(-size / 2, size / 2), z=(-size / 2, size / 2))
    d = {"type": "scene", "ground": make_mesh("ground", gv, gf, ground_albedo)}
    plants = [plant_mesh(k) for k in range(kinds)]
    stems = [box_mesh((-0.005, 0.002, -0.005), (0.005, pv[:, 1].max(), 0.005))
             for pv, _ in plants]
    if instanced:
        for k, (pv, pf) in enumerate(plants):
            d[f"plant{k}"] = {"type": "shapegroup",
                              f"leaves{k}": make_mesh(f"leaves{k}", pv, pf, leaf_albedo),
                              f"stem{k}": make_mesh(f"stem{k}", *stems[k], stem_albedo)}
    half = 0.47 * size
    xz = rng.uniform(-half, half, (n_plants, 2))
    rot = rng.uniform(0.0, 360.0, n_plants)
    for i in range(n_plants):
        T = mi.ScalarTransform4f().translate([float(xz[i, 0]), 0.0, float(xz[i, 1])]) \
            .rotate([0, 1, 0], float(rot[i]))
        if instanced:
            d[f"p{i:04d}"] = {"type": "instance", "id": f"p{i:04d}",
                              "shapegroup": {"type": "ref", "id": f"plant{i % kinds}"},
                              "to_world": T}
        else:
            M = np.array(T.matrix, dtype=float).reshape(4, 4)
            for part, (pv, pf), a in (("leaves", plants[i % kinds], leaf_albedo),
                                      ("stem", stems[i % kinds], stem_albedo)):
                name = f"p{i:04d}_{part}"
                d[name] = make_mesh(name, pv @ M[:3, :3].T + M[:3, 3], pf, a)
    sun = sun_vector(sun_elevation, 160.0)
    d["sun"] = {"type": "directional", "id": "sun", "direction": (-sun).tolist(),
                "irradiance": {"type": "uniform", "value": 1.0}}
    if sky_radiance > 0:
        d["sky"] = {"type": "constant", "id": "sky",
                    "radiance": {"type": "uniform", "value": float(sky_radiance)}}
    return d
