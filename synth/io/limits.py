"""Size limits of inputs and outputs, written once for the engine, the CLI and the service.

An input image must have at least :data:`MIN_SIDE` pixels a side, at most :data:`MAX_ASPECT_RATIO`
elongation, and at most ``max_pixels`` pixels; a volume at most ``max_voxels``. An output has sides in
[:data:`MIN_SIDE`, :data:`MAX_SIDE`] and at most ``max_elements`` pixels or voxels. Every check raises
before any work starts, naming the input or field.

:data:`LIMITS` holds each limit's one environment variable and default, and :func:`limit_from_env`
is the one place that reads them: the engine through :func:`resolve_limit` (an explicit argument
wins), the service's :class:`texsynth.jobs.config.Settings` through its ``from_env``. The service's own output
limits (``max_output_pixels`` for images, ``max_output_voxels`` for volumes) are passed in by the API
and the worker.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from texsynth.synth.errors import InputTooLarge, InvalidInput, InvalidParameter

__all__ = [
    "DEFAULT_MAX_OUTPUT",
    "DEFAULT_MAX_PIXELS",
    "DEFAULT_MAX_VOXELS",
    "DEFAULT_SERVICE_MAX_OUTPUT",
    "DEFAULT_SERVICE_MAX_VOXELS",
    "LIMITS",
    "MAX_ASPECT_RATIO",
    "MAX_SIDE",
    "MIN_SIDE",
    "check_image_shape",
    "check_output_size",
    "limit_from_env",
    "resolve_limit",
]

#: Largest input image accepted by default (width * height), by the engine and the service.
DEFAULT_MAX_PIXELS = 4096 * 4096
#: Largest input volume accepted by default (depth * height * width, 512 MiB as float32).
DEFAULT_MAX_VOXELS = 512**3
#: Largest output (pixels or voxels) the engine makes by default: an 8192^2 image or a 512^3 volume.
DEFAULT_MAX_OUTPUT = 512**3
#: Largest 2-D output one job of the service may ask for by default (width * height).
DEFAULT_SERVICE_MAX_OUTPUT = 4096 * 4096
#: Largest volume one job of the service may ask for by default (width * height * depth); whether it
#: runs is then the admission's estimate of its memory and time (``texsynth.app.admission``).
DEFAULT_SERVICE_MAX_VOXELS = 512**3
#: Longest side / shortest side above which an image is refused: a 1 x 64 strip holds no texture.
MAX_ASPECT_RATIO = 64
#: Shortest side (pixels) of a usable image: smaller than the smallest synthesis neighbourhood.
MIN_SIDE = 8
#: Longest side (pixels) of an output.
MAX_SIDE = 8192


@dataclass(frozen=True)
class Limit:
    """A limit's environment variable, its default, and the older names still read (deprecated)."""

    env: str
    default: int
    deprecated: tuple[str, ...] = ()


#: Every size limit by name (the :class:`texsynth.jobs.config.Settings` field of the same name, where the
#: service has one): one environment variable each.
LIMITS: dict[str, Limit] = {
    "max_input_pixels": Limit("TEXSYNTH_MAX_INPUT_PIXELS", DEFAULT_MAX_PIXELS, ("TEXSYNTH_MAX_PIXELS",)),
    "max_input_voxels": Limit("TEXSYNTH_MAX_VOXELS", DEFAULT_MAX_VOXELS),
    "max_output": Limit("TEXSYNTH_MAX_OUTPUT", DEFAULT_MAX_OUTPUT),
    "max_output_pixels": Limit("TEXSYNTH_MAX_OUTPUT_PIXELS", DEFAULT_SERVICE_MAX_OUTPUT),
    "max_output_voxels": Limit("TEXSYNTH_MAX_OUTPUT_VOXELS", DEFAULT_SERVICE_MAX_VOXELS),
}


def limit_from_env(name: str, environ: Mapping[str, str] | None = None) -> tuple[str, str] | None:
    """``(variable, raw value)`` of limit ``name`` from the environment (its variable, else a
    deprecated one), or ``None`` when none is set."""
    env = os.environ if environ is None else environ
    limit = LIMITS[name]
    for variable in (limit.env, *limit.deprecated):
        raw = env.get(variable, "").strip()
        if raw:
            return variable, raw
    return None


def resolve_limit(param: str, value: int | None, name: str) -> int:
    """An explicit limit, else limit ``name``'s environment variable, else its default; positive
    integers only (``param`` is the argument named in errors)."""
    if value is None:
        found = limit_from_env(name)
        if found is None:
            return LIMITS[name].default
        param, raw = found
        try:
            value = int(raw)
        except ValueError:
            raise InvalidParameter(param, raw, "must be a positive whole number") from None
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
            f"(crop or downscale it, or raise {LIMITS['max_input_pixels'].env} / max_pixels)",
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
    by default the whole ``size``. ``max_elements`` defaults to limit ``max_output``
    (``TEXSYNTH_MAX_OUTPUT``, else :data:`DEFAULT_MAX_OUTPUT`).
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
    limit = resolve_limit("max_elements", max_elements, "max_output")
    total = math.prod(out)
    if total > limit:
        unit = "voxels" if ndim == 3 else "pixels"
        raise InvalidParameter(
            fields[-1] if names is not None else "size",
            out[-1] if names is not None else values,
            f"an output of {total} {unit} is more than the limit of {limit}; ask for a smaller size",
        )
    return tuple(out)
