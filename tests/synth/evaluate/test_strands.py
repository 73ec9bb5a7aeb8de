"""Grey levels along strands (texsynth.synth.evaluate.strands)."""

from __future__ import annotations

import numpy as np

from texsynth.synth.evaluate.strands import exemplar_strand_grey, strand_grey
from texsynth.synth.io.patterns import wood_grain


def _bands(shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    """Horizontal bands 4 px wide, each with its own grey level (strands along the rows)."""
    levels = np.random.default_rng(seed).uniform(0.2, 0.8, shape[0] // 4 + 1)
    return np.repeat(levels[np.arange(shape[0]) // 4][:, None], shape[1], axis=1).astype(np.float32)


def test_strands_of_constant_grey_score_zero_and_across_them_more_than_one() -> None:
    img = _bands((64, 64))
    along = strand_grey(img, np.zeros(img.shape))  # strand direction 0: along the rows
    assert along["along"] < 1e-12 and along["ratio"] < 1e-9
    across = strand_grey(img, np.full(img.shape, np.pi / 2))
    assert across["ratio"] > 1.0


def test_blotches_along_strands_raise_the_ratio_and_noise_scores_about_one() -> None:
    img = _bands((64, 64))
    blotchy = img.copy()
    blotchy[:, 32:] = _bands((64, 32), seed=1)  # every band switches grey level halfway along
    angle = np.zeros(img.shape)
    assert strand_grey(blotchy, angle)["ratio"] > 0.2 > strand_grey(img, angle)["ratio"]
    noise = np.random.default_rng(0).random((64, 64))
    assert 0.9 < strand_grey(noise, angle)["ratio"] < 1.1


def test_wood_grain_keeps_its_grey_along_its_own_fibres() -> None:
    ex = wood_grain((96, 96), seed=1)
    assert exemplar_strand_grey(ex)["ratio"] < 0.1
    assert strand_grey(ex, np.zeros(ex.shape))["ratio"] > 1.0  # across the fibres
