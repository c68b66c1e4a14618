"""Moss tuft models: a few small procedural meshes per species (~1 cm), shipped as PLY files.

Paper 000 renders every moss as one small 3D moss model (its fig 3.7, a haircap moss) and
places it with 1/f noise and a random rotation. This module makes the models: per species a few
variants (different random stems/shoots/fronds), each a triangle mesh in a local frame with
+y along the surface normal, its footprint about 1 cm across (:data:`TUFT_SIZE`) and a per-vertex
``tone`` in [0, 1] (0 = old, dark base; 1 = young, light tips) that the renderer uses to blend two
spectral reflectances.

- ``polytrichum`` (haircap moss): 6-9 upright stems, 6-12 mm tall, each a thin prism with a star
  of narrow leaves near the top;
- ``bryum_argenteum`` (silver moss): a low cushion of 8-10 stubby, catkin-like shoots, 2-5 mm;
- ``hypnum_plumaeforme`` (a feather moss): 4-5 creeping pinnate fronds lying nearly flat,
  radiating 5-8 mm from the centre;
- any other species key uses the ``hypnum_plumaeforme`` models.

The shipped files live in ``mitsuba_veg/data/tufts/<species>_<k>.ply`` (binary PLY with a
``tone`` vertex property); ``python -m mitsuba_veg.render.tufts`` rewrites them (deterministic).
:func:`tuft_models` reads them and regenerates any that are missing.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from ..errors import ParameterError

__all__ = ["TUFT_SIZE", "VARIANTS", "SPECIES_MODELS", "DATA_DIR", "Tuft", "model_key", "generate",
           "write_ply", "read_ply", "tuft_models", "write_all"]

#: footprint of a tuft model [m] (the moss model of paper 000 is 1 cm)
TUFT_SIZE = 0.01
#: variants per species
VARIANTS = 4
#: species with tuft models of their own (others use hypnum_plumaeforme's)
SPECIES_MODELS = ("polytrichum", "bryum_argenteum", "hypnum_plumaeforme")
#: folder of the shipped tuft PLY files
DATA_DIR = Path(__file__).resolve().parents[1] / "data" / "tufts"


@dataclass
class Tuft:
    """One tuft model: vertices (v, 3) [m], faces (f, 3), tone (v,) in [0, 1]."""

    vertices: np.ndarray
    faces: np.ndarray
    tone: np.ndarray
    name: str = "tuft"

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, np.float32).reshape(-1, 3)
        self.faces = np.asarray(self.faces, np.int32).reshape(-1, 3)
        self.tone = np.asarray(self.tone, np.float32).reshape(-1)
        if len(self.tone) != len(self.vertices):
            raise ParameterError("Tuft.tone", len(self.tone), f"{len(self.vertices)} values")

    @property
    def extent(self) -> np.ndarray:
        """Size of the model's bounding box along x, y, z [m] (3,)."""
        return self.vertices.max(0) - self.vertices.min(0)


# ---- geometry helpers ------------------------------------------------------------------------
class _Builder:
    def __init__(self):
        self.v, self.f, self.t = [], [], []
        self.n = 0

    def add(self, verts, faces, tone):
        verts = np.asarray(verts, float).reshape(-1, 3)
        self.v.append(verts)
        self.f.append(np.asarray(faces, np.int64).reshape(-1, 3) + self.n)
        self.t.append(np.broadcast_to(np.asarray(tone, float), (len(verts),)))
        self.n += len(verts)

    def tuft(self, name) -> Tuft:
        return Tuft(np.concatenate(self.v), np.concatenate(self.f), np.concatenate(self.t), name)


def _frame(d):
    d = np.asarray(d, float)
    d = d / np.linalg.norm(d)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def _prism(b, p0, p1, r0, r1, sides, tone0, tone1):
    """A tapered open prism from p0 to p1 (radii r0, r1); r1 = 0 closes it with a tip."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    u, w = _frame(p1 - p0)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w
    k = np.arange(sides)
    k1 = (k + 1) % sides
    if r1 <= 0:
        verts = np.concatenate([p0 + r0 * ring, p1[None]])
        faces = np.stack([k, k1, np.full(sides, sides)], 1)
        tone = np.concatenate([np.full(sides, tone0), [tone1]])
    else:
        verts = np.concatenate([p0 + r0 * ring, p1 + r1 * ring])
        faces = np.concatenate([np.stack([k, k1, sides + k1], 1),
                                np.stack([k, sides + k1, sides + k], 1)])
        tone = np.concatenate([np.full(sides, tone0), np.full(sides, tone1)])
    b.add(verts, faces, tone)


def _blade(b, base, direction, side, length, width, tone0, tone1):
    """A narrow leaf blade: one triangle from a base of ``width`` along ``side`` to a tip."""
    base, direction, side = (np.asarray(x, float) for x in (base, direction, side))
    direction = direction / np.linalg.norm(direction)
    side = side / np.linalg.norm(side)
    verts = [base - 0.5 * width * side, base + 0.5 * width * side, base + length * direction]
    b.add(verts, [[0, 1, 2]], [tone0, tone0, tone1])


# ---- species ---------------------------------------------------------------------------------
def _polytrichum(rng) -> Tuft:
    b = _Builder()
    n = int(rng.integers(6, 10))
    r = 0.0032 * np.sqrt(rng.random(n))
    a = rng.random(n) * 2 * np.pi
    for i in range(n):
        foot = np.array([r[i] * np.cos(a[i]), 0.0, r[i] * np.sin(a[i])])
        h = rng.uniform(0.006, 0.012)
        lean = np.array([np.cos(a[i]), 0, np.sin(a[i])]) * rng.uniform(0.0, 0.35) \
            + rng.normal(0, 0.08, 3) * [1, 0, 1]
        top = foot + h * (np.array([0, 1.0, 0]) + lean) / np.linalg.norm([0, 1.0, 0] + lean)
        _prism(b, foot, top, 0.00035, 0.00022, 3, 0.0, 0.6)
        axis = (top - foot) / np.linalg.norm(top - foot)
        u, w = _frame(axis)
        k = int(rng.integers(5, 7))
        phase = rng.random() * 2 * np.pi
        for j in range(k):
            t = 0.55 + 0.45 * (j / max(k - 1, 1))
            at = foot + t * (top - foot)
            ang = phase + 2 * np.pi * j / k + rng.normal(0, 0.2)
            out = np.cos(ang) * u + np.sin(ang) * w
            d = 0.75 * out + 0.65 * axis
            side = np.cross(axis, out)
            _blade(b, at, d, side, rng.uniform(0.0025, 0.0038), 0.0009, 0.35, 1.0)
    return b.tuft("polytrichum")


def _bryum(rng) -> Tuft:
    b = _Builder()
    n = int(rng.integers(8, 11))
    r = 0.0038 * np.sqrt((np.arange(n) + rng.random(n)) / n)
    a = np.arange(n) * 2.39996 + rng.random() * 6.283
    for i in range(n):
        foot = np.array([r[i] * np.cos(a[i]), 0.0, r[i] * np.sin(a[i])])
        h = rng.uniform(0.0025, 0.0048) * (1.0 - 0.35 * r[i] / 0.0038)
        out = np.array([np.cos(a[i]), 0.0, np.sin(a[i])])
        d = np.array([0.0, 1.0, 0.0]) + out * (r[i] / 0.0038) * 0.5 + rng.normal(0, 0.1, 3)
        d /= np.linalg.norm(d)
        mid = foot + 0.55 * h * d
        tip = foot + h * d
        rw = rng.uniform(0.0011, 0.0015)
        # stubby catkin: base ring -> fat middle ring -> tip
        u, w = _frame(d)
        ang = 2 * np.pi * np.arange(3) / 3 + rng.random()
        ring = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w
        verts = np.concatenate([foot + 0.6 * rw * ring, mid + rw * ring, tip[None]])
        k = np.arange(3)
        k1 = (k + 1) % 3
        faces = np.concatenate([np.stack([k, k1, 3 + k1], 1), np.stack([k, 3 + k1, 3 + k], 1),
                                np.stack([3 + k, 3 + k1, np.full(3, 6)], 1)])
        b.add(verts, faces, [0.0, 0.0, 0.0, 0.55, 0.55, 0.55, 1.0])
    return b.tuft("bryum_argenteum")


def _hypnum(rng) -> Tuft:
    b = _Builder()
    n = int(rng.integers(4, 6))
    a0 = rng.random() * 2 * np.pi
    for i in range(n):
        a = a0 + 2 * np.pi * i / n + rng.normal(0, 0.25)
        out = np.array([np.cos(a), 0.0, np.sin(a)])
        side = np.array([-np.sin(a), 0.0, np.cos(a)])
        length = rng.uniform(0.005, 0.0075)
        lift = rng.uniform(0.15, 0.45)
        curl = rng.normal(0, 0.25)
        seg = 3
        pts = []
        for s in range(seg + 1):
            t = s / seg
            d = out * np.cos(curl * t) + side * np.sin(curl * t)
            y = length * (lift * t - 0.35 * lift * t * t) + 0.0006
            pts.append(d * length * t * 0.9 + np.array([0.0, y, 0.0]))
        pts = np.array(pts)
        wid = np.linspace(0.0012, 0.0005, seg + 1)
        verts = np.concatenate([pts - 0.5 * wid[:, None] * side, pts + 0.5 * wid[:, None] * side])
        k = np.arange(seg)
        faces = np.concatenate([np.stack([k, k + 1, seg + 1 + k + 1], 1),
                                np.stack([k, seg + 1 + k + 1, seg + 1 + k], 1)])
        tone = np.concatenate([np.linspace(0.1, 0.8, seg + 1)] * 2)
        b.add(verts, faces, tone)
        # pinnae: alternate small blades along the frond
        m = 6
        for j in range(m):
            t = 0.2 + 0.75 * j / (m - 1)
            p = pts[0] + t * (pts[-1] - pts[0])
            sgn = 1.0 if j % 2 == 0 else -1.0
            d = 0.55 * out + sgn * side + np.array([0, 0.15, 0])
            _blade(b, p, d, out, 0.0028 * (1.1 - 0.5 * t), 0.0010, 0.3 + 0.4 * t, 1.0)
    return b.tuft("hypnum_plumaeforme")


_MAKERS = {"polytrichum": _polytrichum, "bryum_argenteum": _bryum,
           "hypnum_plumaeforme": _hypnum}


def model_key(species: str) -> str:
    """The tuft model family of a species key (unknown species: the feather moss).

    Parameters
    ----------
    species : str
        Species key (e.g. ``"polytrichum"``).

    Returns
    -------
    str
        ``species`` when it has models of its own, else ``"hypnum_plumaeforme"``.
    """
    return species if species in _MAKERS else "hypnum_plumaeforme"


def generate(species: str, variant: int = 0) -> Tuft:
    """Generate tuft ``variant`` of ``species`` (deterministic), centred, base at y = 0.

    Parameters
    ----------
    species : str
        Species key (unknown species get the ``hypnum_plumaeforme`` models).
    variant : int, optional
        Variant number (default 0); it seeds the random generator with the species.

    Returns
    -------
    Tuft
        The model, vertices [m] in its local frame (+y along the surface normal).
    """
    key = model_key(species)
    seed = [SPECIES_MODELS.index(key), int(variant), 20260]
    t = _MAKERS[key](np.random.default_rng(seed))
    t.vertices[:, 1] -= min(float(t.vertices[:, 1].min()), 0.0)
    return t


# ---- PLY files -------------------------------------------------------------------------------
def write_ply(path, tuft: Tuft) -> None:
    """Binary little-endian PLY with vertex properties x, y, z, tone (written atomically).

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write.
    tuft : Tuft
        The model (vertices [m], triangle faces, tone in [0, 1]).
    """
    path = Path(path)
    v = np.zeros(len(tuft.vertices), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                             ("tone", "<f4")])
    v["x"], v["y"], v["z"] = tuft.vertices.T
    v["tone"] = tuft.tone
    f = np.zeros(len(tuft.faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    f["n"] = 3
    f["i"] = tuft.faces
    head = ("ply\nformat binary_little_endian 1.0\n"
            f"comment mitsuba-veg moss tuft model '{tuft.name}' (mitsuba_veg.render.tufts)\n"
            f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
            f"property float tone\nelement face {len(f)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    with atomic_write(path, path.with_suffix(".tmp")) as tmp, open(tmp, "wb") as fh:
        fh.write(head.encode("ascii"))
        fh.write(v.tobytes())
        fh.write(f.tobytes())


def read_ply(path) -> Tuft:
    """Read a tuft PLY written by :func:`write_ply`.

    Parameters
    ----------
    path : str or pathlib.Path
        The PLY file.

    Returns
    -------
    Tuft
        The model (vertices [m]), named after the file's stem.

    Raises
    ------
    ParameterError
        If a face is not a triangle.
    """
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    head = data[:end].decode("ascii").splitlines()
    nv = int(next(h for h in head if h.startswith("element vertex")).split()[-1])
    nf = int(next(h for h in head if h.startswith("element face")).split()[-1])
    v = np.frombuffer(data, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("tone", "<f4")],
                      count=nv, offset=end)
    f = np.frombuffer(data, dtype=[("n", "u1"), ("i", "<i4", (3,))], count=nf,
                      offset=end + v.nbytes)
    if nf and not np.all(f["n"] == 3):
        raise ParameterError(str(path), "non-triangle faces", "a tuft PLY of triangles")
    return Tuft(np.stack([v["x"], v["y"], v["z"]], 1), f["i"], v["tone"], Path(path).stem)


_CACHE: dict = {}


def tuft_models(species: str, variants: int = VARIANTS) -> list[Tuft]:
    """The tuft models of a species: the shipped PLY files, regenerated where missing.

    Cached per model family and variant count.

    Parameters
    ----------
    species : str
        Species key (unknown species get the ``hypnum_plumaeforme`` models).
    variants : int, optional
        How many variants (default :data:`VARIANTS`, 4).

    Returns
    -------
    list of Tuft
        ``variants`` models (vertices [m]).
    """
    key = (model_key(species), int(variants))
    if key not in _CACHE:
        out = []
        for k in range(int(variants)):
            p = DATA_DIR / f"{key[0]}_{k}.ply"
            try:
                out.append(read_ply(p))
            except (OSError, ValueError, StopIteration):
                out.append(generate(key[0], k))
        _CACHE[key] = out
    return _CACHE[key]


def write_all(directory=DATA_DIR) -> list[Path]:
    """(Re)write the shipped tuft PLY files.

    Parameters
    ----------
    directory : str or pathlib.Path, optional
        Where to write them (default :data:`DATA_DIR`, ``mitsuba_veg/data/tufts``).

    Returns
    -------
    list of pathlib.Path
        The files written, ``<species>_<k>.ply`` for every species model and variant.
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for sp in SPECIES_MODELS:
        for k in range(VARIANTS):
            p = d / f"{sp}_{k}.ply"
            write_ply(p, generate(sp, k))
            paths.append(p)
    return paths


if __name__ == "__main__":  # pragma: no cover
    for p in write_all():
        t = read_ply(p)
        print(f"{p}: {len(t.vertices)} vertices, {len(t.faces)} triangles, extent "
              f"{np.round(t.extent * 1000, 1).tolist()} mm")
