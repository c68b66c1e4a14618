"""Light-study tuning (docs/tuning.md): sun and sky strength fitted to a ground PAR map of the
moss garden made with independent photons, per triangle and on patch means.

    python experiments/tune_light_study.py --photons 300000
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune.light_fit import LightStudy, fit_light  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--photons", type=int, default=300_000)
    a = ap.parse_args()
    data = tune.prepare(ROOT / "scenes" / "moss_garden" / "scenario.toml", days=24,
                        species=["bryum_argenteum"], photons=20_000, light_every=12,
                        kernel_samples=(4, 4))
    st = LightStudy(data.scene, data.base_albedo, bands=("par",), photons=a.photons, seed=0,
                    index=data.index)
    meas = LightStudy(data.scene, data.base_albedo, bands=("par",), photons=a.photons, seed=1,
                      index=data.index)
    g = np.zeros(data.n, bool)
    g[data.shape_slices["ground"]] = True
    truth = {"strength.sun": 1.0, "strength.sky": 1.2}
    target = np.asarray(meas.quantity(truth, "par"))
    for patch in (None, 0.1, 0.2, 0.5):
        for sgn in (-1, 1):
            init = {k: v * (1 + 0.3 * sgn) for k, v in truth.items()}
            r = fit_light(st, target, list(truth), init=init, mask=g, patch=patch)
            print(f"patch {patch}, start {sgn * 30:+d} %: " + ", ".join(
                f"{k} {v:.4f} ({v / truth[k] - 1:+.2%})" for k, v in r.values.items())
                + f"; {r.stats['nfev']} evaluations", flush=True)


if __name__ == "__main__":
    main()
