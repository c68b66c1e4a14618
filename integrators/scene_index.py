"""The scene index of the photon pass: every shape's triangles (and every instance's) as one
flat range of *elements*, with areas, normals and centroids in world space and the device
lookup tables that turn a hit into its element and BSDF (module docstring of
:mod:`mitsuba_veg.integrators.photon_irradiance`)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import SceneError
from mitsuba_veg.meshes import triangle_geometry

__all__ = ["scene_index", "forget_scene_index", "registry_id", "emitter_name", "MeshGeometry",
           "SceneIndex"]

_INDEX_CACHE: dict = {}


def scene_index(scene: mi.Scene, reference: dict | None = None) -> "SceneIndex":
    """The :class:`SceneIndex` of a scene, built once for the last scene seen.

    The cache holds the scene itself: keyed by ``id()`` alone, a new scene allocated where a
    freed one was would get the old scene's index.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    reference : dict, optional
        ``{mesh id: (vertices (n, 3), faces (m, 3) or None)}``: the geometry whose areas,
        normals and centroids the index gives those meshes instead of their vertices now (a
        canopy built with its blades taken out: its elements keep their full blades' areas and
        normals); faces None: a triangle soup (triangle i is vertices 3i..3i+2), which the
        mesh's faces must then be.
        Given, the index is built anew.

    Returns
    -------
    SceneIndex
        The scene's element index.
    """
    if reference is not None or _INDEX_CACHE.get("scene") is not scene:
        _INDEX_CACHE.clear()
        _INDEX_CACHE.update(scene=scene, index=SceneIndex.build(scene, reference))
    return _INDEX_CACHE["index"]


def forget_scene_index() -> None:
    """Let go of the cached scene and its index (:func:`scene_index`), so that a scene being
    replaced is freed before its successor is built (a large stand's rebuild holds one, not
    two)."""
    _INDEX_CACHE.clear()


# --------------------------------------------------------------------------------------------
# Scene analysis: one flat element index over all shapes (triangles of meshes, 1 per other shape)
# --------------------------------------------------------------------------------------------
def registry_id(obj) -> int:
    """JIT registry id of a Mitsuba shape, BSDF or emitter (what ``dr.reinterpret_array`` of a pointer
    array gives; 0 is the null pointer): the key of the photon pass's per-element tables.

    Parameters
    ----------
    obj : mi.Shape, mi.BSDF or mi.Emitter
        The object.

    Returns
    -------
    int
        Its registry id.
    """
    ptr = mi.ShapePtr(obj) if isinstance(obj, mi.Shape) else \
        mi.EmitterPtr(obj) if isinstance(obj, mi.Emitter) else mi.BSDFPtr(obj)
    return int(np.asarray(dr.reinterpret_array(mi.UInt32, ptr))[0])


_reg_id = registry_id


def emitter_name(emitter, index: int) -> str:
    """The name of a scene's emitter in results: its id, or (an emitter without one, as
    Mitsuba's XML writer and hand-written XML leave them) its Mitsuba class and its place in
    ``scene.emitters()``, e.g. ``"DirectionalEmitter_0"``.

    Parameters
    ----------
    emitter : mi.Emitter
        The emitter.
    index : int
        Its position in ``scene.emitters()``.

    Returns
    -------
    str
        The name.
    """
    return emitter.id() or f"{emitter.class_name()}_{int(index)}"


class _Children(mi.TraversalCallback):
    """Collects the Mitsuba objects an object lists in its ``traverse()`` (name -> object)."""

    def __init__(self):
        super().__init__()
        self.objects: dict[str, object] = {}

    def put(self, name, value, flags, cpptype=None):
        """Called by ``traverse()`` for each parameter or child object; keeps the objects."""
        if isinstance(value, mi.Object):
            self.objects[name] = value


def _children(obj) -> dict:
    cb = _Children()
    obj.traverse(cb)
    return cb.objects


def _spatially_varying(obj, depth=0) -> bool:
    """True when a BSDF (or anything below it) holds a texture that varies over the surface
    (bitmap, mesh attribute, checkerboard ...): such BSDFs need Mitsuba's full surface
    interaction (uv, shading frame) at every hit."""
    if depth > 8:
        return False
    if isinstance(obj, mi.Texture) and obj.is_spatially_varying():
        return True
    return any(_spatially_varying(c, depth + 1) for c in _children(obj).values())


def _mesh_arrays(sh, to_world=None):
    """Vertices (n, 3) [m] and faces (m, 3) of a mesh, vertices moved by a 4x4 ``to_world``."""
    v = np.asarray(sh.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
    f = np.asarray(sh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
    if to_world is not None:
        v = v @ to_world[:3, :3].T + to_world[:3, 3]
    return v, f


def _matrix(transform) -> np.ndarray:
    return np.asarray(transform.matrix, dtype=np.float64).reshape(4, 4)


def _box_corners(bmin, bmax):
    return np.array([[x, y, z] for x in (bmin[0], bmax[0]) for y in (bmin[1], bmax[1])
                     for z in (bmin[2], bmax[2])], dtype=np.float64)


class MeshGeometry(Mapping):
    """Shape id -> (vertices (n, 3) [m] float64, faces (m, 3) int64) of the scene's plain
    meshes, read from the meshes' own buffers when first asked for (and kept).

    A large scene's leaves and wood are not copied to the host unless someone reads them
    (a 1-ha stand's would be 2 GB); the terrain's are read by the site at once.

    Parameters
    ----------
    shapes : dict
        Shape id -> Mitsuba mesh.
    """

    def __init__(self, shapes: dict):
        self._shapes = dict(shapes)
        self._arrays: dict = {}

    def __getitem__(self, sid):
        if sid not in self._arrays:
            self._arrays[sid] = _mesh_arrays(self._shapes[sid])
        return self._arrays[sid]

    def __contains__(self, sid) -> bool:
        return sid in self._shapes

    def __iter__(self):
        return iter(self._shapes)

    def __len__(self) -> int:
        return len(self._shapes)


def _check_reference_faces(sid: str, sh, v, f) -> None:
    """Refuse a reference geometry whose triangles are not the mesh's: ``f`` (its faces) equal
    to the mesh's, or None (a triangle soup: triangle i is vertices 3i..3i+2), checked on the
    device without a host copy of the mesh's faces."""
    fb = sh.faces_buffer()
    if f is None:
        ok = dr.width(fb) == len(v) and (len(v) == 0 or bool(
            dr.all(fb == dr.arange(mi.UInt32, dr.width(fb)), axis=None)))
    else:
        f_mesh = np.asarray(fb, dtype=np.int64).reshape(-1, 3)
        ok = np.shape(f) == f_mesh.shape and np.array_equal(f, f_mesh)
    if not ok:
        raise SceneError(f"mesh '{sid}': the reference geometry's faces are not the mesh's")


@dataclass
class SceneIndex:
    """Maps Mitsuba shapes to a flat range of *elements* (one per triangle, one per non-mesh).

    Elements are laid out in ``scene.shapes()`` order. A plain mesh gives one element per
    triangle; an analytic shape (``sphere``, ``disk``, ``cylinder``, ...: Mitsuba 3.9 loads
    ``rectangle`` and ``cube`` as meshes) gives one element, listed in
    :attr:`single_element`; an ``instance`` gives one element per triangle of every mesh of its
    ``shapegroup`` (in the group's order), with areas, normals and centroids in world space.
    Results are looked up by shape id, by instance id (all of the instance's triangles) or by
    ``"instance_id/shape_id"`` (one mesh of the instance's group).

    In the photon kernel the element of a hit is
    ``lookup[shape] + lookup[instance] + prim_index``: ``lookup`` maps the registry id of a
    top-level shape to its first element, of a shape inside a group to its first element within
    the group, of an instance to its first element, and of the null pointer (no instance) to 0.
    """

    shape_ids: list[str]
    offsets: np.ndarray          # first element of each shape (in scene.shapes() order)
    counts: np.ndarray           # elements per shape
    areas: np.ndarray            # area of every element [m2]
    normals: np.ndarray          # geometric unit normal of every triangle (0 for non-meshes)
    centroids: np.ndarray        # centroid of every triangle [m]
    lookup: mi.UInt32            # registry id of a shape/instance -> its (local) offset
    aim_bbox: mi.ScalarBoundingBox3f  # geometry that photons are aimed at
    n_elements: int = 0
    geometry: Mapping = field(default_factory=dict)  # shape id -> (vertices, faces) of plain
    # meshes (:class:`MeshGeometry`)
    #: shapes counted as a single element: {shape id: Mitsuba class name}
    single_element: dict = field(default_factory=dict)
    #: instances: {instance id: shapegroup id}
    instances: dict = field(default_factory=dict)
    #: "instance_id/shape_id" -> slice of that mesh's triangles in the instance
    sub_slices: dict = field(default_factory=dict)
    #: registry id of a shape (top-level or inside a group) -> registry id of its BSDF
    bsdf_lookup: mi.UInt32 | None = None
    #: analytic (non-mesh) top-level shapes: (registry id, shape) - their normal is computed by
    #: the shape itself
    analytic: list = field(default_factory=list)
    #: True when some BSDF is spatially varying, or (in scenes without instances) a mesh has
    #: vertex normals: hits then use Mitsuba's full surface interaction
    needs_full_interaction: bool = False
    #: instanced hits where the backend gives a null shape (Embree):
    #: ``group_base[instance registry id] + shape_index`` indexes ``group_local`` (first
    #: element of that mesh within the group) and ``group_bsdf``; where it gives the mesh as
    #: the shape (OptiX, shape_index 0), ``lookup``/``bsdf_lookup`` of the mesh hold the same
    group_base: mi.UInt32 | None = None
    group_local: mi.UInt32 | None = None
    group_bsdf: mi.UInt32 | None = None
    #: the distinct BSDFs of the shapes that photons can hit: [(registry id, BSDF)]
    bsdf_objects: list = field(default_factory=list)
    #: scenes without instances: registry id of a top-level shape -> 1 where its hits need
    #: the full interaction (vertex normals, spatially varying BSDF); None: none or (with
    #: instances) every hit when :attr:`needs_full_interaction`
    full_lookup: mi.UInt32 | None = None
    #: :attr:`normals` on the device for the kernel (flat, 3 per element)
    kernel_normals: mi.Float | None = None
    #: scenes with instances whose meshes (in groups or top-level) have vertex normals: the
    #: shading normals of their hits from tables instead of Mitsuba's full interaction (a
    #: virtual call over every instance). ``vn_table``: the 3 vertex normals of each such
    #: triangle (9 floats; a group's triangles in object space, a top-level mesh's in world
    #: space); ``vn_base[registry id]`` (of the instance or the top-level mesh): its first row
    #: (``0xFFFFFFFF``: none); ``vn_matrix[9 registry id ..]``: the normal transform (inverse
    #: transpose of an instance's ``to_world``; identity for a top-level mesh)
    vn_table: mi.Float | None = None
    vn_base: mi.UInt32 | None = None
    vn_matrix: mi.Float | None = None

    def __post_init__(self):
        if self.kernel_normals is None:
            self.kernel_normals = mi.Float(np.ascontiguousarray(self.normals, np.float32)
                                           .ravel())

    @staticmethod
    def build(scene: mi.Scene, reference: dict | None = None) -> "SceneIndex":
        """Index the shapes of ``scene``; refuses (``SceneError``) what it cannot resolve.

        Parameters
        ----------
        scene : mi.Scene
            The scene (load with ``optimize=False`` to keep every shape and its id).
        reference : dict, optional
            ``{top-level mesh id: (vertices, faces or None)}`` whose areas, normals and
            centroids the index gives those meshes instead of their vertices now
            (:func:`scene_index`).

        Returns
        -------
        SceneIndex
            Element layout, areas [m2], normals, centroids [m] and the kernel's lookup tables.
        """
        shapes = scene.shapes()
        if len(shapes) == 0:
            raise SceneError("the scene has no shapes: photons would have nothing to hit")
        groups = {name: obj for name, obj in _children(scene).items()
                  if isinstance(obj, mi.Shape) and obj.class_name().startswith("ShapeGroup")}
        group_shapes = {}
        for gname, g in groups.items():
            inner = [(n, s) for n, s in _children(g).items() if isinstance(s, mi.Shape)]
            group_shapes[gname] = inner
        # per shape: its (areas, normals, centroids), or (vertices, faces or None, checked)
        # of a plain mesh, computed after the loop into the tables' own slices
        counts, geo, deferred, ids, geometry = [], [], [], [], {}
        single, instances, sub_local, analytic = {}, {}, {}, []
        reg_offset: dict[int, int] = {}   # registry id -> offset (global or within a group)
        bsdf_of: dict[int, int] = {}
        bsdf_objs: dict[int, object] = {}
        needs_full = False
        smooth = False  # a plain mesh has vertex normals (shading normals)
        bbox = mi.ScalarBoundingBox3f()
        offset = 0

        full_shapes: set[int] = set()   # top-level shapes whose hits need the full interaction

        def note_bsdf(sh) -> bool:
            nonlocal needs_full
            b = sh.bsdf()
            varying = False
            if b is not None:
                bsdf_of[_reg_id(sh)] = _reg_id(b)
                bsdf_objs.setdefault(_reg_id(b), b)
                varying = _spatially_varying(b)
                needs_full = needs_full or varying
            return varying

        group_layout = {}  # group name -> (local offsets, triangle data in local space)
        g_base, g_local, g_bsdf, inst_base = {}, [], [], {}
        # vertex normals per triangle, (k, 3, 3) or None, of each group's meshes and of the
        # top-level meshes (for the shading frame of hits in scenes with instances)
        vn_group: dict[str, list] = {}
        vn_top: dict[int, np.ndarray] = {}
        inst_matrix: dict[int, np.ndarray] = {}

        def tri_normals(sh, f):
            if not (sh.is_mesh() and sh.has_vertex_normals()):
                return None
            vn = np.asarray(sh.vertex_normals_buffer(), dtype=np.float64).reshape(-1, 3)
            return vn.reshape(-1, 3, 3) if f is None else vn[f]

        def layout(gname):
            if gname in group_layout:
                return group_layout[gname]
            local, items, k = {}, [], 0
            # a hit inside an instance gives the mesh's position in its group
            # (PreliminaryIntersection.shape_index; its shape is null), in traversal order
            g_base[gname] = len(g_local)
            for n, s in group_shapes[gname]:
                if not (s.is_mesh() and s.face_count() > 0):
                    raise SceneError(
                        f"shape '{s.id() or n}' ({s.class_name()}) inside shapegroup '{gname}' "
                        "is not a triangle mesh: the photon pass resolves instanced meshes per "
                        "triangle but not instanced analytic shapes. Fix: convert it to a mesh "
                        "(e.g. an .obj/.ply), or place it outside the shapegroup")
                v, f = _mesh_arrays(s)
                local[n] = (k, len(f))
                reg_offset[_reg_id(s)] = k
                vn_group.setdefault(gname, []).append((len(f), tri_normals(s, f)))
                note_bsdf(s)
                g_local.append(k)
                g_bsdf.append(bsdf_of.get(_reg_id(s), 0))
                items.append((v, f))
                k += len(f)
            group_layout[gname] = (local, items, k)
            return group_layout[gname]

        SceneIndex._check_ids(shapes)
        for sh in shapes:
            sid = sh.id()
            ids.append(sid)
            if sh.class_name() == "Instance":
                gname = SceneIndex._group_of(sh, groups)
                local, items, k = layout(gname)
                T = _matrix(mi.traverse(sh)["to_world"])
                a_l, n_l, c_l = [], [], []
                for v, f in items:
                    a, nrm, c = triangle_geometry(v @ T[:3, :3].T + T[:3, 3], f)
                    a_l.append(a), n_l.append(nrm), c_l.append(c)
                counts.append(k)
                geo.append((np.concatenate(a_l), np.concatenate(n_l), np.concatenate(c_l)))
                deferred.append(False)
                instances[sid] = gname
                for n, (o, c) in local.items():
                    sub_local[f"{sid}/{n}"] = (offset + o, c)
                reg_offset[_reg_id(sh)] = offset
                inst_base[_reg_id(sh)] = g_base[gname]
                inst_matrix[_reg_id(sh)] = T
            elif sh.is_mesh() and sh.face_count() > 0:
                if reference and sid in reference:
                    # the reference's vertices, not the mesh's (not read: a bare hectare's
                    # 13 M blades taken out are NaN)
                    v, f = reference[sid]
                    _check_reference_faces(sid, sh, v, f)
                else:
                    # float32 as stored (triangle_geometry converts block by block: the same
                    # values, without a float64 copy of every vertex)
                    v = np.asarray(sh.vertex_positions_buffer()).reshape(-1, 3)
                    f = np.asarray(sh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
                counts.append(sh.face_count())
                geo.append((v, f, not (reference and sid in reference)))
                deferred.append(True)
                geometry[sid] = sh
                reg_offset[_reg_id(sh)] = offset
                tn = tri_normals(sh, f)
                if tn is not None:
                    vn_top[_reg_id(sh)] = tn
                if note_bsdf(sh) or sh.has_vertex_normals():
                    full_shapes.add(_reg_id(sh))
                smooth = smooth or sh.has_vertex_normals()
            else:
                counts.append(1)
                b = sh.bbox()
                geo.append((np.array([float(dr.ravel(sh.surface_area())[0])]), np.zeros((1, 3)),
                            np.array([[(b.min[i] + b.max[i]) / 2 for i in range(3)]])))
                deferred.append(False)
                single[sid] = sh.class_name()
                reg_offset[_reg_id(sh)] = offset
                analytic.append((_reg_id(sh), sh))
                if note_bsdf(sh):
                    full_shapes.add(_reg_id(sh))
            offset += counts[-1]
            # aim at geometry that can receive light: not at emitter shapes (e.g. a distant
            # area "sun") nor at sensor shapes
            if not (sh.is_emitter() or sh.is_sensor()):
                if reference and sid in reference:
                    # the reference geometry's box (collapsed blades grow out later)
                    rv = np.asarray(reference[sid][0], np.float32).reshape(-1, 3)
                    # column by column: a reduction over axis 0 of an (n, 3) array runs
                    # three-wide inner loops (2.9 s for a hectare's 40 M corners, 0.2 s so)
                    lo = [float(rv[:, k].min()) for k in range(3)]
                    hi = [float(rv[:, k].max()) for k in range(3)]
                    bbox.expand(mi.ScalarBoundingBox3f(mi.ScalarPoint3f(*lo),
                                                       mi.ScalarPoint3f(*hi)))
                else:
                    bbox.expand(sh.bbox())
        if not bbox.valid():
            bbox = scene.bbox()
        # shading normals need Mitsuba's full interaction too, except with instances, where
        # it costs a virtual call over every instance (the vertex-normal tables below serve
        # instanced scenes)
        needs_full = needs_full or (smooth and not instances)
        counts = np.asarray(counts, dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        # the element tables filled in place, mesh by mesh (no per-mesh arrays concatenated:
        # a hectare's 21.6 M triangles made 1.2 GB of them, and as much again to join)
        n_el = int(counts.sum())
        areas, normals, cents = np.empty(n_el), np.empty((n_el, 3)), np.empty((n_el, 3))
        for k, (o, c) in enumerate(zip(offsets, counts)):
            part = (areas[o:o + c], normals[o:o + c], cents[o:o + c])
            if deferred[k]:
                v, f, own = geo[k]
                triangle_geometry(v, f, out=part)
                if own and np.isnan(part[0]).any():
                    raise SceneError(
                        f"mesh '{ids[k]}' has triangles with NaN corners (blades taken out of "
                        "a world's leaf mesh): their areas and normals are unknown. Fix: index "
                        "the scene with the mesh's full geometry as the reference "
                        "(scene_index(scene, reference))")
            else:
                for dst, src in zip(part, geo[k]):
                    dst[...] = src
        geo = None
        n_reg = max(list(reg_offset) + list(bsdf_of) + [0]) + 1
        lookup = np.zeros(n_reg, dtype=np.uint32)
        for r, o in reg_offset.items():
            lookup[r] = o
        blook = np.zeros(n_reg, dtype=np.uint32)
        for r, b in bsdf_of.items():
            blook[r] = b
        gbase = np.zeros(n_reg, dtype=np.uint32)
        for r, b in inst_base.items():
            gbase[r] = b
        # the order of a shapegroup's meshes in its acceleration structure (what a hit's
        # shape_index counts) is the backend's: learned by one probe ray per mesh
        first_inst = {}
        for sh in shapes:
            if sh.class_name() == "Instance":
                first_inst.setdefault(instances[sh.id()], sh)
        for gname, base in g_base.items():
            local, items, _ = group_layout[gname]
            perm = SceneIndex._probe_group_order(scene, first_inst.get(gname), items)
            if perm is not None:
                k = len(items)
                g_local[base:base + k] = [g_local[base + j] for j in perm]
                g_bsdf[base:base + k] = [g_bsdf[base + j] for j in perm]
        # with instances: shading normals from tables (groups in object space, top-level
        # meshes in world space; a group's meshes keep the traversal order of its elements)
        vn_table = vn_base = vn_matrix = None
        has_vn = any(tn is not None for items in vn_group.values() for _, tn in items) \
            or bool(vn_top)
        if instances and has_vn:
            rows, base_of, nrow = [], {}, 0
            for gname, items in vn_group.items():
                base_of[gname] = nrow
                for cnt, tn in items:
                    rows.append(np.full((cnt, 3, 3), np.nan) if tn is None else tn)
                    nrow += cnt
            vb = np.full(n_reg, 0xFFFFFFFF, dtype=np.uint32)
            vm = np.zeros((n_reg, 9), dtype=np.float32)
            for sh in shapes:
                r = _reg_id(sh)
                if sh.class_name() == "Instance":
                    vb[r] = base_of[instances[sh.id()]]
                    vm[r] = np.linalg.inv(inst_matrix[r][:3, :3]).T.ravel()
                elif r in vn_top:
                    vb[r] = nrow
                    vm[r] = np.eye(3).ravel()
                    rows.append(vn_top[r])
                    nrow += len(vn_top[r])
            vn_table = mi.Float(np.concatenate(rows).astype(np.float32).ravel())
            vn_base, vn_matrix = mi.UInt32(vb), mi.Float(vm.ravel())
        # without instances, only hits on the listed shapes need the full interaction
        full_lookup = None
        if not instances and full_shapes:
            fl = np.zeros(n_reg, dtype=np.uint32)
            fl[sorted(full_shapes)] = 1
            full_lookup = mi.UInt32(fl)
        return SceneIndex(ids, offsets, counts, areas, normals, cents, mi.UInt32(lookup), bbox,
                          n_el,
                          MeshGeometry(geometry), single, instances,
                          {k: slice(o, o + c) for k, (o, c) in sub_local.items()},
                          mi.UInt32(blook), analytic, needs_full, mi.UInt32(gbase),
                          mi.UInt32(np.array(g_local + [0], np.uint32)),
                          mi.UInt32(np.array(g_bsdf + [0], np.uint32)),
                          sorted(bsdf_objs.items(), key=lambda kv: kv[0]), full_lookup,
                          vn_table=vn_table, vn_base=vn_base, vn_matrix=vn_matrix)

    @staticmethod
    def _check_ids(shapes) -> None:
        """Refuse shapes without an id or with one id twice: results are looked up by id, and
        such shapes would share one name (one row, one map file, the last shape's values).
        Mitsuba's XML writer (``mi.parser.write_file``) writes ``name=`` and no ``id=``."""
        seen, bad = {}, []
        for k, sh in enumerate(shapes):
            sid = sh.id()
            if not sid or sid in seen:
                bad.append(f"shape {k} ({sh.class_name()}"
                           + (f", id '{sid}' as shape {seen[sid]}" if sid else ", no id") + ")")
            seen.setdefault(sid, k)
        if bad:
            raise SceneError(
                f"{len(bad)} shape(s) of the scene have no id or an id used before: "
                f"{', '.join(bad[:4])}{' ...' if len(bad) > 4 else ''}; the photon pass names "
                "its results by shape id. Fix: give every <shape> a unique id=\"...\" attribute "
                "(Mitsuba's XML writer writes name= only; in a dict, the keys are the ids)")

    @staticmethod
    def _probe_group_order(scene, inst, items):
        """For a shapegroup shown by instance ``inst`` with meshes ``items`` (traversal order):
        ``perm[shape_index] = traversal position`` as the scene's ray tracer numbers them (a
        short ray at the largest triangle of each mesh, from just in front of it); None when
        every probe agrees with the traversal order or a probe is inconclusive (then the
        traversal order is kept). Embree keeps the traversal order; OptiX gives shape_index 0
        and the mesh itself as the hit's shape (the kernel reads that instead)."""
        if inst is None or len(items) < 2:
            return None
        T = _matrix(mi.traverse(inst)["to_world"])
        o, d = [], []
        for v, f in items:
            w = v @ T[:3, :3].T + T[:3, 3]
            a, nrm, c = triangle_geometry(w, f)
            j = int(np.argmax(a))
            ext = max(float(np.ptp(w, axis=0).max()), 1e-6)
            o.append(c[j] + nrm[j] * 1e-4 * ext)
            d.append(-nrm[j])
        o, d = np.asarray(o, np.float32), np.asarray(d, np.float32)
        ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k]) for k in range(3)]),
                       mi.Vector3f(*[mi.Float(d[:, k]) for k in range(3)]))
        pi = scene.ray_intersect_preliminary(ray, coherent=False)
        ok = np.asarray(pi.is_valid()) & (np.asarray(dr.reinterpret_array(mi.UInt32, pi.instance))
                                          == _reg_id(inst))
        idx = np.asarray(pi.shape_index)
        if not ok.all() or sorted(idx.tolist()) != list(range(len(items))):
            return None
        if np.array_equal(idx, np.arange(len(items))):
            return None
        perm = np.zeros(len(items), np.int64)
        perm[idx] = np.arange(len(items))
        return perm.tolist()

    @staticmethod
    def _group_of(inst, groups) -> str:
        """The shapegroup an instance shows: the one whose box, moved by the instance's
        ``to_world``, is the instance's box (Mitsuba does not expose the link itself)."""
        if not groups:
            raise SceneError(f"instance '{inst.id()}': no shapegroup found in the scene")
        if len(groups) == 1:
            return next(iter(groups))
        T = _matrix(mi.traverse(inst)["to_world"])
        ib = inst.bbox()
        imin, imax = np.array(ib.min, float), np.array(ib.max, float)
        tol = 1e-4 * max(float(np.linalg.norm(imax - imin)), 1e-6)
        found = []
        for name, g in groups.items():
            gb = g.bbox()
            c = _box_corners(np.array(gb.min, float), np.array(gb.max, float))
            w = c @ T[:3, :3].T + T[:3, 3]
            if np.all(np.abs(w.min(0) - imin) <= tol) and np.all(np.abs(w.max(0) - imax) <= tol):
                found.append(name)
        if len(found) != 1:
            raise SceneError(
                f"instance '{inst.id()}': cannot tell which shapegroup it shows "
                f"({'several' if found else 'none'} of {sorted(groups)} match its bounding box). "
                "Fix: give each shapegroup a distinct extent, or write the plants as meshes")
        return found[0]

    def shape_slice(self, shape_id: str) -> slice:
        """Elements of a shape id, an instance id or an ``"instance_id/shape_id"`` key.

        Parameters
        ----------
        shape_id : str
            A shape id, an instance id or an ``"instance_id/shape_id"`` key.

        Returns
        -------
        slice
            The shape's elements in the index (``scene.shapes()`` order).
        """
        if shape_id in self.sub_slices:
            return self.sub_slices[shape_id]
        if shape_id not in self.shape_ids:
            raise SceneError(
                f"no shape with id '{shape_id}' in the scene (shapes: {self.shape_ids[:20]}"
                f"{' ...' if len(self.shape_ids) > 20 else ''}). Mitsuba "
                f">= 3.7 merges meshes with equal BSDFs at load time and drops their ids: load "
                f"the scene with mi.load_dict(..., optimize=False) / mi.load_file(..., "
                f"optimize=False) to keep per-shape results")
        if getattr(self, "_position", None) is None or len(self._position) != len(self.shape_ids):
            self._position = {sid: i for i, sid in enumerate(self.shape_ids)}
        i = self._position[shape_id]
        return slice(int(self.offsets[i]), int(self.offsets[i] + self.counts[i]))
