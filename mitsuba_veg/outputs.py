"""Run outputs: per-day maps (PNG), the animation of the days (GIF), summary.json.

Maps show the ground (the scenario's ``terrain.ground``) from above, one colour per triangle;
the coverage map also draws the other living surfaces' moss as points.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np


def write_json(path, data, indent: int = 2) -> None:
    """Write ``data`` as JSON atomically (NumPy values converted)."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=indent, default=jsonable))
    os.replace(tmp, path)


def write_summary(path, summary: dict) -> None:
    write_json(path, summary, indent=1)


def jsonable(x):
    """JSON fallback for NumPy arrays and scalars (anything else becomes its str)."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return str(x)


class DayFrames:
    """Called after every simulated day; writes maps every ``frame_every`` days and on the last
    day, and assembles them into ``days.gif`` at the end."""

    def __init__(self, sim):
        self.sim = sim
        self.dir = Path(sim.out) / "maps"
        self.frames: list[Path] = []

    def __call__(self, sim, rec) -> None:
        every = max(int(sim.frame_every), 1)
        if sim.day % every == 0 or sim.day == sim.days or sim.day == 1:
            self.frames.append(self.write_day(sim, rec))

    def write_day(self, sim, rec) -> Path:
        from .plots import _mpl, plan_map
        plt = _mpl()

        self.dir.mkdir(parents=True, exist_ok=True)
        idx = sim.index
        ground = sim.scn.get("terrain.ground", "ground")
        sl = idx.shape_slice(ground)
        v, f = idx.geometry[ground]
        counts = sim._counts()
        cover = np.minimum(counts * sim.grid_cell() ** 2 / idx.areas, 1.0)
        last = sim.last
        fig, axs = plt.subplots(1, 4, figsize=(17, 4.1), constrained_layout=True)
        plan_map(axs[0], v, f, cover[sl], title="moss cover (fraction of each triangle)",
                 label="cover [-]", cmap="Greens", vmin=0.0, vmax=1.0)
        pos = sim.pop.to_numpy()
        live = pos["state"] == 2
        if live.any():
            p = pos["pos"][live]
            axs[0].scatter(p[:, 0], -p[:, 2], s=0.4, c="k", alpha=0.35, linewidths=0)
        plan_map(axs[1], v, f, last["S"][sl], title="insolation S (daily mean)",
                 label="W m$^{-2}$", cmap="inferno", vmin=0.0)
        plan_map(axs[2], v, f, last["Ts"][sl], title="soil surface temperature Ts",
                 label="K", cmap="coolwarm")
        plan_map(axs[3], v, f, last["theta"][sl], title="soil water content θ",
                 label="θ [-]", cmap="Blues", vmin=0.0)
        fig.suptitle(f"day {rec['day']} ({rec['date']}): {rec['moss_alive']} moss, "
                     f"{rec['propagules']} propagules, covered {rec['covered_area_m2']:.4f} m²",
                     fontsize=11)
        path = self.dir / f"day_{rec['day']:04d}.png"
        tmp = self.dir / f".day_{rec['day']:04d}.tmp.png"
        fig.savefig(tmp, dpi=80)
        plt.close(fig)
        os.replace(tmp, path)
        return path

    def finish(self) -> dict:
        files = {"maps": [str(p) for p in sorted(set(self.frames))]}
        frames = sorted(set(self.dir.glob("day_*.png")))
        if len(frames) >= 2:
            from PIL import Image
            imgs = [Image.open(p).convert("P", palette=Image.ADAPTIVE) for p in frames]
            gif = Path(self.sim.out) / "days.gif"
            tmp = gif.with_suffix(".tmp.gif")
            imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=400, loop=0)
            os.replace(tmp, gif)
            files["animation"] = str(gif)
        return files
