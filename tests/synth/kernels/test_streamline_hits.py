"""The kernel that follows an orientation field's streamlines to the first marked pixel
(synth.kernels.streamline_hits), against its plain reference."""

from __future__ import annotations

import numpy as np

from synth.kernels.streamline_hits import first_hits, first_hits_reference
from tests.synth.analysis.test_streamlines import ring_direction


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
