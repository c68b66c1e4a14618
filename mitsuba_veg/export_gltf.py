"""A world's geometry as glTF binary (.glb) for Blender and other tools, with its colours.

:class:`GltfWorld` collects named meshes from plain arrays (vertices [m], faces) and writes them
with trimesh:

- :meth:`GltfWorld.add_mesh`: any mesh with one colour, per-vertex or per-face colours;
- :meth:`GltfWorld.add_leaves`: leaves coloured by their autumn stage (paper 003) through the
  package's own spectrum -> colour path: the PROSPECT-D reflectance of the stage's pigments
  (:func:`mitsuba_veg.foliage.leaf_spectra`) under D65, CIE 1931 XYZ -> sRGB
  (:func:`mitsuba_veg.foliage.spectra.spectrum_to_srgb`, :mod:`mitsuba_veg.foliage.colour_dr`);
- :meth:`GltfWorld.add_terrain`: ground coloured by a moss cover in [0, 1] per triangle, a
  linear blend of a soil and a moss colour (per vertex: area-weighted mean cover of the
  triangles around it; or exactly per triangle);
- :meth:`GltfWorld.add_instances`: one mesh, many nodes with their own 4 x 4 transforms
  (repeated tree variants: glTF instancing); :func:`add_stand` adds a stand's Weber-Penn
  trees that way (:mod:`mitsuba_veg.trees.instancing`).

Colours: glTF's ``COLOR_0`` is *linear* RGB (multiplied into the material's base colour), so
every colour here is linear sRGB in [0, 1] and is written as normalised 8-bit RGBA (steps of
1/255 in linear light). A leaf's colour is its reflectance's colour (exposure 1: a perfect white
reflector is white), i.e. the albedo a renderer needs; leaves reflect 5-15 % in the visible, so
they are dark. Materials are double-sided (thin leaves) and non-metallic.

Frame: the package's (+y up, +x east, +z south, metres) is glTF's (+y up, right-handed,
metres): coordinates are written as they are.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from .atomic import atomic_write
from .errors import ParameterError
from .foliage.colour_dr import srgb_decode_np
from .foliage.pigments import N_STAGES
from .foliage.spectra import leaf_spectra, spectrum_to_srgb
from .meshes import triangle_geometry
from .terrain import GEOLOGY_COLOURS
from .trees.instancing import tree_transforms

#: soil colour (linear sRGB): the humus texture colour of mitsuba_veg.terrain, decoded
SOIL_RGB = tuple(float(c) for c in srgb_decode_np(np.array(GEOLOGY_COLOURS["humus"]) / 255.0))
#: moss colour (linear sRGB): a mid moss green, 8-bit sRGB (78, 102, 38), chosen by eye
MOSS_RGB = tuple(float(c) for c in srgb_decode_np(np.array([78, 102, 38]) / 255.0))
#: bark colour (linear sRGB): a grey brown, 8-bit sRGB (90, 70, 55)
BARK_RGB = tuple(float(c) for c in srgb_decode_np(np.array([90, 70, 55]) / 255.0))
#: stage grid of the leaf colour table (stages 1..7 in steps of 0.05; colours in between are
#: interpolated linearly)
STAGE_STEP = 0.05


def stage_colours(stages, exposure: float = 1.0) -> np.ndarray:
    """Linear sRGB colour of leaves at Ishikura stages (1 green .. 7 red; paper 003).

    The leaf reflectance (PROSPECT-D of the stage's pigments) under D65 goes through
    :func:`mitsuba_veg.foliage.spectra.spectrum_to_srgb` (encoded sRGB, clipped) and is decoded to
    linear light. Computed on a table of stages 1..7 every :data:`STAGE_STEP` and interpolated
    linearly (a stand has millions of leaves; one spectrum is 2101 values).

    Parameters
    ----------
    stages : array_like
        Stages [-] in [1, 7] (values outside are clipped); NaN is refused.
    exposure : float, optional
        Factor on XYZ before encoding [-]; default 1 (the reflectance's own colour).

    Returns
    -------
    numpy.ndarray
        (..., 3) linear sRGB [-] in [0, 1], the shape of ``stages`` plus 3.

    Raises
    ------
    ParameterError
        For NaN stages or an exposure <= 0.
    """
    s = np.asarray(stages, float)
    if np.isnan(s).any():
        raise ParameterError("stages", "NaN", f"stages in [1, {N_STAGES}]")
    if not float(exposure) > 0:
        raise ParameterError("exposure", exposure, "> 0")
    grid, table = _stage_table(float(exposure))
    s = np.clip(s, 1.0, float(N_STAGES))
    return np.stack([np.interp(s, grid, table[:, c]) for c in range(3)], axis=-1)


_TABLES: dict = {}


def _stage_table(exposure: float):
    if exposure not in _TABLES:
        grid = np.linspace(1.0, float(N_STAGES), int(round((N_STAGES - 1) / STAGE_STEP)) + 1)
        sp = leaf_spectra(stage=grid)
        enc = spectrum_to_srgb(sp.wavelength, sp.reflectance, exposure)
        _TABLES[exposure] = (grid, srgb_decode_np(enc))
    return _TABLES[exposure]


def cover_colours(cover, soil=SOIL_RGB, moss=MOSS_RGB) -> np.ndarray:
    """Linear blend of a soil and a moss colour by moss cover: ``(1 - c) soil + c moss``.

    A blend in linear light is the colour of a surface that shows moss on the share c of its
    area.

    Parameters
    ----------
    cover : array_like
        Moss cover [-] in [0, 1] (clipped); NaN is refused.
    soil : sequence of float, optional
        Linear sRGB of bare ground; default :data:`SOIL_RGB`.
    moss : sequence of float, optional
        Linear sRGB of full moss; default :data:`MOSS_RGB`.

    Returns
    -------
    numpy.ndarray
        (..., 3) linear sRGB [-].

    Raises
    ------
    ParameterError
        For NaN cover.
    """
    c = np.asarray(cover, float)
    if np.isnan(c).any():
        raise ParameterError("cover", "NaN", "moss cover in [0, 1]")
    c = np.clip(c, 0.0, 1.0)[..., None]
    return (1.0 - c) * np.asarray(soil, float) + c * np.asarray(moss, float)


def _rgba8(rgb) -> np.ndarray:
    rgb = np.asarray(rgb, float)
    out = np.full(rgb.shape[:-1] + (4,), 255, np.uint8)
    out[..., :3] = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    return out


def _check_mesh(name, vertices, faces):
    v = np.asarray(vertices, float)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ParameterError(f"{name}: vertices, faces", (v.shape, f.shape),
                             "(n, 3) positions and (m, 3) vertex indices")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ParameterError(f"{name}: faces", f"indices in [{f.min()}, {f.max()}]",
                             f"indices in [0, {len(v) - 1}]")
    return v, f.astype(np.int64)


def face_to_vertex_colours(vertices, faces, face_colours):
    """Mesh arrays whose vertex colours show per-face colours exactly.

    When no vertex is shared by faces of different colours (e.g. leaf quads with their own
    corners) the mesh stays as it is; otherwise every face gets its own three vertices.

    Parameters
    ----------
    vertices : array_like
        (n, 3) positions [m].
    faces : array_like
        (m, 3) vertex indices.
    face_colours : array_like
        (m, k) colours per face (any unit).

    Returns
    -------
    vertices : numpy.ndarray
        (n', 3) positions [m].
    faces : numpy.ndarray
        (m, 3) vertex indices.
    vertex_colours : numpy.ndarray
        (n', k) colours per vertex.
    """
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    fc = np.asarray(face_colours)
    vc = np.zeros((len(v),) + fc.shape[1:], fc.dtype)
    vc[f.ravel()] = np.repeat(fc, 3, axis=0)        # the last face writing a vertex wins
    if np.array_equal(vc[f], np.repeat(fc[:, None], 3, axis=1)):
        return v, f, vc
    return v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3), np.repeat(fc, 3, axis=0)


def vertex_mean(vertices, faces, values) -> np.ndarray:
    """Area-weighted mean of per-face values at each vertex (over the faces around it).

    Parameters
    ----------
    vertices : array_like
        (n, 3) positions [m].
    faces : array_like
        (m, 3) vertex indices.
    values : array_like
        (m,) or (m, k) per-face values (any unit).

    Returns
    -------
    numpy.ndarray
        (n,) or (n, k) per-vertex means (0 at a vertex of no face or of zero-area faces only).
    """
    f = np.asarray(faces, np.int64)
    a, _, _ = triangle_geometry(vertices, f)
    val = np.asarray(values, float)
    w = np.zeros(len(vertices))
    np.add.at(w, f.ravel(), np.repeat(a, 3))
    acc = np.zeros((len(vertices),) + val.shape[1:])
    np.add.at(acc, f.ravel(), np.repeat(a.reshape((-1,) + (1,) * (val.ndim - 1)) * val, 3,
                                        axis=0))
    w = w.reshape((-1,) + (1,) * (val.ndim - 1))
    return np.divide(acc, w, out=np.zeros_like(acc), where=w > 0)


class GltfWorld:
    """Named meshes (and instances) to write as one glTF binary file (module docstring).

    Parameters
    ----------
    roughness : float, optional
        PBR roughness of every material [-]; default 0.8 (matte).
    """

    def __init__(self, roughness: float = 0.8):
        self.scene = trimesh.Scene()
        self.roughness = float(roughness)
        self._names: set = set()

    def _material(self):
        return trimesh.visual.material.PBRMaterial(baseColorFactor=[255, 255, 255, 255],
                                                   metallicFactor=0.0,
                                                   roughnessFactor=self.roughness,
                                                   doubleSided=True)

    def _mesh(self, name, v, f, vertex_rgb) -> trimesh.Trimesh:
        if name in self._names:
            raise ParameterError("name", name, "a name not used before in this file")
        m = trimesh.Trimesh(v, f, process=False)
        vis = trimesh.visual.TextureVisuals(material=self._material())
        vis.vertex_attributes["color"] = _rgba8(vertex_rgb)
        m.visual = vis
        m.metadata["name"] = name
        return m

    def add_mesh(self, name: str, vertices, faces, *, colour=None, vertex_colours=None,
                 face_colours=None, transform=None) -> None:
        """Add a mesh with one colour, per-vertex colours or per-face colours.

        Parameters
        ----------
        name : str
            Mesh and node name (unique in the file).
        vertices : array_like
            (n, 3) positions [m].
        faces : array_like
            (m, 3) vertex indices (counter-clockwise seen from the front).
        colour : sequence of float, optional
            One linear sRGB colour [-]; default :data:`BARK_RGB` when no colours are given.
        vertex_colours : array_like, optional
            (n, 3) linear sRGB [-].
        face_colours : array_like, optional
            (m, 3) linear sRGB [-] (exact: see :func:`face_to_vertex_colours`).
        transform : array_like, optional
            (4, 4) node transform; default identity.

        Raises
        ------
        ParameterError
            For bad shapes, a name used twice or more than one colour argument.
        """
        v, f = _check_mesh(name, vertices, faces)
        given = [x is not None for x in (colour, vertex_colours, face_colours)]
        if sum(given) > 1:
            raise ParameterError(f"{name}: colours", "several", "one of colour, vertex_colours, "
                                 "face_colours")
        if face_colours is not None:
            fc = np.asarray(face_colours, float)
            if fc.shape != (len(f), 3):
                raise ParameterError(f"{name}: face_colours", fc.shape, f"({len(f)}, 3)")
            v, f, vc = face_to_vertex_colours(v, f, fc)
        elif vertex_colours is not None:
            vc = np.asarray(vertex_colours, float)
            if vc.shape != (len(v), 3):
                raise ParameterError(f"{name}: vertex_colours", vc.shape, f"({len(v)}, 3)")
        else:
            vc = np.broadcast_to(np.asarray(BARK_RGB if colour is None else colour, float),
                                 (len(v), 3))
        m = self._mesh(name, v, f, vc)
        self.scene.add_geometry(m, node_name=name, geom_name=name,
                                transform=None if transform is None else np.asarray(transform,
                                                                                   float))
        self._names.add(name)

    def add_leaves(self, name: str, vertices, faces, stages, *, face_leaf=None,
                   exposure: float = 1.0, transform=None) -> None:
        """Add leaves coloured by their autumn stage (:func:`stage_colours`).

        Parameters
        ----------
        name : str
            Mesh name (unique).
        vertices : array_like
            (n, 3) positions [m].
        faces : array_like
            (m, 3) vertex indices.
        stages : array_like
            Ishikura stage [-] in [1, 7]: one per face, or one per leaf with ``face_leaf``.
        face_leaf : array_like, optional
            (m,) leaf of each face (e.g. ``repeat(arange(k), 2)`` for quads); default None:
            ``stages`` is per face.
        exposure : float, optional
            Factor on XYZ before encoding [-]; default 1.
        transform : array_like, optional
            (4, 4) node transform; default identity.

        Raises
        ------
        ParameterError
            When the stages do not match the faces or leaves.
        """
        f = np.asarray(faces)
        s = np.asarray(stages, float).ravel()
        if face_leaf is not None:
            fl = np.asarray(face_leaf, np.int64).ravel()
            if len(fl) != len(f) or (len(fl) and (fl.min() < 0 or fl.max() >= len(s))):
                raise ParameterError(f"{name}: face_leaf", f"{len(fl)} values",
                                     f"{len(f)} leaf indices in [0, {len(s) - 1}]")
            s = s[fl]
        elif len(s) != len(f):
            raise ParameterError(f"{name}: stages", f"{len(s)} values",
                                 f"one per face ({len(f)}) or per leaf with face_leaf")
        self.add_mesh(name, vertices, faces, face_colours=stage_colours(s, exposure),
                      transform=transform)

    def add_terrain(self, name: str, vertices, faces, cover, *, soil=SOIL_RGB, moss=MOSS_RGB,
                    per_face: bool = False) -> None:
        """Add ground coloured by its moss cover per triangle (:func:`cover_colours`).

        Parameters
        ----------
        name : str
            Mesh name (unique).
        vertices : array_like
            (n, 3) positions [m].
        faces : array_like
            (m, 3) vertex indices.
        cover : array_like
            (m,) moss cover [-] in [0, 1] per triangle.
        soil, moss : sequence of float, optional
            Linear sRGB of bare ground and of full moss; defaults :data:`SOIL_RGB`,
            :data:`MOSS_RGB`.
        per_face : bool, optional
            Exact colour per triangle (vertices split where colours differ); default False: a
            smooth colour per vertex from the area-weighted mean cover around it.

        Raises
        ------
        ParameterError
            When ``cover`` has not one value per face.
        """
        v, f = _check_mesh(name, vertices, faces)
        c = np.asarray(cover, float).ravel()
        if len(c) != len(f):
            raise ParameterError(f"{name}: cover", f"{len(c)} values", f"one per face "
                                 f"({len(f)})")
        if per_face:
            self.add_mesh(name, v, f, face_colours=cover_colours(c, soil, moss))
        else:
            self.add_mesh(name, v, f,
                          vertex_colours=cover_colours(vertex_mean(v, f, c), soil, moss))

    def add_instances(self, name: str, vertices, faces, transforms, *, colour=None,
                      vertex_colours=None, face_colours=None) -> list[str]:
        """Add one mesh shown at many places: glTF nodes ``<name>_<i>`` sharing mesh ``name``.

        Every instance shares the mesh's colours (per-tree leaf stages need one mesh per tree:
        :meth:`add_leaves` with that tree's vertices).

        Parameters
        ----------
        name : str
            Mesh name (unique).
        vertices : array_like
            (n, 3) positions of the shared mesh [m].
        faces : array_like
            (m, 3) vertex indices.
        transforms : array_like
            (k, 4, 4) node transforms, one per instance.
        colour, vertex_colours, face_colours : optional
            As for :meth:`add_mesh`.

        Returns
        -------
        list of str
            The node names.

        Raises
        ------
        ParameterError
            For transforms that are not (k, 4, 4), or as :meth:`add_mesh`.
        """
        T = np.asarray(transforms, float)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise ParameterError(f"{name}: transforms", T.shape, "(k, 4, 4) matrices")
        tmp = GltfWorld(self.roughness)
        tmp.add_mesh(name, vertices, faces, colour=colour, vertex_colours=vertex_colours,
                     face_colours=face_colours)
        if name in self._names:
            raise ParameterError("name", name, "a name not used before in this file")
        nodes = [f"{name}_{i}" for i in range(len(T))]
        if not nodes:
            return nodes
        self.scene.add_geometry(tmp.scene.geometry[name], node_name=nodes[0], geom_name=name,
                                transform=T[0])
        for node, M in zip(nodes[1:], T[1:]):     # more nodes on the same mesh
            self.scene.graph.update(frame_to=node, frame_from=self.scene.graph.base_frame,
                                    matrix=M, geometry=name)
        self._names.add(name)
        return nodes

    def export(self, path) -> str:
        """Write the collected meshes as glTF binary (atomically, parent folders created).

        Parameters
        ----------
        path : str or pathlib.Path
            A ``.glb`` file.

        Returns
        -------
        str
            The path written.

        Raises
        ------
        ParameterError
            If the extension is not ``.glb`` or nothing was added.
        """
        p = Path(path)
        if p.suffix.lower() != ".glb":
            raise ParameterError("path", str(path), "a .glb file name", "change the extension")
        if not self._names:
            raise ParameterError("meshes", 0, "at least one mesh", "add meshes before export")
        p.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(p) as tmp:
            tmp.write_bytes(self.scene.export(file_type="glb"))
        return str(p)


def add_stand(world: GltfWorld, stand, variants: dict, stages=None,
              exposure: float = 1.0) -> dict:
    """Add a stand's instanced trees: bark as glTF instances of each variant, leaves coloured.

    Bark: one mesh per variant (``bark_<species>_<k>``), one node per tree. Leaves: without
    ``stages`` one green (stage 1) mesh per variant, instanced like the bark
    (``leaves_<species>_<k>``); with ``stages`` one mesh per tree (``leaves_tree_<i>``) coloured
    leaf by leaf.

    Parameters
    ----------
    world : GltfWorld
        Where to add them.
    stand : mitsuba_veg.trees.stand.Stand
        The stand (positions, yaw, heights, variants).
    variants : dict
        ``{(species, variant): VariantMesh}`` (:func:`mitsuba_veg.trees.instancing.build_variants`).
    stages : dict or sequence, optional
        Per tree index, the Ishikura stage [-] of each leaf of its variant (array of the
        variant's leaf count); default None (every leaf green).
    exposure : float, optional
        Factor on XYZ before encoding [-]; default 1.

    Returns
    -------
    dict
        ``{"bark": [mesh names], "leaves": [mesh names]}``.

    Raises
    ------
    ParameterError
        When a tree's stages do not match its leaf count.
    """
    M = tree_transforms(stand, variants)
    out: dict = {"bark": [], "leaves": []}
    for key, var in variants.items():
        idx = np.flatnonzero((stand.species == key[0]) & (stand.variants == key[1]))
        if not len(idx):
            continue
        tag = f"{key[0]}_{int(key[1])}"
        if len(var.bark[1]):
            world.add_instances(f"bark_{tag}", *var.bark, M[idx], colour=BARK_RGB)
            out["bark"].append(f"bark_{tag}")
        if len(var.leaves[1]) and stages is None:
            world.add_instances(f"leaves_{tag}", *var.leaves, M[idx],
                                colour=stage_colours(1.0, exposure))
            out["leaves"].append(f"leaves_{tag}")
        elif len(var.leaves[1]):
            lv, lf = var.leaves
            per_face = np.repeat(np.arange(var.n_leaves), 2)
            for i in idx:
                s = np.asarray(stages[int(i)], float).ravel()
                if len(s) != var.n_leaves:
                    raise ParameterError(f"stages[{int(i)}]", f"{len(s)} values",
                                         f"one per leaf of its variant ({var.n_leaves})")
                v = lv @ M[i, :3, :3].T + M[i, :3, 3]
                world.add_leaves(f"leaves_tree_{int(i)}", v, lf, s, face_leaf=per_face,
                                 exposure=exposure)
                out["leaves"].append(f"leaves_tree_{int(i)}")
    return out


__all__ = ["SOIL_RGB", "MOSS_RGB", "BARK_RGB", "STAGE_STEP", "stage_colours", "cover_colours",
           "face_to_vertex_colours", "vertex_mean", "GltfWorld", "add_stand"]
