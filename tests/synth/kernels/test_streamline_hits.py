"""The kernel that follows an orientation field's streamlines to the first marked pixel
(texsynth.synth.kernels.streamline_hits), against its plain reference."""

from __future__ import annotations

import numpy as np

from tests.synth.analysis.test_streamlines import ring_direction
from texsynth.synth.analysis.streamlines import trace
from texsynth.synth.kernels.streamline_hits import first_hits


def first_hits_reference(
    angle: np.ndarray, label: np.ndarray, max_steps: int, step: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Plain version (non-periodic) of :func:`first_hits`' steps and hit positions, with
    :func:`texsynth.synth.analysis.streamlines.trace` (which mirrors the field outside the image where the
    kernel clamps it: the two agree wherever curves stay a pixel inside)."""
    h, w = label.shape
    starts = np.argwhere(np.ones((h, w), bool)).astype(np.float64)
    best = np.where(label.ravel() >= 0, 0, max_steps + 1)
    pos = starts.copy()
    plus = trace(angle, starts, max_steps, step=step)
    minus = trace(angle, starts, max_steps, step=step, forward=-(plus[1] - plus[0]))
    for curve in (plus, minus):
        iy = np.floor(curve[..., 0] + 0.5).astype(np.int64)
        ix = np.floor(curve[..., 1] + 0.5).astype(np.int64)
        inside = np.cumprod((iy >= 0) & (iy < h) & (ix >= 0) & (ix < w), axis=0).astype(bool)
        on = inside & (label[np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)] >= 0)
        on[0] = False
        k = np.where(on.any(axis=0), on.argmax(axis=0), max_steps + 1)
        better = k < best
        best = np.where(better, k, best)
        pos[better] = curve[k[better], np.flatnonzero(better)]
    steps = np.where(best > max_steps, -1, best)
    pos[best == 0] = starts[best == 0]
    return steps.reshape(h, w), pos.reshape(h, w, 2)


def test_first_hits_kernel_matches_the_reference() -> None:
    shape, centre = (48, 48), (23.5, 23.5)
    angle = ring_direction(shape, centre)
    label = np.full(shape, -1, np.int64)
    label[2:22, 23:25] = 0  # a cut across the rings (upwards from the centre)
    label[26:46, 10:12] = 1
    c2, s2 = np.cos(2 * angle), np.sin(2 * angle)
    steps, hit, _, _ = first_hits(c2, s2, label, 40, 1.0, False)
    ref_steps, ref_hit = first_hits_reference(angle, label, 40)
    assert (steps >= 0).mean() > 0.5
    same = steps == ref_steps
    assert same.mean() > 0.99, same.mean()
    both = same & (steps >= 0)
    err = np.abs(hit[both] - ref_hit[both]).max(axis=-1)
    assert (err < 1e-6).mean() > 0.95  # equal, but for curves passing next to the image's border, where
    assert err.max() < 0.01  # the kernel clamps the field and the reference mirrors it
