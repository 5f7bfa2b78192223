"""How an image can be right in its light transport and wrong in how it was written.

A renderer can compute every ray right and still write a file the check
reads as other light: linear values written where the file holds sRGB codes,
a gamma of 2.2 for the sRGB curve, channels in BGR order, rows from the
bottom, pixels sampled at their corners. Each such *convention* is a
hypothesis about the writer: a map from the scene's light L (the reference)
to the values the check reads back from the file, ``predict``. Under it, an
image made by a correct renderer is ``predict(reference)`` plus the
renderer's noise; :func:`reference.check.suspects.name_cause` judges that
residual with the check's own rules, as it judges the catalog's formula bugs,
and names the hypothesis only when what it leaves is at the noise
(``docs/check.md``, "Naming the cause").

The file's own encoding (:class:`FileEncoding`) is what the check assumed:
an 8-bit PNG or PPM read as sRGB codes (``--encoding srgb``), as linear codes,
as minray's 255 x linear, or a float file read as linear light. The
conventions (:data:`CONVENTIONS`):

* transfer curve: none where the file wants sRGB, sRGB where it wants
  linear light, a pure power 1/1.8, 1/2.2 or 1/2.4 (IEC 61966-2-1's curve is a
  power of 1/2.4 with a linear toe, close to 1/2.2 overall), the sRGB curve
  applied twice, its inverse applied instead, a global exposure scale
  (fitted), values clamped at 1 in a float file, Reinhard's L / (1 + L)
  ("Photographic tone reproduction for digital images", SIGGRAPH 2002, eq. 3);
* channel order: BGR (OpenCV's order), red and green swapped, green and blue
  swapped;
* orientation: upside down, mirrored left to right, both (rotated 180
  degrees), and a column-major buffer written as rows (transposed);
* pixel grid: pixel corners sampled instead of centres (half a pixel off, in
  either diagonal: the exact box integral over the shifted pixel, from the
  tracer's render at twice the resolution), and a one-pixel shift (an
  off-by-one loop bound);
* quantisation: 8-bit codes truncated instead of rounded (half a code low on
  average under noise);
* alpha: colours premultiplied by the file's alpha (Porter and Duff,
  "Compositing Digital Images", SIGGRAPH 1984): a renderer that writes alpha 0
  or partial alpha where rays miss or at edges and stores alpha x colour, so
  the check reads A L. Tried only where the file has an alpha channel with
  alpha < 1 somewhere (``UserImage.alpha``, read by ``reference.check.images``).
  The premultiplication is modelled on linear light, before the file's curve:
  an 8-bit sRGB PNG holds ``round(255 srgb(A L))``, not ``A round(255 srgb(L))``,
  since compositing is linear in light and renderers (and OpenEXR, whose
  colours are premultiplied linear values) multiply their linear buffer
  before encoding it. The alpha the prediction uses is the file's own, after
  its rounding (1/255 for 8-bit PNG: under an sRGB code's own step wherever
  alpha > 0.2).

Besides the named curves, :func:`monotone_fit` fits any monotone curve per
channel (isotonic regression by pool-adjacent-violators over quantile bins
of the reference, weighted by the noise): where that leaves the noise, the
light transport agrees and only the output encoding differs, whichever curve
it is; the fitted curve is drawn by :func:`plot_curve` (``curve.png``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from whitted.reference.check.images import srgb_decode

#: The sRGB curve's source.
SRGB_SOURCE = ("IEC 61966-2-1:1999, sRGB, section 5.2: V = 12.92 L for L <= 0.0031308, "
               "else 1.055 L^(1/2.4) - 0.055")
PNG_SOURCE = "PNG (ISO/IEC 15948:2004), 8-bit samples; IEC 61966-2-1 for their meaning"
ROWS_SOURCE = ("PNG (ISO/IEC 15948:2004) section 4.5.2, PPM (netpbm): rows top to bottom, "
               "pixels left to right, samples in R, G, B order")
GRID_SOURCE = ("pbrt-v4 section 5.4 (Pharr, Jakob, Humphreys): pixel (x, y) covers "
               "[x, x + 1) x [y, y + 1); its centre is (x + 1/2, y + 1/2)")
ALPHA_SOURCE = ("Porter and Duff, \"Compositing Digital Images\", SIGGRAPH 1984, section 2: "
                "a premultiplied pixel stores (A R, A G, A B, A); PNG (ISO/IEC 15948:2004) "
                "section 12.4 stores alpha straight (not premultiplied)")
REINHARD_SOURCE = ("Reinhard, Stark, Shirley, Ferwerda, \"Photographic tone reproduction "
                   "for digital images\", SIGGRAPH 2002, eq. 3")


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """The sRGB curve (IEC 61966-2-1), extended as a line below 0 and a power above 1."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.0031308, 12.92 * x,
                    1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)


def _power(x: np.ndarray, p: float) -> np.ndarray:
    return np.sign(x) * np.abs(x) ** p


@dataclass(frozen=True)
class FileEncoding:
    """How the check read the file: ``srgb``, ``linear`` or ``minray`` codes, or ``float``."""
    name: str
    #: the largest code of an integer file, None for float files
    maxval: int | None
    #: the level the writer clips to (1 for sRGB and linear codes), or None
    clip: float | None

    @property
    def integer(self) -> bool:
        return self.maxval is not None

    def encode(self, x: np.ndarray) -> np.ndarray:
        """Linear light to the file's value (a code / maxval for integer files)."""
        return srgb_encode(x) if self.name == "srgb" else np.asarray(x, dtype=np.float64)

    def decode(self, e: np.ndarray) -> np.ndarray:
        return srgb_decode(e) if self.name == "srgb" else np.asarray(e, dtype=np.float64)

    def written(self, curve: str) -> str:
        """A formula as the writer applies it: ``code = round(255 * curve)``, ``value = curve``."""
        if self.integer:
            scale = 255 if self.name == "minray" else self.maxval
            return f"code = round({scale} * {curve})"
        return f"value = {curve}"

    @property
    def curve(self) -> str:
        return "srgb(L)" if self.name == "srgb" else "L"

    def read(self, e: np.ndarray) -> np.ndarray:
        """What the check reads back from file values ``e`` (clipped as an integer file is)."""
        e = np.asarray(e, dtype=np.float64)
        if self.clip is not None:
            e = np.clip(e, 0.0, self.clip)
        return self.decode(e)


def file_encoding(user) -> FileEncoding:
    """The :class:`FileEncoding` of a :class:`~reference.check.images.UserImage`."""
    if user.encoding is None:
        return FileEncoding("float", None, None)
    maxval = 255
    if "16-bit" in user.storage:
        maxval = 65535
    return FileEncoding(user.encoding, maxval, user.clip)


@dataclass(frozen=True)
class Convention:
    """One way of writing a right image wrongly (module docstring)."""
    id: str
    #: "transfer curve", "channel order", "orientation", "pixel grid" or "quantisation"
    kind: str
    #: in words, as the verdict says it ("it looks like ...")
    summary: str
    #: the formula as the writer computes it, and as it should (``enc`` fills them in)
    formula: Callable[[FileEncoding], str]
    correct: Callable[[FileEncoding], str]
    source: str
    #: file values from linear light, for the pixelwise conventions (params from ``fit``)
    write: Callable[[np.ndarray, FileEncoding, dict], np.ndarray] | None = None
    #: an H x W x 3 array moved as the writer moved it (channels, rows, pixels), with a mask
    #: of the pixels it cannot know (H x W, True: unknown), for the spatial conventions
    move: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None]] | None = None
    #: the inverse of ``move``: the user's image moved back, judged against the reference
    #: itself (its noise then varies slowly again, as the local estimate assumes)
    unmove: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None]] | None = None
    #: half-pixel shifts: (dx, dy) of the pixel's centre, read from a render at twice the size
    half_shift: tuple[float, float] | None = None
    #: whether it is a mistake at all for this file (sRGB curve missing needs an sRGB file)
    applies: Callable[[FileEncoding], bool] = lambda enc: True
    #: fitted parameters: (user image, reference, weights, valid, enc) -> params
    fit: Callable | None = None
    #: the number of fitted parameters
    parameters: int = 0
    #: catalog bugs that make this very image (tied with it whenever both are at the noise)
    same_as: tuple[str, ...] = ()
    #: whether ``write`` needs the file's alpha (``params["alpha"]``, H x W x 1); tried only
    #: where the file has one with alpha < 1 somewhere
    uses_alpha: bool = False


def _curve(fn: Callable[[np.ndarray, dict], np.ndarray]):
    return lambda x, enc, p: fn(x, p)


def _exposure_fit(u, r, w, valid, enc) -> dict:
    """s of u ~ s r (linear light), weighted least squares over values below the clip."""
    m = valid[..., None] & np.isfinite(u) & (w > 0)
    if enc.clip is not None:
        m &= (u < 0.98 * enc.clip) & (r > 0)
    sxx = float((w * r * r)[m].sum())
    s = float((w * r * u)[m].sum()) / sxx if sxx > 0 else 1.0
    return {"s": s if s > 0 else 1.0}


def _swap(i: int, j: int):
    def move(a):
        b = np.array(a, copy=True)
        b[..., [i, j]] = a[..., [j, i]]
        return b, None
    return move


def _shift(dx: int, dy: int):
    """Pixel (x, y) shows the light of pixel (x + dx, y + dy); what falls outside is unknown."""
    def move(a):
        h, w = a.shape[:2]
        b = np.zeros_like(a)
        unknown = np.ones((h, w), dtype=bool)
        ys = slice(max(0, -dy), min(h, h - dy))
        xs = slice(max(0, -dx), min(w, w - dx))
        yr = slice(ys.start + dy, ys.stop + dy)
        xr = slice(xs.start + dx, xs.stop + dx)
        b[ys, xs] = a[yr, xr]
        unknown[ys, xs] = False
        return b, unknown
    return move


def _untransposed(a):
    h, w = a.shape[:2]
    return np.ascontiguousarray(a.reshape(w, h, a.shape[2]).transpose(1, 0, 2)), None


def _transposed(a):
    """A column-major H x W buffer written out as rows: the file's pixels run down columns."""
    h, w = a.shape[:2]
    return np.ascontiguousarray(a.transpose(1, 0, 2)).reshape(h, w, a.shape[2]), None


def _encoded(enc: FileEncoding) -> str:
    return enc.written(enc.curve)


def _fixed(text: str) -> Callable[[FileEncoding], str]:
    return lambda enc: text


_right_rows = _fixed("file row y holds image row y from the top, pixel x from the left, "
                     "channels R, G, B")

CONVENTIONS: tuple[Convention, ...] = (
    Convention("no-srgb-curve", "transfer curve", "no sRGB curve: linear values written "
               "straight into the file's codes",
               lambda enc: enc.written("L"), _encoded, SRGB_SOURCE,
               write=_curve(lambda x, p: x), applies=lambda enc: enc.name == "srgb"),
    Convention("srgb-in-linear-file", "transfer curve", "sRGB-encoded values in a file "
               "read as linear light", lambda enc: enc.written("srgb(L)"), _encoded,
               SRGB_SOURCE, write=_curve(lambda x, p: srgb_encode(x)),
               applies=lambda enc: enc.name != "srgb"),
    *(Convention(f"gamma-{g}", "transfer curve", f"a pure gamma of {g} instead of the "
                 "file's curve", lambda enc, g=g: enc.written(f"L^(1/{g})"), _encoded,
                 SRGB_SOURCE, write=_curve(lambda x, p, g=g: _power(x, 1 / g)))
      for g in (1.8, 2.2, 2.4)),
    Convention("srgb-curve-twice", "transfer curve", "the sRGB curve applied twice",
               lambda enc: enc.written("srgb(srgb(L))"), _encoded, SRGB_SOURCE,
               write=_curve(lambda x, p: srgb_encode(srgb_encode(x))),
               applies=lambda enc: enc.name == "srgb"),
    Convention("srgb-inverse-curve", "transfer curve", "the inverse of the sRGB curve "
               "applied (decoding instead of encoding)",
               lambda enc: enc.written("srgb^-1(L)"), _encoded, SRGB_SOURCE,
               write=_curve(lambda x, p: srgb_decode(np.maximum(x, 0)))),
    Convention("exposure-scale", "transfer curve", "a global exposure scale",
               lambda enc: enc.written("encode(s L)"), _encoded,
               "the scene's light as rendered (no exposure: the film records radiance)",
               write=lambda x, enc, p: enc.encode(p["s"] * x), fit=_exposure_fit,
               parameters=1),
    Convention("clamped-at-one", "transfer curve", "values clamped at 1 in a float file",
               lambda enc: enc.written("min(L, 1)"), _encoded,
               "OpenEXR (ILM): float values keep light above 1",
               write=_curve(lambda x, p: np.minimum(x, 1.0)),
               applies=lambda enc: not enc.integer),
    Convention("reinhard-tone-map", "transfer curve", "Reinhard's tone map L / (1 + L) "
               "before the file's curve", lambda enc: enc.written(
                   "srgb(L / (1 + L))" if enc.name == "srgb" else "L / (1 + L)"),
               _encoded, REINHARD_SOURCE,
               write=lambda x, enc, p: enc.encode(x / (1 + np.maximum(x, 0)))),
    Convention("bgr-order", "channel order", "channels in BGR order",
               _fixed("file channels B, G, R"), _right_rows, ROWS_SOURCE,
               move=_swap(0, 2), unmove=_swap(0, 2)),
    Convention("red-green-swapped", "channel order", "red and green swapped",
               _fixed("file channels G, R, B"), _right_rows, ROWS_SOURCE,
               move=_swap(0, 1), unmove=_swap(0, 1)),
    Convention("green-blue-swapped", "channel order", "green and blue swapped",
               _fixed("file channels R, B, G"), _right_rows, ROWS_SOURCE,
               move=_swap(1, 2), unmove=_swap(1, 2)),
    Convention("upside-down", "orientation", "the image upside down (rows written from the "
               "bottom)", _fixed("file row y holds image row H - 1 - y"), _right_rows,
               ROWS_SOURCE, move=lambda a: (a[::-1].copy(), None),
               unmove=lambda a: (a[::-1].copy(), None), same_as=("camera-y-not-flipped",)),
    Convention("mirrored", "orientation", "the image mirrored left to right",
               _fixed("file pixel x holds image pixel W - 1 - x"), _right_rows, ROWS_SOURCE,
               move=lambda a: (a[:, ::-1].copy(), None),
               unmove=lambda a: (a[:, ::-1].copy(), None)),
    Convention("rotated-180", "orientation", "the image rotated by 180 degrees",
               _fixed("file pixel (x, y) holds image pixel (W - 1 - x, H - 1 - y)"),
               _right_rows, ROWS_SOURCE, move=lambda a: (a[::-1, ::-1].copy(), None),
               unmove=lambda a: (a[::-1, ::-1].copy(), None)),
    Convention("transposed", "orientation", "a column-major buffer written as rows "
               "(transposed)", _fixed("file pixel i (row-major) holds image[i mod H][i div H]"),
               _right_rows, ROWS_SOURCE, move=_transposed, unmove=_untransposed),
    *(Convention(f"pixel-corners-{name}", "pixel grid", f"pixel corners sampled instead of "
                 f"centres (the image half a pixel off, {words})",
                 lambda enc, sx=sx, sy=sy: f"ray through (x {sx} 1/2, y {sy} 1/2) + jitter",
                 _fixed("ray through (x + 1/2, y + 1/2) + jitter in the pixel"), GRID_SOURCE,
                 half_shift=(dx, dy))
      for name, words, dx, dy, sx, sy in (
          ("top-left", "towards the top left", -0.5, -0.5, "+ 0 -", "+ 0 -"),
          ("bottom-left", "towards the bottom left", -0.5, 0.5, "+ 0 -", "+ 1 -"),
          ("top-right", "towards the top right", 0.5, -0.5, "+ 1 -", "+ 0 -"),
          ("bottom-right", "towards the bottom right", 0.5, 0.5, "+ 1 -", "+ 1 -"))),
    *(Convention(f"one-pixel-{name}", "pixel grid", f"the image one pixel off ({name}: an "
                 "off-by-one in the pixel loop)",
                 lambda enc, dx=dx, dy=dy: f"file pixel (x, y) holds image pixel "
                                           f"(x {dx:+d}, y {dy:+d})",
                 _fixed("file pixel (x, y) holds image pixel (x, y)"), GRID_SOURCE,
                 move=_shift(dx, dy), unmove=_shift(-dx, -dy))
      for name, dx, dy in (("left", 1, 0), ("right", -1, 0), ("up", 0, 1), ("down", 0, -1))),
    Convention("truncated-codes", "quantisation", "codes truncated instead of rounded",
               lambda enc: enc.written(enc.curve).replace("round(", "floor("), _encoded,
               PNG_SOURCE + "; rounding to the nearest code",
               write=lambda x, enc, p: enc.encode(x) - 0.5 / enc.maxval,
               applies=lambda enc: enc.integer),
    Convention("premultiplied-alpha", "alpha", "premultiplied alpha: colours multiplied by "
               "the file's alpha (alpha < 1 where rays miss or at edges)",
               lambda enc: enc.written("srgb(A L)" if enc.name == "srgb" else "A L"),
               lambda enc: _encoded(enc) + " with A = 1, or the colours not multiplied by A "
               "(the film's pixel holds all its light)", ALPHA_SOURCE,
               write=lambda x, enc, p: enc.encode(p["alpha"] * x), uses_alpha=True),
)

#: The generic curve: not a named convention but a monotone fit (:func:`monotone_fit`).
MONOTONE = Convention(
    "monotone-curve", "transfer curve", "an output curve none of the named ones (fitted: "
    "see curve.png)", lambda enc: enc.written("f(L), f monotone (fitted)"), _encoded,
    SRGB_SOURCE)


def get(cid: str) -> Convention:
    for c in (*CONVENTIONS, MONOTONE):
        if c.id == cid:
            return c
    raise KeyError(cid)


# ---------------------------------------------------------------- predictions


@dataclass
class Prediction:
    """What the check would read from a correct render written under a convention."""
    convention: Convention
    #: H x W x 3 linear light as the check reads it back
    image: np.ndarray
    #: the reference's variance, spread and quadrature carried through the same map
    variance: np.ndarray | None
    spread: np.ndarray | None
    quadrature: np.ndarray | None
    #: H x W: pixels the convention cannot predict (left out of its judgement)
    unknown: np.ndarray | None = None
    params: dict | None = None
    formula: str = ""
    correct: str = ""


def _through(f, x, s):
    """Half the spread of f over x +- s (a standard deviation carried through f)."""
    return np.abs(f(x + s) - f(np.maximum(x - s, 0))) / 2


def predict(conv: Convention, enc: FileEncoding, ref, user_image: np.ndarray,
            weights: np.ndarray, valid: np.ndarray, fine: Callable[[], np.ndarray] | None,
            alpha: np.ndarray | None = None) -> Prediction | None:
    """The image a correct renderer writes under ``conv`` (None where it does not apply).

    ``ref`` is the check's :class:`~reference.check.judge.Reference`; ``fine``
    returns the tracer's image at twice the film's size (for half-pixel shifts);
    ``alpha`` the file's alpha (H x W), for the conventions that use it.
    """
    if not conv.applies(enc):
        return None
    if conv.uses_alpha and (alpha is None or not (np.asarray(alpha) < 1).any()):
        return None
    r = np.asarray(ref.image, dtype=np.float64)
    var = ref.variance
    spread, quad = ref.spread, ref.quadrature
    unknown = None
    params: dict = {}
    if conv.move is not None:
        r, unknown = conv.move(r)
        var = None if var is None else conv.move(var)[0]
        spread = None if spread is None else conv.move(spread)[0]
        quad = None if quad is None else conv.move(quad)[0]
        image = r
    elif conv.half_shift is not None:
        if fine is None:
            return None
        image, unknown = _half_shifted(fine(), conv.half_shift)
        grow = lambda a: None if a is None else _neighbourhood_max(a)  # noqa: E731
        # the fine render is one seed: its variance is the seeds' mean's times their number
        var = None if var is None else var * max(ref.seeds, 1)
        spread, quad = grow(spread), grow(quad)
    else:
        if conv.fit is not None:
            params = conv.fit(user_image, r, weights, valid, enc)
        given = dict(params)        # the alpha plane stays out of the reported params
        if conv.uses_alpha:
            given["alpha"] = np.asarray(alpha, dtype=np.float64)[..., None]

        def f(x):
            return enc.read(conv.write(x, enc, given))
        image = f(r)
        var = None if var is None else _through(f, r, np.sqrt(var)) ** 2
        spread = None if spread is None else _through(f, r, np.sqrt(spread)) ** 2
        quad = None if quad is None else np.abs(f(r + quad) - image)
    return Prediction(conv, image, var, spread, quad, unknown, params,
                      conv.formula(enc), conv.correct(enc))


def _half_shifted(fine: np.ndarray, shift: tuple[float, float]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's box moved by (dx, dy) = (+-1/2, +-1/2) pixel, from a render at twice the size.

    The moved box [x + dx, x + dx + 1) covers the fine pixels 2 x + 2 dx and the
    next; their mean is the box integral (at the fine render's strata).
    """
    h2, w2 = fine.shape[:2]
    h, w = h2 // 2, w2 // 2
    ox, oy = int(round(2 * shift[0])), int(round(2 * shift[1]))
    pad = np.zeros((h2 + 4, w2 + 4, fine.shape[2]))
    known = np.zeros((h2 + 4, w2 + 4), dtype=bool)
    pad[2:-2, 2:-2] = fine
    known[2:-2, 2:-2] = True
    ys, xs = 2 + oy, 2 + ox
    out = np.zeros((h, w, fine.shape[2]))
    ok = np.ones((h, w), dtype=bool)
    for a in (0, 1):
        for b in (0, 1):
            out += pad[ys + a:ys + a + h2:2, xs + b:xs + b + w2:2]
            ok &= known[ys + a:ys + a + h2:2, xs + b:xs + b + w2:2]
    return out / 4, ~ok


def _neighbourhood_max(a: np.ndarray) -> np.ndarray:
    """The largest value over each pixel's 3 x 3 neighbourhood (edges move by half a pixel)."""
    p = np.pad(a, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = a.shape[:2]
    return np.max([p[y:y + h, x:x + w] for y in range(3) for x in range(3)], axis=0)


# ---------------------------------------------------------------- any monotone curve


#: Quantile bins per channel of the monotone fit (at most; at least 20 values a bin).
MONOTONE_BINS = 256


@dataclass
class MonotoneFit:
    #: per channel: the reference's light at the bins' weighted centres, and the curve there
    x: list[np.ndarray]
    y: list[np.ndarray]
    #: pieces of the fitted curve (its parameters, for a penalised comparison)
    pieces: int


def _pava(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted isotonic (non-decreasing) regression by pool-adjacent-violators."""
    means, weights, counts = [], [], []
    for yi, wi in zip(y.tolist(), w.tolist(), strict=True):
        means.append(yi)
        weights.append(wi)
        counts.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            wt = weights[-2] + weights[-1]
            m = (means[-2] * weights[-2] + means[-1] * weights[-1]) / wt if wt > 0 else \
                (means[-2] + means[-1]) / 2
            c = counts[-2] + counts[-1]
            means[-2:], weights[-2:], counts[-2:] = [m], [wt], [c]
    return np.repeat(means, counts)


def monotone_fit(user_image: np.ndarray, reference: np.ndarray, weights: np.ndarray,
                 valid: np.ndarray) -> tuple[np.ndarray, MonotoneFit]:
    """u ~ f_c(r) per channel c, f_c non-decreasing: (f(reference), the fitted curves).

    The reference's values are cut into quantile bins (:data:`MONOTONE_BINS`;
    equal values stay in one bin), the user's values averaged in each with the
    noise's weights, and the means made non-decreasing (pool-adjacent-violators;
    Barlow et al., "Statistical inference under order restrictions", 1972); f
    is linear between the bins' centres and constant beyond.
    """
    u = np.asarray(user_image, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    out = np.array(r, copy=True)
    xs, ys, pieces = [], [], 0
    for c in range(r.shape[-1]):
        m = valid & np.isfinite(u[..., c]) & (weights[..., c] > 0)
        rv, uv, wv = r[..., c][m], u[..., c][m], weights[..., c][m]
        if rv.size < 2:
            xs.append(np.array([0.0, 1.0]))
            ys.append(np.array([0.0, 1.0]))
            continue
        order = np.argsort(rv, kind="stable")
        rv, uv, wv = rv[order], uv[order], wv[order]
        bins = max(2, min(MONOTONE_BINS, rv.size // 20))
        edges = np.unique(rv[np.linspace(0, rv.size - 1, bins + 1).astype(int)])
        idx = np.clip(np.searchsorted(edges, rv, side="right") - 1, 0, max(len(edges) - 2, 0))
        n = int(idx.max()) + 1
        sw = np.bincount(idx, wv, n)
        keep = sw > 0
        cx = np.bincount(idx, wv * rv, n)[keep] / sw[keep]
        cy = np.bincount(idx, wv * uv, n)[keep] / sw[keep]
        fy = _pava(cy, sw[keep])
        pieces += len(np.unique(fy))
        if cx.size > 1:   # beyond the outer bins' centres: their segments' slopes, not flat
            lo = fy[0] - (fy[1] - fy[0]) / max(cx[1] - cx[0], 1e-300) * (cx[0] - rv[0])
            hi = fy[-1] + (fy[-1] - fy[-2]) / max(cx[-1] - cx[-2], 1e-300) * (rv[-1] - cx[-1])
            cx = np.concatenate([[rv[0]], cx, [rv[-1]]])
            fy = np.concatenate([[min(lo, fy[0])], fy, [max(hi, fy[-1])]])
        xs.append(cx)
        ys.append(fy)
        out[..., c] = np.interp(r[..., c], cx, fy)
    return out, MonotoneFit(xs, ys, pieces)


def plot_curve(fit: MonotoneFit, enc: FileEncoding, path, named: Prediction | None = None,
               samples: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """curve.png: the user's values against the reference's, with the fitted curve.

    Both axes in the file's own encoding (sRGB codes / maxval for an sRGB file):
    a right image lies on the diagonal; ``named`` adds the named curve that
    explains it, ``samples`` (reference, image) a scatter of pixels.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def axis(v):
        v = np.asarray(v, dtype=np.float64)
        return enc.encode(np.maximum(v, 0)) if enc.name == "srgb" else v

    colours = ("#d62728", "#2ca02c", "#1f77b4")
    fig, ax = plt.subplots(figsize=(4.2, 4.0), dpi=100)
    top = 0.0
    if samples is not None:
        rr, uu = samples
        rng = np.random.default_rng(0)
        for c in range(3):
            a, b = rr[..., c].ravel(), uu[..., c].ravel()
            ok = np.isfinite(a) & np.isfinite(b)
            a, b = a[ok], b[ok]
            pick = rng.choice(a.size, min(a.size, 1500), replace=False) if a.size else []
            ax.scatter(axis(a[pick]), axis(b[pick]), s=2, alpha=0.25, color=colours[c],
                       linewidths=0)
    for c in range(3):
        ax.plot(axis(fit.x[c]), axis(fit.y[c]), color=colours[c], lw=1.5,
                label="fitted " + "RGB"[c])
        top = max(top, float(np.max(axis(fit.x[c]), initial=0)),
                  float(np.max(axis(fit.y[c]), initial=0)))
    top = top or 1.0
    grid = np.linspace(0, top, 200)
    lin = enc.decode(grid) if enc.name == "srgb" else grid
    ax.plot(grid, grid, color="#888", lw=1, ls=":", label="right (image = reference)")
    if named is not None and named.convention.write is not None and \
            not named.convention.uses_alpha:     # per pixel, not one curve
        p = named.params or {}
        y = axis(enc.read(named.convention.write(lin, enc, p)))
        ax.plot(grid, y, color="black", lw=1, ls="--", label=named.convention.id)
    unit = "sRGB code / max" if enc.name == "srgb" else "linear value"
    ax.set_xlabel(f"reference ({unit})")
    ax.set_ylabel(f"your image ({unit})")
    ax.set_xlim(0, top * 1.02)
    ax.set_ylim(0, top * 1.02)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("your values against the reference's", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------- students' files


def write_as(conv: Convention | None, linear: np.ndarray, enc: FileEncoding,
             params: dict | None = None, fine: np.ndarray | None = None,
             truncate: bool = False, alpha: np.ndarray | None = None):
    """The :class:`~reference.check.images.UserImage` the check reads from a render written
    under ``conv`` (None: written right) into a file of encoding ``enc``.

    For the tests and the calibration (``benchmarks/bench_suspects.py``): ``linear``
    is the renderer's image, ``fine`` its render at twice the size (half-pixel
    shifts). Integer files are rounded (truncated for ``truncated-codes``). ``alpha``
    (H x W) is the file's alpha channel, stored as the file stores it; for
    ``premultiplied-alpha`` without one, a ramp from 1 at the left to 1/4 at the right.
    """
    from pathlib import Path

    from whitted.reference.check.images import UserImage, _integer_image

    x = np.asarray(linear, dtype=np.float64)
    p = dict(params or {"s": 0.5})
    if alpha is None and conv is not None and conv.uses_alpha:
        alpha = np.broadcast_to(np.linspace(1.0, 0.25, x.shape[1]), x.shape[:2])
    if alpha is not None:
        alpha = np.clip(np.asarray(alpha, dtype=np.float64), 0.0, 1.0)
        if enc.integer:         # the alpha the file stores, which the writer multiplied by
            alpha = np.round(alpha * enc.maxval) / enc.maxval
        p["alpha"] = alpha[..., None]
    if conv is not None and conv.move is not None:
        x, unknown = conv.move(x)
        if unknown is not None:     # the writer's own pixels there: the nearest known ones
            x = _fill(x, unknown)
    elif conv is not None and conv.half_shift is not None:
        x, unknown = _half_shifted(fine, conv.half_shift)
        x = _fill(x, unknown)
    if conv is not None and conv.write is not None:
        e = conv.write(x, enc, p)
        truncate = truncate or conv.id == "truncated-codes"
        if conv.id == "truncated-codes":
            e = enc.encode(x)
    else:
        e = enc.encode(x)
    if not enc.integer:
        return UserImage("<written>", "exr", "float32", e.astype(np.float32).astype(np.float64),
                         alpha=alpha)
    scale = 255 if enc.name == "minray" else enc.maxval
    v = np.maximum(e, 0) * scale
    if enc.clip is not None:
        v = np.minimum(v, scale * enc.clip)
    codes = (np.floor(v) if truncate else np.round(v)).astype(np.int64)
    img = _integer_image(Path("<written>"), "png", codes, enc.maxval, enc.name,
                         "16-bit" if enc.maxval > 255 else "8-bit", [])
    img.alpha = alpha
    return img


def _fill(x: np.ndarray, unknown: np.ndarray) -> np.ndarray:
    """Unknown pixels from their nearest known row or column (edge replication)."""
    x = np.array(x, copy=True)
    if not unknown.any():
        return x
    h, w = unknown.shape
    rows = np.where(~unknown.all(axis=1))[0]
    cols = np.where(~unknown.all(axis=0))[0]
    yi = rows[np.abs(np.arange(h)[:, None] - rows[None, :]).argmin(1)]
    xi = cols[np.abs(np.arange(w)[:, None] - cols[None, :]).argmin(1)]
    src = x[yi][:, xi]
    return np.where(unknown[..., None], src, x)
