"""Size limits of inputs and outputs, written once for the engine, the CLI and the service.

An input image must have at least :data:`MIN_SIDE` pixels a side, at most :data:`MAX_ASPECT_RATIO`
elongation, and at most ``max_pixels`` pixels (:data:`DEFAULT_MAX_PIXELS`, or the environment variable
``TEXSYNTH_MAX_PIXELS``); a volume at most ``max_voxels`` (:data:`DEFAULT_MAX_VOXELS`,
``TEXSYNTH_MAX_VOXELS``). An output has sides in [:data:`MIN_SIDE`, :data:`MAX_SIDE`] and at most
:data:`DEFAULT_MAX_OUTPUT` elements (``TEXSYNTH_MAX_OUTPUT``); the service may set a lower limit of
its own and passes it in. Every check raises before any work starts, naming the input or field.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from synth.errors import InputTooLarge, InvalidInput, InvalidParameter

__all__ = [
    "DEFAULT_MAX_OUTPUT",
    "DEFAULT_MAX_PIXELS",
    "DEFAULT_MAX_VOXELS",
    "MAX_ASPECT_RATIO",
    "MAX_SIDE",
    "MIN_SIDE",
    "check_image_shape",
    "check_output_size",
    "resolve_limit",
]

#: Largest image accepted by default (width * height); the environment variable
#: ``TEXSYNTH_MAX_PIXELS`` overrides it, an explicit ``max_pixels`` argument overrides both.
DEFAULT_MAX_PIXELS = 4096 * 4096
#: Largest volume accepted by default (depth * height * width, 512 MiB as float32); the
#: environment variable ``TEXSYNTH_MAX_VOXELS`` overrides it.
DEFAULT_MAX_VOXELS = 512**3
#: Largest output (pixels or voxels) by default: an 8192^2 image or a 512^3 volume.
DEFAULT_MAX_OUTPUT = 512**3
#: Longest side / shortest side above which an image is refused: a 1 x 64 strip holds no texture.
MAX_ASPECT_RATIO = 64
#: Shortest side (pixels) of a usable image: smaller than the smallest synthesis neighbourhood.
MIN_SIDE = 8
#: Longest side (pixels) of an output.
MAX_SIDE = 8192


def resolve_limit(param: str, value: int | None, env_var: str, default: int) -> int:
    """An explicit limit, else the environment variable's, else the default; positive integers only."""
    if value is None:
        raw = os.environ.get(env_var, "").strip()
        if not raw:
            return default
        try:
            value = int(raw)
        except ValueError:
            raise InvalidParameter(env_var, raw, "must be a positive whole number") from None
        param = env_var
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value <= 0:
        raise InvalidParameter(param, value, "must be a positive whole number")
    return int(value)


def check_image_shape(label: str, height: int, width: int, max_pixels: int | None) -> None:
    """Refuse zero-size, too large (if ``max_pixels``), tiny and absurdly elongated images."""
    if height == 0 or width == 0:
        raise InvalidInput(label, f"the image has zero size ({width}x{height} pixels)")
    if max_pixels is not None and width * height > max_pixels:
        raise InputTooLarge(
            label,
            f"{width}x{height} = {width * height} pixels is more than the limit of {max_pixels} "
            "(crop or downscale it, or raise TEXSYNTH_MAX_PIXELS / max_pixels)",
        )
    if min(height, width) < MIN_SIDE:
        raise InvalidInput(
            label, f"{width}x{height} pixels is too small: at least {MIN_SIDE} pixels are needed on each side"
        )
    if max(height, width) > MAX_ASPECT_RATIO * min(height, width):
        raise InvalidInput(
            label,
            f"{width}x{height} pixels is too elongated: the longer side may be at most {MAX_ASPECT_RATIO} "
            "times the shorter",
        )


def check_output_size(
    size: Sequence[object],
    ndim: int,
    *,
    names: Sequence[str] | None = None,
    max_elements: int | None = None,
) -> tuple[int, ...]:
    """An output shape ``(H, W)`` or ``(D, H, W)`` as ints, or :class:`InvalidParameter` naming the field.

    ``names`` are the fields reported for each axis (the service's ``depth``/``height``/``width``);
    by default the whole ``size``. ``max_elements`` defaults to ``TEXSYNTH_MAX_OUTPUT`` or
    :data:`DEFAULT_MAX_OUTPUT`.
    """
    values = tuple(size)
    if len(values) != ndim:
        kind = "an image (H, W)" if ndim == 2 else "a volume (D, H, W)"
        raise InvalidParameter("size", values, f"needs {ndim} values: this method makes {kind}")
    fields = tuple(names) if names is not None else ("size",) * ndim
    out = []
    for field, value in zip(fields, values, strict=True):
        shown = value if names is not None else values
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer) or int(value) != value:
            raise InvalidParameter(field, shown, "must be a whole number of pixels")
        if not MIN_SIDE <= value <= MAX_SIDE:
            raise InvalidParameter(field, shown, f"each side must lie in [{MIN_SIDE}, {MAX_SIDE}] pixels")
        out.append(int(value))
    limit = resolve_limit("max_elements", max_elements, "TEXSYNTH_MAX_OUTPUT", DEFAULT_MAX_OUTPUT)
    total = math.prod(out)
    if total > limit:
        unit = "voxels" if ndim == 3 else "pixels"
        raise InvalidParameter(
            fields[-1] if names is not None else "size",
            out[-1] if names is not None else values,
            f"an output of {total} {unit} is more than the limit of {limit}; ask for a smaller size",
        )
    return tuple(out)
