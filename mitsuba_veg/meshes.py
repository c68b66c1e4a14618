"""In-memory Mitsuba meshes from NumPy arrays (one helper for the light scenes and the render)."""
from __future__ import annotations

import mitsuba as mi
import numpy as np


def make_mesh(name: str, vertices, faces, bsdf=None, uv=None, normals=None,
              attributes: dict | None = None) -> mi.Mesh:
    """An in-memory Mitsuba mesh (float32 vertices, uint32 faces) with optional UVs, vertex
    normals, a BSDF (dict or object) and per-vertex float attributes (``vertex_<name>``)."""
    v = np.ascontiguousarray(np.asarray(vertices, np.float32).reshape(-1, 3))
    f = np.ascontiguousarray(np.asarray(faces, np.uint32).reshape(-1, 3))
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = bsdf if isinstance(bsdf, mi.BSDF) else mi.load_dict(bsdf)
    m = mi.Mesh(name, len(v), len(f), props, has_vertex_normals=normals is not None,
                has_vertex_texcoords=uv is not None)
    p = mi.traverse(m)
    p["vertex_positions"] = mi.Float(v.ravel())
    p["faces"] = mi.UInt32(f.ravel())
    if uv is not None:
        p["vertex_texcoords"] = mi.Float(np.asarray(uv, np.float32).ravel())
    if normals is not None:
        p["vertex_normals"] = mi.Float(np.asarray(normals, np.float32).ravel())
    p.update()
    for k, a in (attributes or {}).items():
        m.add_attribute(k, 1, mi.Float(np.asarray(a, np.float32).ravel()))
    return m
