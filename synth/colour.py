"""The engine's dtype and colour policy, written once: float32 images, and one grey conversion.

Images are ``float32`` in [0, 1], ``(H, W)`` grey or ``(H, W, 3)`` RGB (ALGORITHMS.md, "Conventions").
Colour becomes grey by the ITU-R BT.601 luma ``0.299 R + 0.587 G + 0.114 B`` (:data:`LUMA_WEIGHTS`):
the weights of Pillow's ``convert("L")`` and of ImageJ's weighted conversion, so a grey image made
here agrees with what a materials scientist's tools show. (scikit-image's ``rgb2gray`` uses BT.709
weights; the engine does not.) Loading, evaluation, rendering and the methods all call
:func:`to_grey`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LUMA_WEIGHTS", "as_float32", "to_grey"]

#: ITU-R BT.601 luma weights of R, G, B.
LUMA_WEIGHTS: tuple[float, float, float] = (0.299, 0.587, 0.114)


def as_float32(image: np.ndarray) -> np.ndarray:
    """``image`` as a C-contiguous float32 array (no copy when it already is one)."""
    return np.ascontiguousarray(image, dtype=np.float32)


def to_grey(image: np.ndarray, dtype: type[np.floating] = np.float32) -> np.ndarray:
    """Grey ``(H, W)`` of ``dtype`` from a grey ``(H, W)`` or RGB ``(H, W, 3)`` image.

    RGB is weighted by :data:`LUMA_WEIGHTS`, summed in float64 then cast, so the result does not
    depend on the input's dtype. Other shapes are returned cast but unchanged: callers that need
    a 2-D image check the shape themselves and name the input in their error.
    """
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[-1] == 3:
        arr = arr.astype(np.float64, copy=False) @ np.asarray(LUMA_WEIGHTS, dtype=np.float64)
    return np.ascontiguousarray(arr, dtype=dtype)
