"""Standard plots of a sweep (PNG, in ``OUT/plots``).

``cover_by_day.png``
    Covered area [m2] over the days, one line per combination of the swept fields other than
    the seed: the mean over the seeds, shaded from the lowest to the highest seed.
``final_vs_<field>.png`` (one per swept field other than the seed)
    The last day's covered area (all surfaces and each region) [m2] and live moss per species
    against the field's values, one line per combination of the other swept fields (e.g. per
    species list when ``moss.species`` is swept): the mean over the seeds with bars from the
    lowest to the highest seed, and each seed as a dot.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..plots import _mpl
from .spec import SEED_FIELD, Sweep
from .table import _cell


__all__ = ["sweep_plots"]

def _groups(df, fields):
    if not fields:
        return [("all runs", df)]
    out = []
    for key, g in df.groupby(fields, sort=False, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        out.append((", ".join(f"{f.split('.')[-1]}={v}" for f, v in zip(fields, key)), g))
    return out


def _short(field: str) -> str:
    return field.replace(".", "_")


def sweep_plots(df, sw: Sweep, out) -> list[Path]:
    """Write the standard plots of a sweep's table (module docstring).

    Parameters
    ----------
    df : pandas.DataFrame
        The tidy table (:func:`mitsuba_veg.sweeps.table.tidy`).
    sw : Sweep
        The sweep.
    out : str or Path
        Folder of the PNGs.

    Returns
    -------
    list of Path
        The files written (none when no run finished).
    """
    plt = _mpl()

    out = Path(out)
    ok = df[df["status"] != "failed"].dropna(subset=["day"])
    if ok.empty:
        return []
    out.mkdir(parents=True, exist_ok=True)
    fields = [f for f in sw.fields if f != SEED_FIELD]
    files = []

    # covered area over the days
    fig, ax = plt.subplots(figsize=(7.5, 4.5), constrained_layout=True)
    groups = _groups(ok, fields)
    for label, g in groups:
        per_day = g.groupby("day")["covered_area_m2"]
        d = np.asarray(per_day.mean().index, float)
        ax.plot(d, per_day.mean().to_numpy(float), label=label, lw=1.5)
        ax.fill_between(d, per_day.min().to_numpy(float), per_day.max().to_numpy(float),
                        alpha=0.2)
    ax.set_xlabel("day")
    ax.set_ylabel("covered area [m²]")
    ax.set_title("moss cover over the days (mean over seeds, shaded: seed range)")
    if len(groups) <= 12:
        ax.legend(fontsize=7)
    p = out / "cover_by_day.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    files.append(p)

    last = ok[ok["day"] == ok.groupby("run")["day"].transform("max")]
    metrics = ["covered_area_m2"] + sorted(c for c in last.columns
                                           if c.startswith("regions.")) + \
        sorted(c for c in last.columns if c.startswith("alive."))
    for f in fields:
        others = [o for o in fields if o != f]
        vals = list(sw.axes[f])
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals)
        n = len(metrics)
        cols = min(n, 3)
        rows = -(-n // cols)
        fig, axs = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.4 * rows),
                                constrained_layout=True, squeeze=False)
        for ax, m in zip(axs.flat, metrics):
            for label, g in _groups(last, others):
                xs, mean, lo, hi = [], [], [], []
                for i, v in enumerate(vals):
                    if numeric:
                        sel = g[np.isclose(g[f].to_numpy(float), float(v))]
                    else:
                        sel = g[g[f].astype(str) == str(_cell_text(v))]
                    if sel.empty:
                        continue
                    y = sel[m].to_numpy(float)
                    x = float(v) if numeric else float(i)
                    xs.append(x)
                    mean.append(y.mean())
                    lo.append(y.mean() - y.min())
                    hi.append(y.max() - y.mean())
                    ax.scatter([x] * len(y), y, s=8, alpha=0.5)
                if xs:
                    ax.errorbar(xs, mean, yerr=[lo, hi], capsize=3, lw=1.3, label=label)
            if m == "covered_area_m2":
                title = "covered area, all surfaces [m²]"
            elif m.startswith("regions."):
                title = f"covered area, {m.split('.')[1]} [m²]"
            else:
                title = f"live moss, {m.split('.', 1)[1]}"
            ax.set_title(title, fontsize=9)
            ax.set_xlabel(f)
            if not numeric:
                ax.set_xticks(range(len(vals)))
                ax.set_xticklabels([str(_cell_text(v)) for v in vals], fontsize=7, rotation=15)
        for ax in list(axs.flat)[n:]:
            ax.axis("off")
        h, lab = axs.flat[0].get_legend_handles_labels()
        if h and len(h) <= 12:
            axs.flat[0].legend(fontsize=7)
        fig.suptitle(f"last day vs {f} (mean over seeds, bars: seed range, dots: seeds)",
                     fontsize=10)
        p = out / f"final_vs_{_short(f)}.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        files.append(p)
    return files


def _cell_text(v):
    return _cell(v)
