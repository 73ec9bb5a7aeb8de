"""The one dtype policy: how an image's samples become the engine's float32 in [0, 1], and its bit depth.

Used by :func:`texsynth.synth.io.load_image` (files), :func:`texsynth.synth.api.synthesize` and
:func:`texsynth.synth.evaluate.evaluate_pair` (arrays), so that a picture gives the same numbers whichever way
it comes in:

- ``bool``: ``False`` -> 0, ``True`` -> 1;
- unsigned integers: divided by ``2**used - 1``, where ``used`` is the bit depth the values actually
  use (:func:`used_bits`): 12-bit camera data in a 16-bit container (values 0-4095, common for TEM
  and microscopy cameras) are scaled by 4095, not 65535, so that grey histograms on [0, 1] mean
  something; 8-bit containers are always scaled by 255;
- floats: must be finite and within [0, 1] (an array; files, where float counts are common, are
  rescaled by :func:`texsynth.synth.io.load_image` instead).

:class:`InputBits` records the container and used depths, so that outputs are written back at the
depth the input had (``output.tiff`` 16-bit with values 0-4095 for 12-bit-in-16 data).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from texsynth.synth.errors import InvalidInput

__all__ = ["InputBits", "array_to_unit", "unsigned_to_unit", "used_bits"]


@dataclass(frozen=True)
class InputBits:
    """Bits per sample of an input: of its container (1, 8, 16, 32) and those its values use."""

    container: int
    used: int

    def as_json(self) -> dict[str, int]:
        return {"container": self.container, "used": self.used}


#: Float inputs (and images a method made) have no integer depth; outputs default to 8-bit previews.
FLOAT_BITS = InputBits(32, 32)


def used_bits(arr: np.ndarray, container: int) -> int:
    """The bit depth the unsigned values of ``arr`` use within a ``container``-bit type.

    8-bit containers use 8 bits. In wider containers the smallest even depth from 8 up whose full
    scale holds the maximum: a 16-bit array whose maximum is 4095 (or any value up to it) is 12-bit.
    A genuinely 16-bit picture that is so dark that it never exceeds 4095 is read as 12-bit too: the
    data cannot tell the two apart.
    """
    if container <= 8:
        return container
    top = int(arr.max()) if arr.size else 0
    for bits in range(8, container, 2):
        if top <= 2**bits - 1:
            return bits
    return container


def unsigned_to_unit(arr: np.ndarray, *, bits: int | None = None) -> tuple[np.ndarray, InputBits]:
    """Unsigned integers (or bool) as float32 in [0, 1], scaled by the depth they use.

    ``bits`` is a depth the file's header declares (a 12-bit TIFF says 12): then it is the used depth.
    """
    if arr.dtype == bool:
        return arr.astype(np.float32), InputBits(1, 1)
    container = arr.dtype.itemsize * 8
    used = bits if bits is not None and 1 <= bits < container else used_bits(arr, container)
    return arr.astype(np.float32) / np.float32(2**used - 1), InputBits(container, used)


def array_to_unit(arr: np.ndarray, name: str) -> tuple[np.ndarray, InputBits]:
    """An array from a caller as C-contiguous float32 in [0, 1], and its depth; :class:`InvalidInput`
    naming ``name`` for any other dtype, for NaN/inf, or for floats outside [0, 1] (with how to scale)."""
    arr = np.asarray(arr)
    if arr.dtype == bool or np.issubdtype(arr.dtype, np.unsignedinteger):
        unit, depth = unsigned_to_unit(arr)
        return np.ascontiguousarray(unit), depth
    if np.issubdtype(arr.dtype, np.signedinteger):
        raise InvalidInput(
            name,
            f"{arr.dtype} array: give uint8/uint16 (scaled by their range), bool, or floats in [0, 1] "
            "(e.g. a.astype(np.uint16), or a / a.max())",
        )
    if not np.issubdtype(arr.dtype, np.floating):
        raise InvalidInput(name, f"{arr.dtype} array: give uint8, uint16, bool or float values in [0, 1]")
    if arr.size and not np.isfinite(arr).all():
        what = "NaN" if np.isnan(arr).any() else "infinite (inf)"
        raise InvalidInput(name, f"contains {what} values; only finite numbers are accepted")
    lo, hi = (float(arr.min()), float(arr.max())) if arr.size else (0.0, 0.0)
    if lo < 0.0 or hi > 1.0:
        hint = " (8-bit values as float? divide by 255)" if lo >= 0.0 and hi <= 255.0 else ""
        hint = hint or (" (16-bit values as float? divide by 65535)" if lo >= 0.0 and hi <= 65535.0 else "")
        raise InvalidInput(
            name,
            f"float values span [{lo:.6g}, {hi:.6g}], outside [0, 1]{hint}: scale them to [0, 1] "
            "first, e.g. (a - a.min()) / (a.max() - a.min()), or pass the integer array itself",
        )
    return np.ascontiguousarray(arr, dtype=np.float32), FLOAT_BITS
