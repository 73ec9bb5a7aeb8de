"""Pictures of tensor fields a person can read: orientation, coherence and the HSV composite.

Conventions (ALGORITHMS.md, "Rendering"):

- **orientation** images map an angle in ``(-pi/2, pi/2]`` to a cyclic hue,
  ``hue = (theta + pi/2) / pi``: -90 and +90 degrees (the same orientation) are both red, 0 is cyan,
  +45 violet and -45 yellow-green, with no seam at the wrap;
- **coherence** images are grey, 0 black and 1 white;
- the **composite** is HSV with hue = orientation, saturation = coherence and value = the image (the
  OrientationJ "colour survey").

Which angle? The functions colour whatever angle they are given, but the legends are labelled
**fringe direction**, and the project passes :func:`texsynth.synth.analysis.tensor.structure_direction` (the
direction fringes and laminae run, as OrientationJ and materials tools show it), not the gradient direction of
:func:`texsynth.synth.analysis.tensor.orientation`, which is 90 degrees away. A caller showing something else
says so with ``title=``. Angles are counter-clockwise from +x with ``y`` up on screen, so the half-disc in the
orientation legend is a true picture: the ray at +45 degrees points up-right and wears the colour of
fringes running up-right.

Every rendering ships with its legend (``legend=True`` or :func:`with_legend`): a palette strip with
ticks and labels drawn below the image (Pillow's default font), the image padded on the right with
white when it is narrower than the legend. All functions are vectorised and return ``uint8``.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Literal

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidParameter

__all__ = [
    "LEGEND_KINDS",
    "LegendKind",
    "coherence_image",
    "composite_image",
    "legend_shape",
    "orientation_hue",
    "orientation_image",
    "with_legend",
]

LegendKind = Literal["orientation", "coherence", "composite"]
LEGEND_KINDS: tuple[LegendKind, ...] = ("orientation", "coherence", "composite")

_TITLES: dict[str, str] = {
    "orientation": "fringe direction",
    "coherence": "coherence",
    "composite": "hue: fringe direction, saturation: coherence",
}
# Legend layout in "units" (pixels at scale 1); the scale grows with the image width so that the
# legend of a 2048-pixel image stays legible next to it.
_BASE_HEIGHT: dict[str, int] = {"orientation": 86, "coherence": 58, "composite": 112}
_BASE_MIN_WIDTH = 300
_WIDTH_PER_SCALE = 640
_MAX_SCALE = 4
_FONT_SIZE = 11
_PAD = 10
_STRIP_HEIGHT = 16
_TICK = 5
_DISC_RADIUS = 28
_DISC_BLOCK = 64  # width kept for the half-disc and its labels on the right
_TEXT = (0, 0, 0)
_FRAME = (128, 128, 128)
_BACKGROUND = (255, 255, 255)
_Font = ImageFont.FreeTypeFont | ImageFont.ImageFont


# --- palettes ---------------------------------------------------------------------------------


def orientation_hue(theta: np.ndarray) -> np.ndarray:
    """Cyclic hue in ``[0, 1)`` of orientations: ``hue = (theta + pi/2) / pi`` modulo 1.

    Parameters
    ----------
    theta : ndarray
        Angles in radians; any value is first taken modulo pi, so ``theta`` and ``theta + pi``
        (the same orientation) get the same hue.

    Returns
    -------
    ndarray
        float64 hues, same shape as ``theta``; +-90 degrees map to 0 (red), 0 degrees to 0.5 (cyan).

    Examples
    --------
    >>> import numpy as np
    >>> orientation_hue(np.radians([-45.0, 0.0, 45.0, 90.0])).round(3).tolist()
    [0.25, 0.5, 0.75, 0.0]
    """
    t = np.asarray(theta, dtype=np.float64)
    return np.mod((t + np.pi / 2) / np.pi, 1.0)


def _to_uint8(x: np.ndarray) -> np.ndarray:
    return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


#: The standard HSV -> RGB table: in sector ``floor(6 hue) mod 6`` of the hue circle, which of
#: ``(v, q, p, t)`` (below) each of R, G and B takes.
_SECTOR_PICKS = np.array([[0, 3, 2], [1, 0, 2], [2, 0, 3], [2, 1, 0], [3, 2, 0], [0, 2, 1]])


def _hsv_uint8(hue: np.ndarray, saturation: np.ndarray, value: np.ndarray) -> np.ndarray:
    """RGB ``uint8`` of HSV in [0, 1] (broadcast together), in float64: the floats of scikit-image's
    ``hsv2rgb`` (the same formulas; tested bit for bit), one channel at a time instead of its stacks of
    the six sectors' RGB candidates (2.5 times faster, a third of its temporaries)."""
    h, s, v = (np.asarray(a, dtype=np.float64) for a in np.broadcast_arrays(hue, saturation, value))
    sector = np.floor(h * 6)
    f = h * 6 - sector
    p = v * (1 - s)
    q = v * (1 - f * s)
    t = v * (1 - (1 - f) * s)
    sector = sector.astype(np.uint8) % 6
    candidates = (v, q, p, t)
    rgb = np.empty((*h.shape, 3), dtype=np.uint8)
    for channel in range(3):
        rgb[..., channel] = _to_uint8(np.choose(sector, [candidates[k] for k in _SECTOR_PICKS[:, channel]]))
    return rgb


#: Pixels coloured at once: the renderings are per pixel, so they are made in blocks of rows, and the
#: colour conversion's float64 temporaries (about 100 bytes per pixel) stay small whatever the image.
_BLOCK_PIXELS = 1 << 16


def _row_blocks(shape: tuple[int, ...]) -> Iterator[slice]:
    """Slices of consecutive rows of about :data:`_BLOCK_PIXELS` pixels that cover ``shape[0]`` rows."""
    rows = max(1, _BLOCK_PIXELS // max(1, shape[1]))
    for start in range(0, shape[0], rows):
        yield slice(start, min(start + rows, shape[0]))


def _checked(name: str, array: np.ndarray, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Validate a 2D real field (and its shape against ``shape``); returned as it is, not copied."""
    arr = np.asarray(array)
    if arr.ndim != 2 or arr.size == 0:
        raise InvalidParameter(name, f"array of shape {arr.shape}", "must be a non-empty 2D array (H, W)")
    if shape is not None and arr.shape != shape:
        raise InvalidParameter(name, f"array of shape {arr.shape}", f"must have the shape {shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InvalidParameter(name, f"array of dtype {arr.dtype}", "must be a real-valued array")
    return arr


def _field(name: str, array: np.ndarray, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Validate a 2D float field (and its shape against ``shape``); non-finite values become NaN."""
    return _checked(name, array, shape).astype(np.float64)


def _clipped(arr: np.ndarray) -> np.ndarray:
    """Values in [0, 1] (clipped; NaN -> 0), float64."""
    return np.clip(np.nan_to_num(arr.astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


def _unit(name: str, array: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A field of values in [0, 1] (clipped; NaN -> 0)."""
    return _clipped(_checked(name, array, shape))


# --- images -----------------------------------------------------------------------------------


def orientation_image(
    theta: np.ndarray,
    *,
    coherence: np.ndarray | None = None,
    legend: bool = False,
    title: str | None = None,
) -> np.ndarray:
    """Colour an orientation field with the cyclic hue palette.

    Parameters
    ----------
    theta : ndarray, shape (H, W)
        Angles in radians, counter-clockwise from +x with ``y`` up; by the project's convention the
        fringe direction (:func:`texsynth.synth.analysis.tensor.structure_direction`). Non-finite angles are
    black. coherence : ndarray, shape (H, W), optional
        When given, the saturation (0 white, 1 full colour), so that orientation-less regions fade
        out; otherwise every pixel is fully saturated.
    legend : bool
        Append the legend (hue strip and half-disc; the hue x saturation chart with ``coherence``).
    title : str, optional
        Legend caption, ``'fringe direction'`` (or the composite caption) by default.

    Returns
    -------
    ndarray, shape (H, W, 3) or (H + legend, max(W, legend width), 3), uint8
    """
    theta_all = _checked("theta", theta)
    coherence_all = None if coherence is None else _checked("coherence", coherence, theta_all.shape)
    rgb = np.empty((*theta_all.shape, 3), dtype=np.uint8)
    for rows in _row_blocks(theta_all.shape):  # per pixel: blocks of rows give the same bytes
        t = theta_all[rows].astype(np.float64)
        finite = np.isfinite(t)
        hue = orientation_hue(np.where(finite, t, 0.0))
        sat = np.ones_like(hue) if coherence_all is None else _clipped(coherence_all[rows])
        rgb[rows] = _hsv_uint8(hue, sat, finite.astype(np.float64))
    if not legend:
        return rgb
    return with_legend(rgb, "orientation" if coherence is None else "composite", title=title)


def coherence_image(coherence: np.ndarray, *, legend: bool = False, title: str | None = None) -> np.ndarray:
    """Grey rendering of a coherence field: 0 black, 1 white (clipped; NaN black).

    Parameters
    ----------
    coherence : ndarray, shape (H, W)
        Coherence in [0, 1] (:func:`texsynth.synth.analysis.tensor.coherence`).
    legend : bool
        Append the grey-ramp legend.
    title : str, optional
        Legend caption, ``'coherence'`` by default.

    Returns
    -------
    ndarray, shape (H, W) or (H + legend, max(W, legend width)), uint8

    Examples
    --------
    >>> import numpy as np
    >>> coherence_image(np.array([[0.0, 0.5, 1.0]])).tolist()
    [[0, 128, 255]]
    """
    c = _checked("coherence", coherence)
    grey = np.empty(c.shape, dtype=np.uint8)
    for rows in _row_blocks(c.shape):
        grey[rows] = _to_uint8(_clipped(c[rows]))
    return with_legend(grey, "coherence", title=title) if legend else grey


def composite_image(
    theta: np.ndarray,
    coherence: np.ndarray,
    value: np.ndarray,
    *,
    legend: bool = False,
    title: str | None = None,
) -> np.ndarray:
    """HSV composite: hue = orientation, saturation = coherence, value = the image.

    The OrientationJ "colour survey": fringes keep their brightness from the image, take their hue
    from their direction and fade to grey where the structure is not oriented.

    Parameters
    ----------
    theta : ndarray, shape (H, W)
        Angles in radians (by convention the fringe direction, see the module notes).
    coherence : ndarray, shape (H, W)
        Saturation, in [0, 1].
    value : ndarray, shape (H, W) or (H, W, 3)
        The image in [0, 1] (an RGB image contributes its luminance), clipped.
    legend : bool
        Append the hue x saturation chart and the half-disc.
    title : str, optional
        Legend caption.

    Returns
    -------
    ndarray, shape (H, W, 3) or with the legend appended, uint8
    """
    t = _field("theta", theta)
    val = np.asarray(value)
    if val.ndim == 3 and val.shape[2] == 3:
        val = to_grey(np.clip(np.nan_to_num(val.astype(np.float64)), 0.0, 1.0), np.float64)
    v = _unit("value", val, t.shape)
    finite = np.isfinite(t)
    hue = orientation_hue(np.where(finite, t, 0.0))
    sat = np.where(finite, _unit("coherence", coherence, t.shape), 0.0)
    rgb = _hsv_uint8(hue, sat, v)
    return with_legend(rgb, "composite", title=title) if legend else rgb


# --- legends ----------------------------------------------------------------------------------


def _scale(width: int) -> int:
    return int(min(_MAX_SCALE, max(1, width // _WIDTH_PER_SCALE)))


def legend_shape(kind: LegendKind, image_width: int) -> tuple[int, int]:
    """``(height, width)`` of the legend panel :func:`with_legend` appends below an image.

    The output of :func:`with_legend` is ``(H + height, max(W, width))``: the legend is never
    narrower than it needs to be for its labels, and grows with wide images.
    """
    if kind not in LEGEND_KINDS:
        raise InvalidParameter("kind", kind, f"must be one of {', '.join(LEGEND_KINDS)}")
    u = _scale(int(image_width))
    return _BASE_HEIGHT[kind] * u, max(int(image_width), _BASE_MIN_WIDTH * u)


def with_legend(image: np.ndarray, kind: LegendKind, *, title: str | None = None) -> np.ndarray:
    """Append the legend of a rendering below it.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3), uint8
        A rendering from this module (grey for ``'coherence'``, RGB otherwise).
    kind : {'orientation', 'coherence', 'composite'}
        ``'orientation'``: a hue strip from -90 to +90 degrees with ticks every 45 degrees, and a
        half-disc whose rays wear the colour of their own direction; ``'coherence'``: a grey ramp
        from 0 to 1; ``'composite'``: a 2D chart, hue (orientation) across and saturation
        (coherence) up, beside the same half-disc.
    title : str, optional
        The caption; by default ``'fringe direction'``, ``'coherence'`` or
        ``'hue: fringe direction, saturation: coherence'``.

    Returns
    -------
    ndarray, uint8
        ``(H + h, max(W, w))`` or ``(H + h, max(W, w), 3)`` with ``(h, w) = legend_shape(kind, W)``;
        the image sits top-left, padded with white.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
        raise InvalidParameter(
            "image", f"{img.dtype} array of shape {img.shape}", "must be a uint8 (H, W) or (H, W, 3) image"
        )
    height, width = legend_shape(kind, img.shape[1])
    panel = _draw_legend(kind, width, height, _scale(img.shape[1]), title or _TITLES[kind])
    if img.ndim == 2:
        panel = panel.convert("L")
    legend_array = np.asarray(panel, dtype=np.uint8)
    out = np.full((img.shape[0] + height, width, *img.shape[2:]), 255, dtype=np.uint8)
    out[: img.shape[0], : img.shape[1]] = img
    out[img.shape[0] :] = legend_array
    return out


def _font(u: int) -> _Font:
    return ImageFont.load_default(size=_FONT_SIZE * u)


def _text_centred(draw: ImageDraw.ImageDraw, x: float, y: float, text: str, font: _Font) -> None:
    left, _, right, _ = draw.textbbox((0, 0), text, font=font)
    draw.text((round(x - (right - left) / 2), round(y)), text, fill=_TEXT, font=font)


def _ticks(
    draw: ImageDraw.ImageDraw,
    x0: int,
    x1: int,
    y: int,
    u: int,
    font: _Font,
    ticks: list[tuple[float, str]],
) -> None:
    """Tick marks below a strip spanning ``[x0, x1)`` at fractions ``f``, labelled when given."""
    for fraction, label in ticks:
        x = x0 + fraction * (x1 - 1 - x0)
        draw.line([(x, y), (x, y + _TICK * u)], fill=_TEXT, width=max(1, u))
        if label:
            _text_centred(draw, x, y + (_TICK + 1) * u, label, font)


_ANGLE_TICKS = [(0.0, "-90°"), (0.25, ""), (0.5, "0°"), (0.75, ""), (1.0, "+90°")]


def _hue_strip(width: int, height: int, saturation: np.ndarray | float = 1.0) -> np.ndarray:
    """Hues from -90 (left) to +90 degrees (right), ``saturation`` per row or constant."""
    theta = np.linspace(-np.pi / 2, np.pi / 2, width)[None, :]
    sat = np.broadcast_to(np.asarray(saturation, dtype=np.float64).reshape(-1, 1), (height, width))
    return _hsv_uint8(orientation_hue(np.broadcast_to(theta, (height, width))), sat, 1.0)


def _half_disc(canvas: Image.Image, draw: ImageDraw.ImageDraw, cx: int, cy: int, u: int, font: _Font) -> None:
    """Right half-disc; the ray at angle ``a`` (y up) wears ``hue(a)``: a picture of directions."""
    r = _DISC_RADIUS * u
    dy, dx = np.mgrid[-r : r + 1, 0 : r + 1].astype(np.float64)
    angle = np.arctan2(-dy, dx)  # rows grow down, y up
    inside = dx**2 + dy**2 <= r * r
    rgb = _hsv_uint8(orientation_hue(angle), 1.0, 1.0)
    rgb[~inside] = _BACKGROUND
    canvas.paste(Image.fromarray(rgb), (cx, cy - r))
    draw.line([(cx, cy - r), (cx, cy + r)], fill=_FRAME, width=max(1, u))
    _text_centred(draw, cx, cy - r - 12 * u, "+90°", font)
    _text_centred(draw, cx, cy + r + 1 * u, "-90°", font)
    draw.text((cx + r + 4 * u, cy - 6 * u), "0°", fill=_TEXT, font=font)


def _draw_legend(kind: str, width: int, height: int, u: int, title: str) -> Image.Image:
    canvas = Image.new("RGB", (width, height), _BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    font = _font(u)
    pad = _PAD * u
    draw.text((pad, 4 * u), title, fill=_TEXT, font=font)
    top = 22 * u
    if kind == "coherence":
        x0, x1 = pad + 6 * u, width - pad - 6 * u
        ramp = np.linspace(0.0, 1.0, x1 - x0)
        strip = np.repeat(
            _to_uint8(np.broadcast_to(ramp, (_STRIP_HEIGHT * u, x1 - x0)))[..., None], 3, axis=2
        )
        canvas.paste(Image.fromarray(strip), (x0, top))
        draw.rectangle([x0 - 1, top - 1, x1, top + _STRIP_HEIGHT * u], outline=_FRAME)
        labels = [(0.0, "0"), (0.25, ""), (0.5, "0.5"), (0.75, ""), (1.0, "1")]
        _ticks(draw, x0, x1, top + _STRIP_HEIGHT * u, u, font, labels)
        return canvas
    disc_x = width - _DISC_BLOCK * u
    x1 = disc_x - 3 * pad
    if kind == "orientation":
        x0 = pad + 6 * u
        strip = _hue_strip(x1 - x0, _STRIP_HEIGHT * u)
        canvas.paste(Image.fromarray(strip), (x0, top))
        _ticks(draw, x0, x1, top + _STRIP_HEIGHT * u, u, font, _ANGLE_TICKS)
        _half_disc(canvas, draw, disc_x, height // 2, u, font)
        return canvas
    # composite: hue across, saturation (coherence) up.
    x0 = pad + 22 * u
    chart_h = 56 * u
    chart = _hue_strip(x1 - x0, chart_h, saturation=np.linspace(1.0, 0.0, chart_h))
    canvas.paste(Image.fromarray(chart), (x0, top))
    draw.rectangle([x0 - 1, top - 1, x1, top + chart_h], outline=_FRAME)
    _ticks(draw, x0, x1, top + chart_h, u, font, _ANGLE_TICKS)
    for y, label in ((top, "1"), (top + chart_h - 10 * u, "0")):
        draw.text((x0 - 10 * u, y), label, fill=_TEXT, font=font)
    draw.text((pad - 6 * u, top + chart_h // 2 - 6 * u), "C", fill=_TEXT, font=font)
    # Lower than the chart's middle, so that its '+90°' clears the caption.
    _half_disc(canvas, draw, disc_x, top + chart_h // 2 + 6 * u, u, font)
    return canvas
