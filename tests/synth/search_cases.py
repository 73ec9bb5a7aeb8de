"""Small cases shared by the pixel engine's and its search kernel's tests: smooth noise images,
candidate windows, and the kernel-against-reference comparison of whole source-map syntheses."""

from __future__ import annotations

import numpy as np
import pytest

import texsynth.synth.pixel.synthesis as synthesis
from texsynth.synth.kernels.pixel_search import synthesize_levels_reference
from texsynth.synth.pixel.synthesis import CandidateWindow, synthesize_source_map

__all__ = ["_rng_image", "_run_both", "_striped_window", "_tiled_window", "synthesize_with_reference"]


def synthesize_with_reference(**kwargs: object) -> tuple:
    """:func:`synthesize_source_map` with the plain NumPy search (``synthesize_levels_reference``) in
    place of the numba kernel: the driver calls whatever its module's ``synthesize_levels`` is."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(synthesis, "synthesize_levels", synthesize_levels_reference)
        return synthesize_source_map(**kwargs)  # type: ignore[arg-type]


def _rng_image(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    noise = np.random.default_rng(seed).random(shape).astype(np.float32)
    smooth = gaussian_filter(noise, (1.0, 1.0) + (0,) * (len(shape) - 2))
    return ((smooth - smooth.min()) / (smooth.max() - smooth.min())).astype(np.float32)


def _run_both(**kwargs: object) -> None:
    fast, fast_report = synthesize_source_map(**kwargs)  # type: ignore[arg-type]
    slow, slow_report = synthesize_with_reference(**kwargs)
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(a, b)
    for key, value in fast_report.mean_best_distance.items():
        assert value == pytest.approx(slow_report.mean_best_distance[key], rel=1e-4, abs=1e-7)


def _striped_window(ex_shape: tuple[int, int], out_shape: tuple[int, int], span: int) -> CandidateWindow:
    """Exemplar columns in 4 classes (stripes of 5), output rows wanting class ``row % 4``."""
    cls = np.broadcast_to(np.arange(ex_shape[1]) // 5 % 4, ex_shape).copy()
    cls[:, :5] = -1  # never searched
    want = np.broadcast_to((np.arange(out_shape[0]) % 4)[:, None], out_shape).copy()
    return CandidateWindow([cls], [want], period=4, span=span)


def _tiled_window(
    tile: np.ndarray, n_tiles: int, out_shape: tuple[int, int], period: int
) -> tuple[np.ndarray, CandidateWindow]:
    """``n_tiles`` copies of ``tile`` side by side, class = copy; output row ``r`` wants class
    ``r % n_tiles``; the transfer maps a copy's positions to the tile's own and back."""
    h, w = tile.shape[:2]
    ex = np.ascontiguousarray(np.concatenate([tile] * n_tiles, axis=1))
    cls = np.broadcast_to(np.arange(n_tiles * w) // w, (h, n_tiles * w)).copy()
    want = np.broadcast_to((np.arange(out_shape[0]) % n_tiles)[:, None], out_shape).copy()
    to_common = np.zeros((n_tiles, 2, 3))
    to_common[:, 0, 0] = to_common[:, 1, 1] = 1.0
    from_common = to_common.copy()
    to_common[:, 1, 2] = -w * np.arange(n_tiles)
    from_common[:, 1, 2] = w * np.arange(n_tiles)
    return ex, CandidateWindow(
        [cls], [want], period=period, span=0, transfer_levels=[(to_common, from_common)]
    )
