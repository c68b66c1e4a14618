"""The render's film and image outputs: spectral bands, sRGB, EXR, PNG, red:far-red view.

One ``specfilm`` records five channels in a single pass: the CIE 1931 colour matching functions
x̄, ȳ, z̄ (for the colour image) and two narrow bands, red 655-665 nm and far-red 725-735 nm
(Smith 1982's R:FR bands). The film samples wavelengths in proportion to the sum of the channel
sensitivities; the narrow bands are weighted up (:data:`BAND_WEIGHT`) so that each gets about
a sixth of the wavelength samples instead of 3 %, and divided back afterwards.

:func:`develop` turns the film's tensor into calibrated quantities:

- ``XYZ`` (h, w, 3): CIE XYZ normalised so that Y is the ȳ-weighted mean spectral radiance
  [W m-2 sr-1 nm-1] (Y = 1 for a flat spectrum of 1 W m-2 sr-1 nm-1);
- ``rgb`` (h, w, 3): linear sRGB (D65 white, :data:`XYZ_TO_SRGB`: colour-science's
  ``XYZ_to_sRGB``, which a test checks), same scale;
- ``bands`` {name: (h, w)}: band-mean spectral radiance [W m-2 sr-1 nm-1] over 655-665 and
  725-735 nm (each band is a 10-nm box with 1-nm linear edges, FWHM 10 nm);
- ``r_fr`` (h, w): the red:far-red photon ratio (photon radiance 655-665 / 725-735 nm).

Outputs: :func:`write_exr` (OpenEXR, float32: R, G, B linear sRGB + the bands + R:FR + X, Y, Z),
:func:`to_srgb8` / :func:`write_png` (exposure, filmic shoulder, the sRGB transfer function,
:func:`srgb_encode`) and :func:`rfr_false_colour` (the ratio on a log colour scale with a legend).
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from PIL import Image

from ..atomic import atomic_write
from ..errors import ParameterError

__all__ = ["BANDS", "BAND_WEIGHT", "CMF_FILE", "XYZ_TO_SRGB", "srgb_encode", "band_response",
           "film_dict", "develop", "write_exr", "read_exr", "auto_exposure", "tone_map",
           "to_srgb8", "write_png", "rfr_false_colour", "write_gif", "PLASMA_FILE",
           "RFR_TICKS"]

#: extra spectral bands of every render: name -> (lo, hi) [nm]
BANDS = {"red": (655.0, 665.0), "far_red": (725.0, 735.0)}
#: sensitivity of the band channels (relative to the CMFs' peak ~1): sampling weight
BAND_WEIGHT = 8.0
_WL = np.arange(360.0, 831.0, 1.0)
_CMF_INTEGRAL_Y = None


#: the CIE 1931 2-degree colour matching functions on 360-830 nm (1 nm), shipped as a table so
#: that a render does not import colour-science (a second of start-up)
CMF_FILE = Path(__file__).resolve().parents[1] / "data" / "cie1931_2deg_cmfs.csv"
#: XYZ (D65 white) -> linear sRGB, IEC 61966-2-1 (colour-science's sRGB matrix)
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986],
                        [-0.9689, 1.8758, 0.0415],
                        [0.0557, -0.2040, 1.0570]])
_CMFS = None


def _cmfs():
    global _CMFS
    if _CMFS is None:
        a = np.loadtxt(CMF_FILE, delimiter=",", comments="#", skiprows=4)
        if not np.allclose(a[:, 0], _WL):
            raise ValueError(f"{CMF_FILE}: not 360-830 nm in 1-nm steps")
        _CMFS = np.ascontiguousarray(a[:, 1:].T)
    return _CMFS


def srgb_encode(lin):
    """The sRGB transfer function (IEC 61966-2-1) of linear values in [0, 1].

    Parameters
    ----------
    lin : array_like
        Linear values [-].

    Returns
    -------
    numpy.ndarray
        Encoded values [-].
    """
    x = np.asarray(lin, np.float64)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308),
                                                                   1.0 / 2.4) - 0.055)


def band_response(lo: float, hi: float, height: float = BAND_WEIGHT) -> np.ndarray:
    """A box response on the 1-nm grid (360-830 nm).

    ``height`` inside (lo, hi), half at lo and hi, so that its integral is exactly
    height * (hi - lo) [nm] (Mitsuba interpolates linearly).

    Parameters
    ----------
    lo, hi : float
        Band edges [nm], on the 1-nm grid.
    height : float, optional
        Sensitivity inside the band [-] (default :data:`BAND_WEIGHT`, 8).

    Returns
    -------
    numpy.ndarray
        Response on 360, 361, ..., 830 nm (471 values) [-].
    """
    r = np.where((_WL > lo) & (_WL < hi), height, 0.0)
    r[np.isclose(_WL, lo) | np.isclose(_WL, hi)] = 0.5 * height
    return r


def _regular(v) -> dict:
    return {"type": "regular", "wavelength_min": float(_WL[0]), "wavelength_max": float(_WL[-1]),
            "values": ", ".join(f"{x:.6g}" for x in v)}


def film_dict(options) -> dict:
    """The ``specfilm`` of a render.

    Channels c0_X, c1_Y, c2_Z (CIE 1931 colour matching functions), c3_<band>, ... (the
    :data:`BANDS`) in this order: specfilm sorts channels by name. Float32, Gaussian
    reconstruction filter.

    Parameters
    ----------
    options : RenderOptions
        Gives the image ``width`` and ``height`` [px].

    Returns
    -------
    dict
        The film dict for ``mi.load_dict``.
    """
    xyz = _cmfs()
    d = {"type": "specfilm", "width": int(options.width), "height": int(options.height),
         "component_format": "float32", "rfilter": {"type": "box"}}
    for i, c in enumerate("XYZ"):
        d[f"c{i}_{c}"] = _regular(xyz[i])
    for j, (name, (lo, hi)) in enumerate(BANDS.items()):
        d[f"c{3 + j}_{name}"] = _regular(band_response(lo, hi))
    return d


def develop(tensor) -> dict:
    """Calibrated images from the film tensor (module docstring).

    Parameters
    ----------
    tensor : array_like
        The rendered ``specfilm`` tensor (h, w, 3 + len(BANDS)): channels X, Y, Z, then the bands.

    Returns
    -------
    dict
        ``XYZ`` (h, w, 3): CIE XYZ with Y the ȳ-weighted mean spectral radiance
        [W m-2 sr-1 nm-1]; ``rgb`` (h, w, 3): linear sRGB on the same scale; ``bands``
        {name: (h, w)}: band-mean spectral radiance [W m-2 sr-1 nm-1]; ``r_fr`` (h, w): the
        red:far-red photon ratio [-] (NaN where undefined).

    Raises
    ------
    ParameterError
        If the tensor does not have the shape (h, w, 3 + len(BANDS)).
    """
    a = np.asarray(tensor, np.float64)
    if a.ndim != 3 or a.shape[2] != 3 + len(BANDS):
        raise ParameterError("film tensor", a.shape, f"(h, w, {3 + len(BANDS)})")
    y_int = float(np.trapezoid(_cmfs()[1], _WL))
    XYZ = a[..., :3] / y_int
    rgb = XYZ @ XYZ_TO_SRGB.T
    bands = {}
    for j, (name, (lo, hi)) in enumerate(BANDS.items()):
        bands[name] = a[..., 3 + j] / (BAND_WEIGHT * (hi - lo))
    out = {"XYZ": XYZ, "rgb": rgb, "bands": bands}
    if "red" in bands and "far_red" in bands:
        lr = 0.5 * sum(BANDS["red"])
        lf = 0.5 * sum(BANDS["far_red"])
        with np.errstate(divide="ignore", invalid="ignore"):
            r = (bands["red"] * lr) / (bands["far_red"] * lf)
        out["r_fr"] = np.where(np.isfinite(r), r, np.nan)
    return out


# ---- EXR ---------------------------------------------------------------------------------------
def write_exr(path, images: dict, meta: dict | None = None) -> Path:
    """Write the images as OpenEXR (float32, ZIP compression, written atomically).

    Channels R, G, B (linear sRGB, as rendered), X, Y, Z, the bands (``red_655_665``,
    ``far_red_725_735``: band-mean spectral radiance W m-2 sr-1 nm-1), ``R_FR`` (photon ratio;
    NaN written as 0) and, when the display image differs from the rendered one (denoised),
    ``display.R``, ``display.G``, ``display.B`` (the PNG's linear sRGB before exposure).

    Parameters
    ----------
    path : str or pathlib.Path
        The EXR file.
    images : dict
        From :func:`develop` (``rgb``, ``XYZ``, optional ``bands`` and ``r_fr``).
    meta : dict, optional
        String header attributes (units, time, camera ...).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import OpenEXR

    path = Path(path)
    ch = {}
    rgb = np.asarray(images["rgb"], np.float32)
    for i, c in enumerate("RGB"):
        ch[c] = np.ascontiguousarray(rgb[..., i])
    xyz = np.asarray(images["XYZ"], np.float32)
    for i, c in enumerate("XYZ"):
        ch[c] = np.ascontiguousarray(xyz[..., i])
    disp = images.get("display")
    if disp is not None and disp is not images["rgb"]:
        disp = np.asarray(disp, np.float32)
        for i, c in enumerate("RGB"):
            ch[f"display.{c}"] = np.ascontiguousarray(disp[..., i])
    for name, img in images.get("bands", {}).items():
        lo, hi = BANDS[name]
        ch[f"{name}_{lo:.0f}_{hi:.0f}"] = np.ascontiguousarray(np.asarray(img, np.float32))
    if "r_fr" in images:
        ch["R_FR"] = np.ascontiguousarray(np.nan_to_num(images["r_fr"], nan=0.0)
                                          .astype(np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in (meta or {}).items():
        header[str(k)] = str(v)
    with atomic_write(path) as tmp, OpenEXR.File(header, ch) as f:
        f.write(str(tmp))
    return path


def read_exr(path) -> dict:
    """Channels of an EXR as float32 arrays {name: (h, w)}.

    Parameters
    ----------
    path : str or pathlib.Path
        The EXR file.

    Returns
    -------
    dict
        ``{channel name: numpy.ndarray (h, w)}`` (for :func:`write_exr`'s files: see there for
        the units).
    """
    import OpenEXR
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {k: np.array(v.pixels) for k, v in f.channels().items()}


# ---- display -----------------------------------------------------------------------------------
def auto_exposure(rgb, key: float = 0.18) -> float:
    """Exposure that maps the image's log-average luminance to ``key``.

    Reinhard et al. 2002's "key value": shade and sun both stay readable under :func:`tone_map`'s
    shoulder. Luminances below 1e-4 of the 99th percentile are raised to it before the log mean.

    Parameters
    ----------
    rgb : numpy.ndarray
        Linear sRGB image (h, w, 3) [W m-2 sr-1 nm-1].
    key : float, optional
        Target log-average luminance after exposure [-] (default 0.18).

    Returns
    -------
    float
        The exposure factor [sr nm m2 W-1] (1.0 for an image without positive luminance).
    """
    Y = 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]
    Y = Y[np.isfinite(Y) & (Y > 0)]
    if Y.size == 0:
        return 1.0
    lo = max(float(np.percentile(Y, 99.0)) * 1e-4, 1e-12)
    gm = float(np.exp(np.mean(np.log(np.maximum(Y, lo)))))
    return key / gm if gm > 0 else 1.0


def tone_map(x):
    """Filmic curve (Narkowicz's fit of the ACES reference rendering transform).

    A toe, a nearly linear middle and a soft shoulder that reaches 1 only far above the key, so
    sunlit sand does not clip while the shade keeps its contrast::

        f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14),   clipped to [0, 1]

    Parameters
    ----------
    x : array_like
        Exposed linear values [-] (negative values are set to 0).

    Returns
    -------
    numpy.ndarray
        Display-linear values in [0, 1] [-].
    """
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    return np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def to_srgb8(rgb, exposure: float | None = None) -> tuple[np.ndarray, float]:
    """8-bit sRGB image (h, w, 3) of a linear sRGB image and the exposure used.

    NaN and +inf are set to 0; then exposure, :func:`tone_map` and the sRGB encoding.

    Parameters
    ----------
    rgb : array_like
        Linear sRGB image (h, w, 3) [W m-2 sr-1 nm-1].
    exposure : float, optional
        Exposure factor (default None: :func:`auto_exposure`).

    Returns
    -------
    img8 : numpy.ndarray
        The uint8 image (h, w, 3).
    exposure : float
        The exposure factor used.
    """
    rgb = np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=0.0)
    if exposure is None:
        exposure = auto_exposure(rgb)
    lin = tone_map(rgb * exposure)
    enc = srgb_encode(np.clip(lin, 0.0, 1.0))
    return (np.clip(enc, 0, 1) * 255 + 0.5).astype(np.uint8), float(exposure)


def write_png(path, img8) -> Path:
    """Write an 8-bit image as PNG (atomically).

    Parameters
    ----------
    path : str or pathlib.Path
        The PNG file.
    img8 : array_like
        uint8 image (h, w, 3) (or (h, w)).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = Path(path)
    with atomic_write(path) as tmp:
        Image.fromarray(np.asarray(img8, np.uint8)).save(tmp, optimize=True)
    return path


#: matplotlib's ``plasma`` colour map (CC0), 256 entries of 8-bit sRGB, for the R:FR pictures
PLASMA_FILE = Path(__file__).resolve().parents[1] / "data" / "plasma_colormap.csv"

#: the ratios labelled on the R:FR picture's colour bar (where inside its range)
RFR_TICKS = (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)


@functools.lru_cache(maxsize=1)
def _plasma() -> np.ndarray:
    return np.loadtxt(PLASMA_FILE, delimiter=",", skiprows=3, dtype=np.float64) / 255.0


@functools.lru_cache(maxsize=4)
def _font(size: int):
    from PIL import ImageFont
    return ImageFont.load_default(size=size)


def rfr_false_colour(r_fr, lo: float = 0.05, hi: float = 2.0, title: str | None = None,
                     luminance=None):
    """An RGB uint8 image of the red:far-red ratio on a log scale with a colour bar.

    Low ratios (light filtered or reflected by vegetation) purple-blue, daylight's ~1.15
    yellow-orange (matplotlib's ``plasma`` map, shipped as a table: drawing it needs neither
    matplotlib nor a figure). NaN pixels show as ``lo``; the picture is 125 px wider and 45 px
    taller than the ratio image (colour bar and title).

    Parameters
    ----------
    r_fr : array_like
        Red:far-red photon ratio (h, w) [-].
    lo, hi : float, optional
        Range of the log colour scale [-] (default 0.05 .. 2.0); values outside are clipped.
    title : str, optional
        A title at the top left.
    luminance : array_like, optional
        Luminance (h, w) (e.g. the Y image) that shades the colours so that shapes stay readable.

    Returns
    -------
    numpy.ndarray
        The picture (h + 45, w + 125, 3), uint8.
    """
    from PIL import ImageDraw

    if not (0 < lo < hi):
        raise ValueError(f"rfr_false_colour: lo={lo}, hi={hi}: need 0 < lo < hi")
    lut = _plasma()
    r = np.asarray(r_fr, np.float64)
    h, w = r.shape

    def to_unit(x):             # the log scale, 0 at lo, 1 at hi
        return (np.log(x) - np.log(lo)) / (np.log(hi) - np.log(lo))

    u = to_unit(np.clip(np.nan_to_num(r, nan=lo, posinf=hi, neginf=lo), lo, hi))
    rgb = lut[np.clip(np.rint(u * 255), 0, 255).astype(np.int64)]
    if luminance is not None:
        L = np.asarray(luminance, np.float64)
        ref = np.percentile(L[np.isfinite(L)], 99) if np.isfinite(L).any() else 1.0
        shade = np.clip(np.nan_to_num(L) / max(ref, 1e-12), 0, 1) ** 0.4
        rgb = rgb * (0.35 + 0.65 * shade)[..., None]
    W, H, top = w + 125, h + 45, 45
    canvas = Image.new("RGB", (W, H), (255, 255, 255))
    canvas.paste(Image.fromarray((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)), (0, top))
    draw = ImageDraw.Draw(canvas)
    # the colour bar: 12 px wide beside the image, over 75 % of the picture's height
    x0, bw = w + 12, 12
    y0, y1 = top + int(0.1 * h), top + int(0.9 * h)
    t = np.linspace(1.0, 0.0, max(y1 - y0, 2))
    bar = lut[np.clip(np.rint(t * 255), 0, 255).astype(np.int64)]
    canvas.paste(Image.fromarray((np.repeat(bar[:, None], bw, 1) * 255 + 0.5).astype(np.uint8)),
                 (x0, y0))
    draw.rectangle([x0 - 1, y0 - 1, x0 + bw, y0 + len(t)], outline=(0, 0, 0))
    font = _font(10)
    for v in RFR_TICKS:
        if lo <= v <= hi:
            y = y1 - 1 - to_unit(v) * (len(t) - 1)
            draw.line([x0 + bw, y, x0 + bw + 3, y], fill=(0, 0, 0))
            draw.text((x0 + bw + 7, y), f"{v:g}", fill=(0, 0, 0), font=font, anchor="lm")
    # the bar's label, along it (drawn horizontally, turned a quarter)
    label = "red : far-red (photons 655-665 / 725-735 nm)"
    lf = _font(10)
    box = draw.textbbox((0, 0), label, font=lf)
    tw, th = box[2] - box[0] + 2, box[3] - box[1] + 4
    strip = Image.new("RGB", (tw, th), (255, 255, 255))
    ImageDraw.Draw(strip).text((1 - box[0], 2 - box[1]), label, fill=(0, 0, 0), font=lf)
    strip = strip.rotate(90, expand=True)
    if strip.height > H:                # a small picture: the label shrinks with it
        strip = strip.resize((strip.width, H), Image.LANCZOS)
    canvas.paste(strip, (min(W - strip.width - 2, x0 + bw + 38),
                         max(0, (y0 + y1) // 2 - strip.height // 2)))
    if title:
        draw.text((6, top // 2), title, fill=(0, 0, 0), font=_font(13), anchor="lm")
    return np.asarray(canvas)


def write_gif(frames: list, path: Path, fps: int, width: int | None = None) -> Path:
    """An animated GIF of PNG frames (the last frame held 1.5 s).

    Parameters
    ----------
    frames : list of path-like
        The frames in order.
    path : Path
        The GIF (written atomically).
    fps : int
        Frames per second.
    width : int, optional
        Downscale to this width [pixels].

    Returns
    -------
    Path
        ``path``.
    """
    imgs = []
    for f in frames:
        im = Image.open(f).convert("RGB")
        if width and im.size[0] > width:
            im = im.resize((width, round(im.size[1] * width / im.size[0])), Image.LANCZOS)
        imgs.append(im.convert("P", palette=Image.ADAPTIVE, colors=255))
    durations = [int(1000 / fps)] * len(imgs)
    if durations:
        durations[-1] = 1500      # hold the last day
    with atomic_write(path) as tmp:
        imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=durations, loop=0,
                     optimize=True)
    return path
