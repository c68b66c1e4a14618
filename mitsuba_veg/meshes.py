"""Triangle meshes: their geometry (areas, unit normals, centroids) and in-memory Mitsuba meshes
from NumPy arrays (one helper each for the light scenes, the terrain, the trees and the render)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .parallel import map_on_cores


__all__ = ["make_mesh", "triangle_geometry"]

def make_mesh(name: str, vertices, faces, bsdf=None, uv=None, normals=None,
              attributes: dict | None = None, *, albedo: float | None = None) -> mi.Mesh:
    """An in-memory Mitsuba mesh from NumPy arrays, its id set (the one mesh helper of the
    package: light scenes, terrain, trees, sensors and the render).

    Parameters
    ----------
    name : str
        The shape id.
    vertices : array_like or mi.Float
        (n, 3) positions [m] (stored as float32), or the flat (3n,) positions already on the
        device (taken as they are: no host copy of a large mesh).
    faces : array_like or mi.UInt32
        (m, 3) vertex indices (stored as uint32), or the flat (3m,) indices on the device.
    bsdf : dict, mitsuba.BSDF or float, optional
        Its material; a number is the reflectance [-] of a (one-sided) ``diffuse`` BSDF with a
        spectrally flat reflectance. Default None: Mitsuba's default BSDF.
    uv : array_like, optional
        (n, 2) texture coordinates.
    normals : array_like, optional
        (n, 3) vertex normals.
    attributes : dict, optional
        Per-vertex float attributes (``vertex_<name>``: (n,) values).
    albedo : float, optional
        Same as a number given as ``bsdf`` (overrides it).

    Returns
    -------
    mitsuba.Mesh
        The mesh, with the given id, BSDF, texture coordinates, normals and attributes.
    """
    if isinstance(vertices, mi.Float):
        nv, v_flat = dr.width(vertices) // 3, vertices
    else:
        v = np.ascontiguousarray(np.asarray(vertices, np.float32).reshape(-1, 3))
        nv, v_flat = len(v), None
    if isinstance(faces, mi.UInt32):
        nf, f_flat = dr.width(faces) // 3, faces
    else:
        f = np.ascontiguousarray(np.asarray(faces, np.uint32).reshape(-1, 3))
        nf, f_flat = len(f), None
    props = mi.Properties()
    if albedo is not None:
        bsdf = albedo
    if isinstance(bsdf, (int, float, np.floating, np.integer)) and not isinstance(bsdf, bool):
        bsdf = {"type": "diffuse", "reflectance": {"type": "uniform", "value": float(bsdf)}}
    if bsdf is not None:
        props["bsdf"] = bsdf if isinstance(bsdf, mi.BSDF) else mi.load_dict(bsdf)
    m = mi.Mesh(name, nv, nf, props, has_vertex_normals=normals is not None,
                has_vertex_texcoords=uv is not None)
    m.set_id(name)   # (otherwise only loading a scene dict gives it its key as id)
    p = mi.traverse(m)
    p["vertex_positions"] = mi.Float(v.ravel()) if v_flat is None else v_flat
    p["faces"] = mi.UInt32(f.ravel()) if f_flat is None else f_flat
    if uv is not None:
        p["vertex_texcoords"] = mi.Float(np.asarray(uv, np.float32).ravel())
    if normals is not None:
        p["vertex_normals"] = mi.Float(np.asarray(normals, np.float32).ravel())
    p.update()
    for k, a in (attributes or {}).items():
        m.add_attribute(k, 1, mi.Float(np.asarray(a, np.float32).ravel()))
    return m


#: triangles per block of :func:`triangle_geometry`
_BLOCK = 1 << 16
#: at most this many threads of :func:`triangle_geometry` on meshes of several blocks (never
#: more than the machine's cores)
_THREADS = 4


def triangle_geometry(vertices, faces, out=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Areas, unit normals and centroids of a triangle mesh.

    Parameters
    ----------
    vertices : array_like
        (n, 3) vertex positions [m].
    faces : array_like or None
        (m, 3) vertex indices per triangle (counter-clockwise seen from the front); None: a
        triangle soup, triangle i being vertices 3i, 3i + 1, 3i + 2 (no index array read).
    out : tuple of numpy.ndarray, optional
        (areas (m,), normals (m, 3), centroids (m, 3)) float64 arrays to fill (e.g. slices of
        a scene's element tables: no array of its own per mesh).

    Returns
    -------
    areas : numpy.ndarray
        (m,) triangle areas [m2].
    normals : numpy.ndarray
        (m, 3) unit normals of the front sides (zero for degenerate triangles).
    centroids : numpy.ndarray
        (m, 3) centroids [m].
    """
    v = np.asarray(vertices).reshape(-1, 3)
    if v.dtype not in (np.float32, np.float64):
        v = v.astype(np.float64)
    if faces is None:
        if len(v) % 3:
            raise ValueError(f"a triangle soup has 3 vertices per triangle, not {len(v)}")
        f, m = None, len(v) // 3
    else:
        f = np.asarray(faces).reshape(-1, 3)
        m = len(f)
    if out is None:
        areas, normals, centroids = np.empty(m), np.empty((m, 3)), np.empty((m, 3))
    else:
        areas, normals, centroids = out
        if areas.shape != (m,) or normals.shape != (m, 3) or centroids.shape != (m, 3):
            raise ValueError(f"triangle_geometry: out arrays of {m} triangles expected")
    # component by component: np.cross and np.linalg.norm copy strided (m, 3) arrays; the same
    # operations in the same order as (p1 - p0) x (p2 - p0), |c| and (p0 + p1 + p2) / 3, in
    # float64 (float32 vertices convert exactly), so the same bits. In blocks of triangles
    # whose corners are gathered and converted block by block: a hectare's 21.6 M triangles
    # made each whole-mesh temporary a new mapping of up to 1 GB, filled page by page (21 s);
    # the results do not depend on the block size
    def block(s0):
        s1 = min(s0 + _BLOCK, m)
        if f is None:
            vb = v[3 * s0:3 * s1].astype(np.float64, copy=False).reshape(-1, 3, 3)
            p0, p1, p2 = vb[:, 0], vb[:, 1], vb[:, 2]
        else:
            fb = f[s0:s1]
            p0 = v[fb[:, 0]].astype(np.float64, copy=False)
            p1 = v[fb[:, 1]].astype(np.float64, copy=False)
            p2 = v[fb[:, 2]].astype(np.float64, copy=False)
        ax, ay, az = p0[:, 0], p0[:, 1], p0[:, 2]
        bx, by, bz = p1[:, 0], p1[:, 1], p1[:, 2]
        qx, qy, qz = p2[:, 0], p2[:, 1], p2[:, 2]
        ux, uy, uz = bx - ax, by - ay, bz - az
        wx, wy, wz = qx - ax, qy - ay, qz - az
        cx = uy * wz - uz * wy
        cy = uz * wx - ux * wz
        cz = ux * wy - uy * wx
        norm = np.sqrt(cx * cx + cy * cy + cz * cz)
        nb = normals[s0:s1]
        with np.errstate(invalid="ignore", divide="ignore"):
            nb[:, 0], nb[:, 1], nb[:, 2] = cx / norm, cy / norm, cz / norm
        nb[norm <= 0.0] = 0.0
        cb = centroids[s0:s1]
        cb[:, 0] = (ax + bx + qx) / 3.0
        cb[:, 1] = (ay + by + qy) / 3.0
        cb[:, 2] = (az + bz + qz) / 3.0
        areas[s0:s1] = 0.5 * norm

    # the blocks are independent and NumPy lets go of the GIL inside each operation: large
    # meshes use the machine's cores (the same values in any order)
    map_on_cores(block, range(0, m, _BLOCK), max_workers=_THREADS)
    return areas, normals, centroids
