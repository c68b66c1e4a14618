"""Render an assembled scene and write the still outputs (EXR, PNG, red:far-red view)."""
from __future__ import annotations

import time
from pathlib import Path

import mitsuba as mi
import numpy as np

from . import film as _film


def render(rs, spp: int | None = None, seed: int | None = None) -> dict:
    """Render a :class:`~mitsuba_veg.render.scene.RenderScene`; returns :func:`film.develop`'s
    images plus ``seconds``."""
    t0 = time.perf_counter()
    if spp is not None:
        from dataclasses import replace
        spp = replace(rs.options, spp=int(spp)).samples
    img = mi.render(rs.scene, sensor=rs.sensor, spp=int(spp or rs.options.samples),
                    seed=int(rs.options.seed if seed is None else seed))
    a = np.asarray(img)   # waits for the kernel
    out = _film.develop(a)
    out["seconds"] = time.perf_counter() - t0
    return out


def write_outputs(images: dict, out_dir, stem: str = "render", meta: dict | None = None,
                  exposure: float | None = None, title: str | None = None) -> dict:
    """Write ``<stem>.exr``, ``<stem>.png`` and ``<stem>_rfr.png``; returns their paths and the
    exposure used."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    exr = _film.write_exr(out_dir / f"{stem}.exr", images, meta)
    img8, exp = _film.to_srgb8(images["rgb"], exposure)
    png = _film.write_png(out_dir / f"{stem}.png", img8)
    files = {"exr": str(exr), "png": str(png)}
    if "r_fr" in images:
        fc = _film.rfr_false_colour(images["r_fr"], luminance=images["XYZ"][..., 1], title=title)
        files["rfr_png"] = str(_film.write_png(out_dir / f"{stem}_rfr.png", fc))
    return {"files": files, "exposure": exp}
