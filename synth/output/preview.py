"""A small PNG preview of an image, or of a volume's middle slice, for progress reports."""

from __future__ import annotations

import numpy as np

from texsynth.synth.io import image_to_png_bytes

__all__ = ["preview_png"]


def preview_png(image: np.ndarray, max_side: int = 160) -> bytes:
    """8-bit PNG of ``image`` (float, grey/RGB, or a ``(D, H, W)`` volume's middle slice), longest side
    at most ``max_side`` (every n-th pixel); NaN (not yet synthesized) shows black."""
    arr = np.asarray(image, dtype=np.float32)
    if arr.ndim == 3 and arr.shape[-1] != 3:
        arr = arr[arr.shape[0] // 2]
    step = max(1, int(np.ceil(max(arr.shape[:2]) / max_side)))
    return image_to_png_bytes(np.clip(np.nan_to_num(arr[::step, ::step]), 0.0, 1.0))
