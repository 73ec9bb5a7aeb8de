"""Pictures of a volume a person can read: orthogonal mid-slices beside their exemplars, a cut-away block.

A volume is ``(D, H, W) = (z, y, x)`` (ALGORITHMS.md, "Conventions"); its planes are ``xy`` (``vol[z]``,
rows ``y``, columns ``x``), ``xz`` (``vol[:, y]``, rows ``z``, columns ``x``) and ``yz``
(``vol[:, :, x]``, rows ``z``, columns ``y``). Every picture labels its axes by these names, with an
arrow pointing the way the voxel index grows.

- :func:`slices_image`: the three orthogonal mid-slices side by side (top row), each above the
  exemplar its plane must resemble (bottom row), all at one integer magnification so that sizes
  compare; captions ``xy (z = k)`` and the axis names on the sides of every panel.
- :func:`cube_image`: the block in a cabinet (oblique) projection, ``x`` to the right, ``z`` down (the
  stack's page order, as in the ``xz`` and ``yz`` slices), ``y`` receding up and to the right. Left:
  the three visible outer faces (``z = 0`` on top, ``y = 0`` in front, ``x = W - 1`` on the right);
  right: the same block with the corner octant nearest the viewer cut away, which shows the three
  mid-planes inside (outlined in orange). Faces are shaded by their direction (top lightest, right
  darkest) and edged in dark grey so that the block's shape reads even where the material is black.
- :func:`write_volume_images`: those two PNGs and, per plane, the coherence and fringe-direction
  images of the mid-slice with their legends (:mod:`texsynth.synth.output.render`).

Text is drawn with Pillow's scalable default font; images are ``uint8`` RGB arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from texsynth.synth.analysis.tensor import coherence, structure_direction, structure_tensor
from texsynth.synth.colour import LUMA_WEIGHTS
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.io import image_to_png_bytes
from texsynth.synth.io.atomic import atomic_write_bytes
from texsynth.synth.output.render import coherence_image, orientation_image, with_legend

__all__ = ["PLANES", "PLANE_AXES", "cube_image", "mid_slices", "slices_image", "write_volume_images"]

#: The orthogonal planes of a volume, as :data:`texsynth.synth.api.PLANES`.
PLANES: tuple[str, ...] = ("xy", "xz", "yz")
#: (row axis, column axis, fixed axis) of each plane's slice images.
PLANE_AXES: dict[str, tuple[str, str, str]] = {
    "xy": ("y", "x", "z"),
    "xz": ("z", "x", "y"),
    "yz": ("z", "y", "x"),
}
_AXIS_INDEX = {"z": 0, "y": 1, "x": 2}

_BACKGROUND = (255, 255, 255)
_TEXT = (20, 20, 20)
_EDGE = (60, 60, 60)
_CUT = (230, 120, 20)  # outline of the cut faces: the mid-planes
_ARROW = (40, 40, 40)
#: Target size (pixels) of the largest panel of slices.png and of the block in cube.png.
_PANEL_TARGET = 256
_CUBE_TARGET = 340
#: Cabinet projection: receding axis drawn at this angle and shortened by this factor.
_RECEDE_ANGLE = math.radians(35.0)
_RECEDE_SCALE = 0.5
#: Brightness of faces facing up (-z), front (-y) and right (+x).
_SHADE = {"top": 1.0, "front": 0.82, "right": 0.64}
#: Lifted floor so that shading still shows on the black phase of a two-phase volume.
_FLOOR = 0.12


#: Voxels per slab when a volume is checked (a 512^3 float32 volume is never copied whole).
_SLAB = 1 << 22


def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    return ImageFont.load_default(size=size)


def _check_volume(volume: np.ndarray) -> np.ndarray:
    vol = np.asarray(volume)
    if vol.ndim != 3 or min(vol.shape) < 1:
        raise InvalidInput("volume", f"expected a grey (D, H, W) volume, got shape {vol.shape}")
    if not (
        np.issubdtype(vol.dtype, np.floating) or np.issubdtype(vol.dtype, np.integer) or vol.dtype == bool
    ):
        raise InvalidInput("volume", f"array of dtype {vol.dtype} is not a grey volume")
    step = max(1, _SLAB // max(1, vol[0].size))
    for start in range(0, vol.shape[0], step):  # slab by slab: no copy of the whole volume
        slab = vol[start : start + step]
        if np.issubdtype(slab.dtype, np.floating) and not np.isfinite(slab).all():
            raise InvalidInput("volume", "holds NaN/inf values")
    return vol


def _unit(values: np.ndarray) -> np.ndarray:
    """A slice or face of a checked volume as float64 clipped to [0, 1]: only what is drawn is converted."""
    return np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)


def _mid_index(volume_shape: tuple[int, ...], index: tuple[int, int, int] | None) -> tuple[int, int, int]:
    if index is None:
        return (volume_shape[0] // 2, volume_shape[1] // 2, volume_shape[2] // 2)
    idx = tuple(int(i) for i in index)
    if len(idx) != 3 or any(not 0 <= i < n for i, n in zip(idx, volume_shape, strict=True)):
        raise InvalidParameter("index", index, f"must be (z, y, x) inside the volume of shape {volume_shape}")
    return idx  # type: ignore[return-value]


def mid_slices(volume: np.ndarray, index: tuple[int, int, int] | None = None) -> dict[str, np.ndarray]:
    """The three orthogonal slices through ``index`` (``(z, y, x)``, the middle voxel by default).

    Returns
    -------
    dict
        ``{'xy': vol[z] (H, W), 'xz': vol[:, y] (D, W), 'yz': vol[:, :, x] (D, H)}``.
    """
    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise InvalidInput("volume", f"expected a grey (D, H, W) volume, got shape {vol.shape}")
    z, y, x = _mid_index(vol.shape, index)
    return {"xy": vol[z], "xz": vol[:, y], "yz": vol[:, :, x]}


def _plane_exemplars(
    exemplars: Mapping[str, np.ndarray] | np.ndarray | None,
) -> tuple[dict[str, np.ndarray] | None, bool]:
    """Grey exemplar per plane (RGB as its luma), and whether one serves all planes."""
    if exemplars is None:
        return None, False
    if not isinstance(exemplars, Mapping):
        one = _grey(exemplars, "exemplar")
        return dict.fromkeys(PLANES, one), True
    unknown = sorted(str(k) for k in set(exemplars) - set(PLANES))
    if unknown:
        raise InvalidInput(f"exemplar_{unknown[0]}", f"unknown plane (known: {', '.join(PLANES)})")
    missing = [p for p in PLANES if p not in exemplars]
    if missing:
        raise InvalidInput(f"exemplar_{missing[0]}", "missing: per-plane exemplars come as all three")
    grey = {p: _grey(exemplars[p], f"exemplar_{p}") for p in PLANES}
    same = all(np.array_equal(grey[p], grey["xy"]) for p in PLANES)
    return grey, same


def _grey(image: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(image, dtype=np.float64)
    if arr.ndim == 3 and arr.shape[2] == 3:
        arr = arr @ np.asarray(LUMA_WEIGHTS, dtype=np.float64)  # as texsynth.synth.io.load_image
    if arr.ndim != 2 or min(arr.shape) < 1:
        raise InvalidInput(name, f"expected a grey (H, W) image, got shape {np.shape(image)}")
    if not np.isfinite(arr).all():
        raise InvalidInput(name, "holds NaN/inf values")
    return np.clip(arr, 0.0, 1.0)


def _magnify(image: np.ndarray, scale: int) -> np.ndarray:
    return np.repeat(np.repeat(image, scale, axis=0), scale, axis=1) if scale > 1 else image


def _to_rgb8(grey: np.ndarray) -> np.ndarray:
    g = np.round(np.clip(grey, 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=2)


def _arrow(
    draw: ImageDraw.ImageDraw,
    start: tuple[float, float],
    end: tuple[float, float],
    width: int,
    label: str,
    font: ImageFont.FreeTypeFont | ImageFont.ImageFont,
    label_offset: tuple[float, float],
) -> None:
    """A line from ``start`` to ``end`` with a filled head at ``end`` and ``label`` near the head."""
    (x0, y0), (x1, y1) = start, end
    draw.line([(x0, y0), (x1, y1)], fill=_ARROW, width=width)
    length = math.hypot(x1 - x0, y1 - y0) or 1.0
    ux, uy = (x1 - x0) / length, (y1 - y0) / length
    head = 4.0 * width + 4.0
    left = (x1 - head * ux + 0.5 * head * uy, y1 - head * uy - 0.5 * head * ux)
    right = (x1 - head * ux - 0.5 * head * uy, y1 - head * uy + 0.5 * head * ux)
    draw.polygon([(x1 + ux, y1 + uy), left, right], fill=_ARROW)
    left_t, top_t, right_t, bottom_t = draw.textbbox((0, 0), label, font=font)
    cx, cy = x1 + label_offset[0], y1 + label_offset[1]
    draw.text(
        (cx - (right_t - left_t) / 2, cy - (bottom_t - top_t) / 2 - top_t), label, fill=_TEXT, font=font
    )


def _text_centre(
    draw: ImageDraw.ImageDraw,
    x: float,
    y: float,
    text: str,
    font: ImageFont.FreeTypeFont | ImageFont.ImageFont,
) -> None:
    left, _, right, _ = draw.textbbox((0, 0), text, font=font)
    draw.text((round(x - (right - left) / 2), round(y)), text, fill=_TEXT, font=font)


def slices_image(
    volume: np.ndarray,
    exemplars: Mapping[str, np.ndarray] | np.ndarray | None = None,
    *,
    index: tuple[int, int, int] | None = None,
    scale: int | None = None,
    title: str | None = None,
) -> np.ndarray:
    """The three orthogonal slices of a volume side by side, each above its plane's exemplar.

    Parameters
    ----------
    volume : ndarray, shape (D, H, W)
        Grey volume in [0, 1] (``(z, y, x)``).
    exemplars : ndarray or mapping ``{'xy', 'xz', 'yz'} -> ndarray``, optional
        One exemplar for all planes, or one per plane; drawn below the slice of its plane at the same
        magnification. ``None``: slices only.
    index : (int, int, int), optional
        ``(z, y, x)`` of the voxel the slices cross; the middle voxel by default.
    scale : int, optional
        Integer magnification (nearest neighbour) of every panel; by default the one that brings the
        largest panel to about 256 px (at most 8).
    title : str, optional
        A line above the panels.

    Returns
    -------
    ndarray, shape (h, w, 3), uint8
        Captions ``xy (z = k)``, ``xz (y = k)``, ``yz (x = k)`` and ``exemplar xy``...; on every panel
        an arrow along the top edge names the column axis and one down the left edge the row axis,
        both pointing the way the index grows.
    """
    vol = _check_volume(volume)
    idx = _mid_index(vol.shape, index)
    slices = {plane: _unit(s) for plane, s in mid_slices(vol, idx).items()}
    planes, same = _plane_exemplars(exemplars)
    panels_dims = [s.shape for s in slices.values()] + ([e.shape for e in planes.values()] if planes else [])
    largest = max(max(d) for d in panels_dims)
    if scale is None:
        scale = int(min(8, max(1, round(_PANEL_TARGET / largest))))
    elif isinstance(scale, bool) or not isinstance(scale, int | np.integer) or not 1 <= scale <= 32:
        raise InvalidParameter("scale", scale, "must be an integer magnification in [1, 32]")
    font_size = 15
    font, small = _font(font_size), _font(font_size - 2)
    margin = 12
    caption_h = font_size + 8
    side = 30  # room for the axis arrows on the left and the top of each panel
    col_w = [max(s.shape[1], planes[p].shape[1] if planes else 0) * scale for p, s in slices.items()]
    row_h = [max(s.shape[0] for s in slices.values()) * scale]
    if planes:
        row_h.append(max(e.shape[0] for e in planes.values()) * scale)
    title_h = font_size + 12 if title else 0
    width = margin + sum(side + w + margin for w in col_w) + margin
    height = title_h + margin + sum(caption_h + side + h + margin for h in row_h)
    canvas = Image.new("RGB", (width, height), _BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    if title:
        draw.text((margin, 6), title, fill=_TEXT, font=font)
    fixed_names = {p: PLANE_AXES[p][2] for p in PLANES}
    rows: list[tuple[str, dict[str, np.ndarray]]] = [("slice", slices)]
    if planes:
        rows.append(("exemplar", planes))
    y = title_h + margin
    for (kind, images), h in zip(rows, row_h, strict=True):
        x = margin
        for (plane, img), w in zip(images.items(), col_w, strict=True):
            rows_axis, cols_axis, fixed = PLANE_AXES[plane]
            if kind == "slice":
                caption = f"{plane} ({fixed_names[plane]} = {idx[_AXIS_INDEX[fixed]]})"
            else:
                caption = "exemplar (all planes)" if same else f"exemplar {plane}"
            px, py = x + side, y + caption_h + side
            _text_centre(draw, px + img.shape[1] * scale / 2, y, caption, font)
            canvas.paste(Image.fromarray(_to_rgb8(_magnify(img, scale))), (px, py))
            draw.rectangle(
                [px - 1, py - 1, px + img.shape[1] * scale, py + img.shape[0] * scale], outline=_EDGE
            )
            length = min(60, img.shape[1] * scale - 4)
            _arrow(draw, (px, py - 10), (px + length, py - 10), 2, cols_axis, small, (12, 0))
            length = min(60, img.shape[0] * scale - 4)
            _arrow(draw, (px - 10, py), (px - 10, py + length), 2, rows_axis, small, (0, 12))
            x += side + w + margin
        y += caption_h + side + h + margin
    return np.asarray(canvas, dtype=np.uint8)


def _face_layer(
    shape: tuple[int, int],
    origin: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    values: np.ndarray,
    keep: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample a face (a parallelogram ``origin + a e1 + b e2``, ``values[a, b]``) on the screen grid.

    Inverse mapping: every screen pixel centre is solved for ``(a, b)``; pixels with ``0 <= a < n1``,
    ``0 <= b < n2`` (and ``keep[a, b]``) take the nearest voxel. Returns the screen values and mask.
    """
    h, w = shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    basis = np.array([[e1[0], e2[0]], [e1[1], e2[1]]])
    inv = np.linalg.inv(basis)
    du, dv = u - origin[0], v - origin[1]
    a = inv[0, 0] * du + inv[0, 1] * dv
    b = inv[1, 0] * du + inv[1, 1] * dv
    n1, n2 = values.shape
    inside = (a >= 0) & (a < n1) & (b >= 0) & (b < n2)
    ai = np.clip(a.astype(np.int64), 0, n1 - 1)
    bi = np.clip(b.astype(np.int64), 0, n2 - 1)
    if keep is not None:
        inside &= keep[ai, bi]
    return values[ai, bi], inside


def _block_view(
    vol: np.ndarray, cut: bool, scale: float, idx: tuple[int, int, int]
) -> tuple[Image.Image, dict[str, np.ndarray]]:
    """One cabinet-projection view of the block; returns the picture and its corner points (screen)."""
    d, h, w = vol.shape
    rx, ry = _RECEDE_SCALE * math.cos(_RECEDE_ANGLE), _RECEDE_SCALE * math.sin(_RECEDE_ANGLE)
    pad = 4.0
    lift = ry * h * scale

    def screen(z: float, y: float, x: float) -> np.ndarray:
        return np.array([pad + scale * (x + rx * y), pad + lift + scale * (z - ry * y)])

    size = (round(2 * pad + lift + scale * d), round(2 * pad + scale * (w + rx * h)))
    ex, ey, ez = (
        screen(0, 0, 1) - screen(0, 0, 0),
        screen(0, 1, 0) - screen(0, 0, 0),
        screen(1, 0, 0) - screen(0, 0, 0),
    )
    cz, cy, cx = idx[0], idx[1], idx[2] + 1  # removed octant: z < cz, y < cy, x >= cx

    def grey(*index: int | slice) -> np.ndarray:  # one face, shaded from its voxels only
        return _FLOOR + (1.0 - _FLOOR) * _unit(vol[index])

    # kept parts of the outer faces when the corner octant is cut away, as masks over (a, b)
    z_col, y_col, y_row, x_row = (
        np.arange(d)[:, None],
        np.arange(h)[:, None],
        np.arange(h)[None, :],
        np.arange(w)[None, :],
    )
    keep_front = (z_col >= cz) | (x_row < cx) if cut else None
    keep_top = (y_col >= cy) | (x_row < cx) if cut else None
    keep_right = (z_col >= cz) | (y_row >= cy) if cut else None
    # (origin, e1, e2, values[a, b], keep[a, b] or None, facing, is a cut face)
    faces = [
        (screen(0, 0, 0), ez, ex, grey(slice(None), 0, slice(None)), keep_front, "front", False),
        (screen(0, 0, 0), ey, ex, grey(0, slice(None), slice(None)), keep_top, "top", False),
        (screen(0, 0, w), ez, ey, grey(slice(None), slice(None), w - 1), keep_right, "right", False),
    ]
    if cut:
        faces += [
            (screen(0, cy, cx), ez, ex, grey(slice(None, cz), cy, slice(cx, None)), None, "front", True),
            (screen(cz, 0, cx), ey, ex, grey(cz, slice(None, cy), slice(cx, None)), None, "top", True),
            (screen(0, 0, cx), ez, ey, grey(slice(None, cz), slice(None, cy), cx - 1), None, "right", True),
        ]
    canvas = np.full((*size, 3), 255.0)
    outlines = []
    for origin, e1, e2, values, keep, facing, is_cut in faces:
        if values.size == 0:
            continue
        sampled, mask = _face_layer(size, origin, e1, e2, values, keep)
        canvas[mask] = (255.0 * _SHADE[facing] * sampled[mask])[:, None]
        n1, n2 = values.shape
        corners = [origin, origin + n1 * e1, origin + n1 * e1 + n2 * e2, origin + n2 * e2]
        outlines.append((corners, is_cut, keep, origin, e1, e2))
    image = Image.fromarray(np.round(canvas).astype(np.uint8))
    draw = ImageDraw.Draw(image)
    line = max(1, round(scale / 3))
    if cut:
        _draw_cut_block_edges(draw, screen, (d, h, w), (cz, cy, cx), line)
    else:
        for corners, *_ in outlines:
            draw.line([tuple(p) for p in [*corners, corners[0]]], fill=_EDGE, width=line)
    for corners, is_cut, *_ in outlines:
        if is_cut:
            draw.line([tuple(p) for p in [*corners, corners[0]]], fill=_CUT, width=line + 1)
    points = {
        "origin": screen(0, 0, 0),
        "x_end": screen(0, 0, w),
        "y_end": screen(0, h, 0),
        "z_end": screen(d, 0, 0),
        "front_bottom_right": screen(d, 0, w),
    }
    return image, points


def _draw_cut_block_edges(
    draw: ImageDraw.ImageDraw,
    screen: Callable[[float, float, float], np.ndarray],
    dims: tuple[int, int, int],
    cut: tuple[int, int, int],
    width: int,
) -> None:
    """The visible outer edges of the block with its front-top-right octant removed."""
    d, h, w = dims
    cz, cy, cx = cut
    segments = [
        # front face (y = 0) outline, notched at the top right
        ((0, 0, 0), (d, 0, 0)),
        ((d, 0, 0), (d, 0, w)),
        ((d, 0, w), (cz, 0, w)),
        ((cz, 0, w), (cz, 0, cx)),
        ((cz, 0, cx), (0, 0, cx)),
        ((0, 0, cx), (0, 0, 0)),
        # top face (z = 0), notched at the front right
        ((0, 0, 0), (0, h, 0)),
        ((0, h, 0), (0, h, w)),
        ((0, h, w), (0, cy, w)),
        ((0, cy, w), (0, cy, cx)),
        ((0, cy, cx), (0, 0, cx)),
        # right face (x = W), notched at the top front
        ((d, 0, w), (d, h, w)),
        ((d, h, w), (0, h, w)),
        ((cz, 0, w), (cz, cy, w)),
        ((cz, cy, w), (0, cy, w)),
    ]
    for a, b in segments:
        draw.line([tuple(screen(*a)), tuple(screen(*b))], fill=_EDGE, width=width)


def cube_image(
    volume: np.ndarray,
    *,
    index: tuple[int, int, int] | None = None,
    views: tuple[str, ...] = ("outside", "cut"),
    title: str | None = None,
) -> np.ndarray:
    """The volume as a block in a cabinet projection: its outer faces, and with a corner cut away.

    Parameters
    ----------
    volume : ndarray, shape (D, H, W)
        Grey volume in [0, 1] (``(z, y, x)``).
    index : (int, int, int), optional
        ``(z, y, x)`` of the cut's inner corner: the cut-away view shows the planes ``z = index[0]``,
        ``y = index[1]`` and ``x = index[2]`` inside the block (the mid-planes by default, the slices of
        :func:`slices_image`).
    views : tuple of {'outside', 'cut'}
        Which views to draw, left to right.
    title : str, optional
        A line above the views.

    Returns
    -------
    ndarray, shape (h, w, 3), uint8
        ``x`` to the right, ``z`` down (page order of the TIFF stack, as the rows of the ``xz`` and
        ``yz`` slices), ``y`` receding up-right at 35 degrees, shortened by half (a cabinet projection:
        every face keeps its true proportions along ``x`` and ``z``). Faces are shaded by direction;
        the cut faces are outlined in orange. Arrows name the axes; captions give the faces' planes.
    """
    vol = _check_volume(volume)
    idx = _mid_index(vol.shape, index)
    if not views or any(v not in ("outside", "cut") for v in views):
        raise InvalidParameter("views", views, "must list 'outside' and/or 'cut'")
    d, h, w = vol.shape
    extent = max(
        w + _RECEDE_SCALE * math.cos(_RECEDE_ANGLE) * h, d + _RECEDE_SCALE * math.sin(_RECEDE_ANGLE) * h
    )
    scale = max(1.0, _CUBE_TARGET / extent)
    font_size = 15
    font, small = _font(font_size), _font(font_size - 2)
    margin, arrow_room = 16, 44
    captions = {
        "outside": ["outer faces", f"top: xy (z = 0), front: xz (y = 0), right: yz (x = {w - 1})"],
        "cut": ["corner cut away", f"cut faces: xy (z = {idx[0]}), xz (y = {idx[1]}), yz (x = {idx[2]})"],
    }
    rendered = [(v, *_block_view(vol, v == "cut", scale, idx)) for v in views]
    caption_h = 2 * (font_size + 6)
    title_h = font_size + 12 if title else 0
    caption_w = max(
        ImageDraw.Draw(Image.new("RGB", (1, 1))).textbbox((0, 0), c[1], font=small)[2]
        for c in captions.values()
    )
    panel_w = max(max(img.width for _, img, _ in rendered), caption_w) + arrow_room
    width = margin + len(rendered) * (panel_w + margin)
    height = title_h + margin + caption_h + max(img.height for _, img, _ in rendered) + 30 + margin
    canvas = Image.new("RGB", (width, height), _BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    if title:
        draw.text((margin, 6), title, fill=_TEXT, font=font)
    for i, (view, img, pts) in enumerate(rendered):
        left = margin + i * (panel_w + margin)
        top = title_h + margin
        _text_centre(draw, left + panel_w / 2, top, captions[view][0], font)
        _text_centre(draw, left + panel_w / 2, top + font_size + 6, captions[view][1], small)
        ox, oy = left + arrow_room, top + caption_h
        canvas.paste(img, (ox, oy))
        o = pts["origin"] + (ox, oy)
        # x along the bottom front edge, z down the left front edge, y along the top left edge
        fb = pts["z_end"] + (ox, oy)
        xe = pts["front_bottom_right"] + (ox, oy)
        _arrow(
            draw, (fb[0], fb[1] + 14), (fb[0] + min(70, xe[0] - fb[0]), fb[1] + 14), 2, "x", small, (12, 0)
        )
        _arrow(draw, (o[0] - 14, o[1]), (o[0] - 14, o[1] + min(70, fb[1] - o[1])), 2, "z", small, (0, 12))
        ye = pts["y_end"] + (ox, oy)
        direction = (ye - o) / max(float(np.hypot(*(ye - o))), 1.0)
        normal = np.array([direction[1], -direction[0]])  # to the upper left of the receding edge
        start = o + 12 * normal
        length = min(60.0, float(np.hypot(*(ye - o))))
        end = start + length * direction
        _arrow(draw, tuple(start), tuple(end), 2, "y", small, (-8, -8))
    return np.asarray(canvas, dtype=np.uint8)


def _magnified_rendering(rendering: np.ndarray, scale: int) -> np.ndarray:
    return _magnify(rendering, scale) if scale > 1 else rendering


def write_volume_images(
    folder: str | Path,
    volume: np.ndarray,
    exemplars: Mapping[str, np.ndarray] | np.ndarray | None = None,
    *,
    index: tuple[int, int, int] | None = None,
) -> list[str]:
    """Write ``slices.png``, ``cube.png`` and the mid-slices' tensor images into ``folder``.

    Per plane ``p`` in ``xy``, ``xz``, ``yz``: ``coherence_p.png`` and ``orientation_p.png``, the
    coherence (grey) and the fringe direction (hue, faded by coherence) of the structure tensor of the
    mid-slice (the study's 7x7 window, :func:`texsynth.synth.analysis.tensor.structure_tensor` defaults), each
    with its legend. Angles are counter-clockwise from the slice's column axis with up on screen, as
    in every 2-D rendering (so in an ``xz`` slice, +90 degrees points toward lower ``z``).

    Returns
    -------
    list of str
        The file names written, in ``folder``.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    vol = _check_volume(volume)
    idx = _mid_index(vol.shape, index)
    d, h, w = vol.shape
    names = ["slices.png", "cube.png"]
    title = f"volume {w} x {h} x {d} voxels (x, y, z): mid-slices (top) and their exemplars (bottom)"
    slices = slices_image(vol, exemplars, index=idx, title=title if exemplars is not None else None)
    atomic_write_bytes(out / "slices.png", image_to_png_bytes(slices.astype(np.float32) / 255.0))
    cube = cube_image(vol, index=idx)
    atomic_write_bytes(out / "cube.png", image_to_png_bytes(cube.astype(np.float32) / 255.0))
    largest = max(vol.shape)
    scale = int(min(8, max(1, round(_PANEL_TARGET / largest))))
    for plane, img in mid_slices(vol, idx).items():
        fixed = PLANE_AXES[plane][2]
        where = f"{plane} ({fixed} = {idx[_AXIS_INDEX[fixed]]})"
        tensors = structure_tensor(_unit(img).astype(np.float32))
        coh = coherence(tensors)
        grey = _magnified_rendering(coherence_image(coh), scale)
        coloured = _magnified_rendering(orientation_image(structure_direction(tensors), coherence=coh), scale)
        renderings = {
            f"coherence_{plane}.png": with_legend(grey, "coherence", title=f"coherence, {where}"),
            f"orientation_{plane}.png": with_legend(
                coloured, "composite", title=f"fringe direction and coherence, {where}"
            ),
        }
        for name, arr in renderings.items():
            atomic_write_bytes(out / name, image_to_png_bytes(arr.astype(np.float32) / 255.0))
            names.append(name)
    return names
