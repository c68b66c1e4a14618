"""Pictures people would rather look at than read: false-colour maps of per-triangle values.

Maps are drawn from above (plan view): x to the right (east), north (-z) up, one colour per
triangle, with a colour bar in the quantity's units.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .meshes import triangle_geometry


__all__ = ["plan_map", "irradiance_figure", "result_geometry", "save_figure", "loss_curve_figure"]

def _mpl():
    """pyplot, with the backend matplotlib chose: Agg without a display, the notebook's own
    inline backend in Jupyter (forcing Agg here would leave later plt.show() calls blank)."""
    import matplotlib.pyplot as plt
    return plt


#: face groups by dominant normal direction: name, normal axis, sign, projected axes, labels
_VIEWS = [
    ("upward faces, seen from above", 1, +1, (0, 2), (1, -1), ("x (east) [m]", "-z (north) [m]")),
    ("downward faces, seen from above through the shape", 1, -1, (0, 2), (1, -1),
     ("x (east) [m]", "-z (north) [m]")),
    ("south-facing faces (+z), seen from the south", 2, +1, (0, 1), (1, 1),
     ("x (east) [m]", "y (up) [m]")),
    ("north-facing faces (-z), seen from the south through the shape", 2, -1, (0, 1), (1, 1),
     ("x (east) [m]", "y (up) [m]")),
    ("east-facing faces (+x), seen from the east", 0, +1, (2, 1), (-1, 1),
     ("-z (north) [m]", "y (up) [m]")),
    ("west-facing faces (-x), seen from the east through the shape", 0, -1, (2, 1), (-1, 1),
     ("-z (north) [m]", "y (up) [m]")),
]


def plan_map(ax, vertices, faces, values, *, title="", label="", cmap="inferno", vmin=None,
             vmax=None, log=False, axes=(0, 2), signs=(1, -1),
             axis_labels=("x (east) [m]", "-z (north) [m]")):
    """Draw per-triangle ``values`` on ``ax`` projected on two world axes.

    The default is the plan view: x east to the right, north (-z) up. NaN values are left out of
    the colour range; a colour bar with ``label`` is added.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    vertices : array_like
        Vertex positions (V, 3) [m], world frame (+y up).
    faces : array_like of int
        Triangles (F, 3), vertex indices.
    values : array_like
        One value per triangle (F,), in the quantity's unit (given by ``label``).
    title : str, optional
        Axes title; default ``""``.
    label : str, optional
        Colour-bar label, with the unit (e.g. ``"W m$^{-2}$"``); default ``""``.
    cmap : str, optional
        Matplotlib colour map; default ``"inferno"``.
    vmin, vmax : float, optional
        Colour range, in the unit of ``values``; default None: the finite data's min / max
        (positive data's with ``log``).
    log : bool, optional
        Logarithmic colour scale (values <= 0 drawn at the lowest colour); default False.
    axes : tuple of int, optional
        World axes (0 x, 1 y, 2 z) drawn horizontally and vertically; default ``(0, 2)``.
    signs : tuple of int, optional
        Sign (+1 / -1) applied to each drawn axis; default ``(1, -1)`` (north up).
    axis_labels : tuple of str, optional
        Axis labels; default ``("x (east) [m]", "-z (north) [m]")``.

    Returns
    -------
    matplotlib.collections.PolyCollection
        The ``tripcolor`` collection.
    """
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.tri import Triangulation

    v = np.asarray(vertices)
    tri = Triangulation(signs[0] * v[:, axes[0]], signs[1] * v[:, axes[1]], np.asarray(faces))
    vals = np.asarray(values, dtype=float)
    finite = vals[np.isfinite(vals)]
    if log:
        pos = finite[finite > 0]
        lo = vmin if vmin is not None else (pos.min() if pos.size else 1e-3)
        hi = vmax if vmax is not None else (pos.max() if pos.size else 1.0)
        norm = LogNorm(vmin=lo, vmax=max(hi, lo * 1.0001))
        vals = np.where(vals > 0, vals, lo)
    else:
        lo = vmin if vmin is not None else (finite.min() if finite.size else 0.0)
        hi = vmax if vmax is not None else (finite.max() if finite.size else 1.0)
        norm = Normalize(vmin=lo, vmax=hi if hi > lo else lo + 1e-9)
    pc = ax.tripcolor(tri, facecolors=vals, cmap=cmap, norm=norm, edgecolors="face",
                      linewidth=0.2)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(axis_labels[0])
    ax.set_ylabel(axis_labels[1])
    cb = ax.figure.colorbar(pc, ax=ax, shrink=0.85)
    cb.set_label(label)
    return pc


def irradiance_figure(result, shape_id: str, path, title: str | None = None) -> str:
    """PNG of the front irradiance of ``shape_id`` from a photon pass.

    Columns: total, direct and indirect irradiance [W m-2] and (if the red and far-red bands
    were traced) the red:far-red photon ratio [-]; one row per group of faces that share a facing
    direction (up, down, south ...) and hold at least 5 % of the shape's area, each drawn in the
    projection that shows it. Written atomically.

    Parameters
    ----------
    result : PhotonIrradianceResult
        Result of :func:`mitsuba_veg.light.photon_irradiance` (with stored mesh geometry).
    shape_id : str
        Id of the mesh shape to draw.
    path : str or pathlib.Path
        The PNG to write.
    title : str, optional
        Figure title; default None: the shape id and the photon count.

    Returns
    -------
    str
        The written path.
    """
    plt = _mpl()
    result.index.shape_slice(shape_id)  # clear error for an unknown id
    band = "total" if "total" in result.bands else result.bands[0]
    verts, faces = result_geometry(result, shape_id)
    v = np.asarray(verts)
    area, nrm, _ = triangle_geometry(v, faces)
    dom = np.argmax(np.abs(nrm), axis=1)
    sign = np.sign(nrm[np.arange(len(nrm)), dom])
    rows = []
    for name, ax_i, sg, axes, signs, labels in _VIEWS:
        sel = (dom == ax_i) & (sign == sg)
        if sel.any() and area[sel].sum() >= 0.05 * area.sum():
            rows.append((name, sel, axes, signs, labels))
    has_rfr = "red" in result.bands and "far_red" in result.bands
    cols = [("total", f"{band} irradiance, all light"), ("direct", "direct (first hit)"),
            ("indirect", "indirect (own scale)")] + ([("rfr", "red : far-red (photons)")]
                                                      if has_rfr else [])
    fig, axs = plt.subplots(len(rows), len(cols), figsize=(4.4 * len(cols), 3.9 * len(rows)),
                            constrained_layout=True, squeeze=False)
    data = {c: (result.red_far_red(shape_id) if c == "rfr" else
                result.irradiance(shape_id, band, c)) for c, _ in cols}
    vmax = float(np.nanmax(data["total"])) if data["total"].size else 1.0
    for r, (name, sel, axes, signs, labels) in enumerate(rows):
        f = faces[sel]
        for c, (comp, t) in enumerate(cols):
            vals = data[comp][sel]
            kw = dict(axes=axes, signs=signs, axis_labels=labels)
            if comp == "rfr":
                top = float(np.nanmax(vals)) if np.isfinite(vals).any() else 1.3
                plan_map(axs[r, c], v, f, vals, title=t, label="R:FR", cmap="RdYlGn", vmin=0.0,
                         vmax=max(1.3, top), **kw)
            else:
                top = vmax if comp != "indirect" else float(np.nanmax(vals))
                plan_map(axs[r, c], v, f, vals, title=t, label="W m$^{-2}$", vmin=0.0,
                         vmax=top if top > 0 else 1.0, **kw)
        axs[r, 0].annotate(name, (0, 1.2), xycoords="axes fraction", fontsize=10,
                           fontweight="bold")
    fig.suptitle(title or f"'{shape_id}': irradiance on the front of each triangle - "
                 f"{result.photons.sum():,d} photons", fontsize=11)
    with atomic_write(path, f"{path}.tmp.png") as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return str(path)


def result_geometry(result, shape_id: str):
    """(vertices, faces) of a shape of the scene a result was traced on.

    Parameters
    ----------
    result : PhotonIrradianceResult
        A photon-pass result (its ``index.geometry``).
    shape_id : str
        Id of a mesh shape.

    Returns
    -------
    vertices : numpy.ndarray
        Vertex positions (V, 3) [m], world space.
    faces : numpy.ndarray
        Triangles (F, 3), vertex indices.

    Raises
    ------
    ValueError
        If no mesh geometry is stored for ``shape_id``.
    """
    geo = getattr(result.index, "geometry", {}).get(shape_id)
    if geo is None:
        raise ValueError(f"no mesh geometry stored for '{shape_id}'")
    return geo


def save_figure(fig, path, dpi: int = 80) -> str:
    """Write a Matplotlib figure as PNG atomically (parent folders made) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or pathlib.Path
        The PNG.
    dpi : int, optional
        Resolution [dots per inch]; default 80.

    Returns
    -------
    str
        The written path.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(p, p.with_name(f".{p.stem}.tmp.png")) as tmp:
        fig.savefig(tmp, dpi=dpi)
    _mpl().close(fig)
    return str(p)


def loss_curve_figure(history: list[dict], path, loss_name: str = "") -> str:
    """Loss (log scale) and every fitted parameter against the optimiser (Adam) step, as a PNG.

    Parameters
    ----------
    history : list of dict
        One dict per step with ``step`` (int), ``loss`` (float) and ``params`` (name -> value, in
        each parameter's own unit).
    path : str or pathlib.Path
        The PNG to write.
    loss_name : str, optional
        Name of the loss for the title; default ``""``.

    Returns
    -------
    str
        The written path.
    """
    plt = _mpl()
    steps = [h["step"] for h in history]
    names = list(history[0]["params"]) if history else []
    fig, axes = plt.subplots(1, 1 + len(names), figsize=(4.0 * (1 + len(names)), 3.4),
                             squeeze=False)
    ax = axes[0, 0]
    ax.semilogy(steps, np.maximum([h["loss"] for h in history], 1e-300), "-o", ms=2)
    ax.set_xlabel("Adam step")
    ax.set_ylabel("loss")
    ax.set_title(f"loss ({loss_name})" if loss_name else "loss")
    ax.grid(True, which="both", alpha=0.3)
    for ax, n in zip(axes[0, 1:], names):
        ax.plot(steps, [h["params"][n] for h in history], "-", lw=1.5)
        ax.set_xlabel("Adam step")
        ax.set_title(n)
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    with atomic_write(path, f"{path}.tmp.png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return str(path)
