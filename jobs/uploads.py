"""Reading uploads and encoding small images, for the API (validation) and the worker (the run).

Decoding goes through the engine's :func:`synth.io.load_image`, so that the service accepts exactly
what the library and the CLI accept. The service's own pixel limit is checked first, from the image
header only (:func:`check_upload`): a decompression bomb is never decoded.
"""

from __future__ import annotations

import io
import warnings

import numpy as np
from PIL import Image

from synth.errors import InputTooLarge, InvalidInput, UnsupportedFormat
from synth.io import image_to_png_bytes, load_image

__all__ = ["check_upload", "decode_image", "png_bytes", "preview_png"]

# What synth.io reads; anything else is refused from the header (HTTP 415).
ALLOWED_FORMATS = frozenset({"PNG", "TIFF", "JPEG", "MPO"})


def check_upload(data: bytes, role: str, max_pixels: int) -> tuple[str, tuple[int, int]]:
    """Format and ``(height, width)`` of an uploaded image, from its header only.

    Raises :class:`UnsupportedFormat` (HTTP 415), :class:`InputTooLarge` (more than ``max_pixels``
    pixels, or a decompression bomb: HTTP 413) or :class:`InvalidInput` (empty or damaged header:
    HTTP 422), each naming ``role`` (``exemplar``, ``constraint``).
    """
    if not data:
        raise InvalidInput(role, "the file is empty")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as im:
                fmt, (w, h) = im.format, im.size
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise InputTooLarge(
            role,
            "the image declares too many pixels to decode safely "
            f"(this service's limit is {max_pixels} pixels)",
        ) from None
    except Image.UnidentifiedImageError:
        raise UnsupportedFormat(
            role, "not an image format texsynth reads; upload PNG, TIFF or JPEG"
        ) from None
    except (OSError, SyntaxError, ValueError) as exc:
        raise InvalidInput(role, f"the image header is damaged or truncated ({exc})") from None
    if fmt not in ALLOWED_FORMATS:
        raise UnsupportedFormat(role, f"{fmt} images are not supported; upload PNG, TIFF or JPEG")
    if w * h > max_pixels:
        raise InputTooLarge(
            role,
            f"{w}x{h} is {w * h} pixels, more than this service's limit of {max_pixels}; "
            "crop or downscale the image",
        )
    return fmt, (h, w)


def decode_image(data: bytes, role: str, max_pixels: int | None = None) -> np.ndarray:
    """Decode to float32 in [0, 1], ``(H, W)`` or ``(H, W, 3)``; errors name ``role``."""
    return load_image(data, name=role, max_pixels=max_pixels)


def png_bytes(image: np.ndarray) -> bytes:
    """8-bit PNG of a float image in [0, 1], or of a uint8 rendering (grey or RGB)."""
    arr = np.asarray(image)
    if arr.dtype == np.uint8:
        buf = io.BytesIO()
        Image.fromarray(arr).save(buf, format="PNG")
        return buf.getvalue()
    return image_to_png_bytes(np.clip(np.nan_to_num(arr.astype(np.float32)), 0.0, 1.0))


def preview_png(image: np.ndarray, max_side: int = 160) -> bytes:
    """A small PNG preview (longest side <= ``max_side``) of a float image or of a volume's middle slice."""
    arr = np.asarray(image, dtype=np.float32)
    if arr.ndim == 3 and arr.shape[-1] != 3:
        arr = arr[arr.shape[0] // 2]
    step = max(1, int(np.ceil(max(arr.shape[:2]) / max_side)))
    return png_bytes(arr[::step, ::step])
