"""The seam contrast of a source map: known answers."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.errors import InvalidInput
from texsynth.synth.evaluate.breaks import seams_from_labels, seams_from_sources
from texsynth.synth.evaluate.patches import seam_contrast


def test_a_step_on_the_seam_gives_its_energy_over_the_interior() -> None:
    img = np.tile(np.array([0.0, 0.1, 0.2, 0.9, 1.0, 1.1]), (4, 1))
    out = seam_contrast(img, seams_from_labels(np.tile([0, 0, 0, 1, 1, 1], (4, 1))))
    # seam edges: 4 of 0.7^2; coherent: 16 of 0.1^2 across columns and 18 of 0 across rows
    assert out["seam"] == pytest.approx(0.49)
    assert out["coherent"] == pytest.approx(16 * 0.01 / 34)
    assert out["ratio"] == pytest.approx(0.49 / (0.16 / 34))
    assert out["coherent_share"] == pytest.approx(34 / 38)


def test_a_verbatim_copy_has_no_seam_and_a_seamless_cut_scores_one() -> None:
    rows, cols = np.mgrid[0:6, 0:8]
    copy = seams_from_sources(np.stack([rows + 3, cols + 5], axis=-1))
    out = seam_contrast(np.random.default_rng(0).random((6, 8)), copy)
    assert out["coherent_share"] == 1.0 and np.isnan(out["ratio"])
    # white noise cut anywhere: the seam edges are like any other -> ratio about 1
    noise = np.random.default_rng(1).random((64, 64))
    cut = seam_contrast(noise, seams_from_labels(np.mgrid[0:64, 0:64][1] >= 32))
    assert cut["ratio"] == pytest.approx(1.0, abs=0.15)


def test_seams_of_another_shape_are_refused() -> None:
    with pytest.raises(InvalidInput, match="seams"):
        seam_contrast(np.zeros((5, 5)), seams_from_labels(np.zeros((4, 4), int)))
