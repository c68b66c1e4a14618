"""Write mitsuba_veg/data/earthlib_spectra.csv: measured reflectance curves of the render's
materials, taken from the Earth Library (earthlib 1.1.0, MIT licence, C. Anderson;
https://github.com/earth-chris/earthlib), resampled to 360-830 nm in 5 nm steps.

    pip download earthlib==1.1.0 --no-deps -d /tmp/earthlib
    python scripts/vendor_earthlib.py /tmp/earthlib/earthlib-1.1.0-py3-none-any.whl

Each curve is the per-wavelength percentile of one earthlib class (LEVEL_2/LEVEL_3 of its
``spectra.csv``) named in :data:`CURVES`: the median for a material, a lower or upper
percentile for its dark or light variant. The soils are first narrowed to organic-looking ones
(:data:`SOIL_SELECT`): the library's 4,185 soils are mostly mineral, many of them red tropical
soils; humus is the dark, least red end (reflectance at 550 nm and its ratio 660/550 nm within
the given percentile windows of all soils). earthlib starts at 400 nm; below, each curve is
extended linearly with its 400-440 nm slope, limited to [0.5, 1] x its 400-nm value (soils,
bark and litter fall gently into the ultraviolet). The CSV is deterministic: running the script
again writes the same file.
"""
from __future__ import annotations

import csv
import io
import re
import sys
import zipfile
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "mitsuba_veg" / "data" / "earthlib_spectra.csv"
WL = np.arange(360.0, 830.0 + 1e-9, 5.0)
#: material -> (earthlib LEVEL_2 / LEVEL_3 classes, percentile)
CURVES = {
    "humus": (("bare/soil",), 50),
    "humus_light": (("bare/soil",), 50),
    "sand": (("bare/sand",), 50),
    "sand_light": (("bare/sand",), 90),
    "asphalt": (("built/asphalt",), 50),
    "asphalt_light": (("built/asphalt",), 80),
    "gravel": (("bare/gravel", "built/gravel"), 50),
    "gravel_light": (("bare/gravel", "built/gravel"), 75),
    "concrete": (("built/sidewalk",), 50),
    "concrete_light": (("built/sidewalk",), 75),
    "bark": (("npv/bark",), 35),
    "bark_light": (("npv/bark",), 65),
    "wood": (("npv/wood",), 50),
    "litter": (("npv/litter",), 50),
    "litter_dark": (("npv/litter",), 20),
}


#: soils kept for a material: percentile windows of brightness (R 550 nm) and redness
#: (R 660 / R 550 nm) over all soils
SOIL_SELECT = {"humus": ((0, 10), (0, 33)), "humus_light": ((10, 25), (0, 33))}


def read_library(wheel: Path):
    """(wavelengths [nm], spectra (n, bands), classes "LEVEL_2/LEVEL_3") from the wheel."""
    with zipfile.ZipFile(wheel) as z:
        hdr = z.read("earthlib/data/spectra.sli.hdr").decode()
        raw = z.read("earthlib/data/spectra.sli")
        meta = list(csv.DictReader(io.StringIO(z.read("earthlib/data/spectra.csv").decode())))
    get = lambda k: re.search(rf"^{k}\s*=\s*(\S+)", hdr, re.M).group(1)  # noqa: E731
    samples, lines = int(get("samples")), int(get("lines"))
    wl = np.array([float(x) for x in re.search(r"wavelength\s*=\s*\{([^}]*)\}", hdr)
                   .group(1).split(",")]) * 1000.0
    data = np.frombuffer(raw, "<f4").reshape(lines, samples).astype(np.float64)
    classes = [f"{m['LEVEL_2']}/{m['LEVEL_3']}" for m in meta]
    return wl, data, classes


def curve(wl, data, classes, names, pct, select=None) -> np.ndarray:
    sel = np.array([c in names for c in classes])
    if select is not None:
        (b0, b1), (r0, r1) = select
        b = data[:, np.argmin(abs(wl - 550))]
        red = data[:, np.argmin(abs(wl - 660))] / np.maximum(b, 1e-6)
        inb = (b >= np.percentile(b[sel], b0)) & (b <= np.percentile(b[sel], b1))
        inr = (red >= np.percentile(red[sel & inb], r0)) & (red <= np.percentile(red[sel & inb], r1))
        sel = sel & inb & inr
    p = np.percentile(data[sel], pct, axis=0)
    r = np.interp(WL, wl, p)
    lo = WL < wl[0]
    slope = (np.interp(440.0, wl, p) - p[0]) / (440.0 - wl[0])
    ext = p[0] + slope * (WL[lo] - wl[0])
    r[lo] = np.clip(ext, 0.5 * p[0], p[0])
    return np.clip(r, 0.005, 0.95), int(sel.sum())


def main(wheel):
    wl, data, classes = read_library(Path(wheel))
    rows, counts = {}, {}
    for name, (cls, pct) in CURVES.items():
        rows[name], counts[name] = curve(wl, data, classes, cls, pct, SOIL_SELECT.get(name))
    with open(OUT, "w", newline="") as f:
        f.write("# Reflectance [-] of the render's materials, 360-830 nm (5 nm), from the Earth "
                "Library\n# (earthlib 1.1.0, MIT licence, (c) 2023 Christopher Anderson, "
                "https://github.com/earth-chris/earthlib):\n# per material the given "
                "percentile over the spectra of its class; below 400 nm extended linearly\n"
                "# (scripts/vendor_earthlib.py).\n")
        for name, (cls, pct) in CURVES.items():
            sel = SOIL_SELECT.get(name)
            how = "" if sel is None else (f" (of soils with R550 in percentiles {sel[0]} and "
                                          f"R660/R550 in {sel[1]} of those)")
            f.write(f"# {name}: {'+'.join(cls)}, percentile {pct}{how}, {counts[name]} "
                    "spectra\n")
        w = csv.writer(f)
        w.writerow(["wavelength_nm"] + list(CURVES))
        for i, x in enumerate(WL):
            w.writerow([f"{x:g}"] + [f"{rows[n][i]:.4f}" for n in CURVES])
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main(sys.argv[1])
