"""Pictures of trees: side (x-y) and plan (x-z) views drawn with matplotlib.

Branches are lines whose width follows the pipe-model radius, leaf spheres (growth model) are
translucent discs of their true radius, dead branches are left out (or drawn thin and grey with
``dead=True``), obstacles are grey projected triangles.
"""
from __future__ import annotations

import numpy as np

from ..plots import _mpl

__all__ = ["VIEWS", "draw", "picture"]

#: view name -> (horizontal axis, vertical axis, axis labels)
VIEWS = {
    "side": (0, 1, ("x [m]", "y (up) [m]")),
    "front": (2, 1, ("z [m]", "y (up) [m]")),
    "top": (0, 2, ("x [m]", "z [m]")),
}


def _plt():
    return _mpl()


def draw(ax, trees, view="side", env=None, spheres=True, dead=False, colors=None,
         title=None, width_scale=1.0, sphere_alpha=0.08, clip=None):
    """Draw ``trees`` (a Tree or a list) on a matplotlib axis in ``view``.

    Branch line widths follow the radius at the segment start (``width_scale x 40 x radius``
    [points], clipped to [0.3, 8]); leaf spheres are translucent discs of their true radius,
    trees without spheres show their leaves as dots; obstacles are grey projected triangles.
    The axis limits fit the drawn branches and spheres (5 % margin), with equal aspect; the
    top view has +z down (north up).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axis to draw on.
    trees : Tree or list of Tree
        The trees.
    view : str, optional
        'side' (x-y), 'front' (z-y) or 'top' (x-z); default 'side'.
    env : mitsuba_veg.trees.environment.Environment, optional
        Obstacles to draw behind the trees (default None: none).
    spheres : bool, optional
        Draw the leaf spheres (default True).
    dead : bool, optional
        Also draw dead branches, thin and grey (default False: left out).
    colors : sequence of str, optional
        Branch colour per tree, cycled (default None: brown for all).
    title : str, optional
        Axis title (default None: none).
    width_scale : float, optional
        Multiplier of the branch line widths [-] (default 1).
    sphere_alpha : float, optional
        Opacity of the leaf-sphere discs [-] (default 0.08).
    clip : tuple of array_like, optional
        Box (lo, hi), each (3,) [m]: only segments whose start lies in it (and leaf spheres whose
        centre lies in it) are drawn; default None: everything.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    from matplotlib.collections import LineCollection, PatchCollection, PolyCollection
    from matplotlib.patches import Circle

    if not isinstance(trees, (list, tuple)):
        trees = [trees]
    a, b, labels = VIEWS[view]
    if env is not None and len(env):
        V, F = env.triangles()[:2]
        polys = V[F][:, :, [a, b]]
        ax.add_collection(PolyCollection(polys, facecolors="0.85", edgecolors="0.7",
                                         linewidths=0.2, zorder=0))
    lo = np.full(2, np.inf)
    hi = -lo
    for i, t in enumerate(trees):
        col = (colors[i % len(colors)] if colors else "#5a3a1a")
        live = t.alive.copy()
        if clip is not None:
            inside = np.all((t.start >= clip[0]) & (t.start <= clip[1]), axis=1)
            live &= inside
        if live.any():
            seg = np.stack([t.start[live][:, [a, b]], t.end[live][:, [a, b]]], 1)
            lw = np.clip(width_scale * 40 * t.radius_start[live], 0.3, 8)
            ax.add_collection(LineCollection(seg, colors=col, linewidths=lw, zorder=2,
                                             capstyle="round"))
            lo = np.minimum(lo, seg.reshape(-1, 2).min(0))
            hi = np.maximum(hi, seg.reshape(-1, 2).max(0))
        if dead and (~t.alive).any():
            seg = np.stack([t.start[~t.alive][:, [a, b]], t.end[~t.alive][:, [a, b]]], 1)
            ax.add_collection(LineCollection(seg, colors="0.6", linewidths=0.3, zorder=1))
        c = t.attrs.get("leaf_sphere_center")
        if spheres and c is not None and len(c):
            r = float(t.attrs.get("leaf_sphere_radius", 0.0))
            if clip is not None:
                c = c[np.all((c >= clip[0]) & (c <= clip[1]), axis=1)]
            pc = PatchCollection([Circle((x, y), r) for x, y in c[:, [a, b]]],
                                 facecolor="#2e8b3e", edgecolor="none", alpha=sphere_alpha,
                                 zorder=3)
            ax.add_collection(pc)
            if len(c):
                lo = np.minimum(lo, c[:, [a, b]].min(0) - r)
                hi = np.maximum(hi, c[:, [a, b]].max(0) + r)
        elif len(t.leaves):
            p = t.leaves.position[:, [a, b]]
            ax.scatter(p[:, 0], p[:, 1], s=1, c="#2e8b3e", alpha=0.4, lw=0, zorder=3)
    if np.all(np.isfinite(lo)):
        pad = 0.05 * max(hi - lo)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    if view == "top":
        ax.invert_yaxis()   # +z (south) down: north up as in the plan maps of the package
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def picture(trees, path, env=None, title=None, views=("side", "top"), dpi=110, **kw) -> str:
    """Save a figure with one panel per view; returns the path.

    Parameters
    ----------
    trees : Tree or list of Tree
        The trees.
    path : str or pathlib.Path
        Output image file (format by extension).
    env : mitsuba_veg.trees.environment.Environment, optional
        Obstacles to draw (default None: none).
    title : str, optional
        Figure title (default None: none).
    views : sequence of str, optional
        Views, one panel each (default ('side', 'top'); see :data:`VIEWS`).
    dpi : int, optional
        Resolution [dots per inch] (default 110).
    **kw : dict
        Further keyword arguments of :func:`draw` (``spheres``, ``dead``, ``colors``, ...).

    Returns
    -------
    str
        The path written.
    """
    plt = _plt()
    fig, axs = plt.subplots(1, len(views), figsize=(5.2 * len(views), 5.0))
    axs = np.atleast_1d(axs)
    for ax, v in zip(axs, views):
        draw(ax, trees, v, env=env, **kw)
        ax.set_title(f"{v} view", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return str(path)
