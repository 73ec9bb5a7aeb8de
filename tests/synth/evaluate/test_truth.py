"""A volume against a known answer's slices (texsynth.synth.evaluate.truth)."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.evaluate.truth import evaluate_against_truth, truth_slices
from texsynth.synth.io.laminar import onion_volume


@pytest.fixture(scope="module")
def truth() -> np.ndarray:
    return onion_volume((32, 32, 32), period=5.0, seed=1)


def test_a_block_of_the_truth_matches_its_own_slices(truth: np.ndarray) -> None:
    ref = truth_slices(truth, (32, 32, 32))
    result = evaluate_against_truth(ref, truth)
    assert result["blocks"] == 1
    for axis in "012":
        head = result["summary"]["per_axis"][axis]
        assert head["grey_kl"] == 0.0 and head["orientation_kl"] == 0.0
        assert head["coherence_ratio"] == pytest.approx(1.0) and head["contrast"] == pytest.approx(1.0)
        assert head["fringe_ks_length"] == 0.0


def test_blocks_pool_the_whole_truth_and_noise_fails(truth: np.ndarray) -> None:
    ref = truth_slices(truth, (16, 16, 16), fringes=False)
    assert ref.blocks == 8
    same = evaluate_against_truth(ref, truth[16:, :16, 16:])
    noise = np.random.default_rng(0).random((16, 16, 16)).astype(np.float32)
    worse = evaluate_against_truth(ref, noise)
    for axis in "012":
        good, bad = same["summary"]["per_axis"][axis], worse["summary"]["per_axis"][axis]
        assert 0.9 < good["coherence_ratio"] < 1.1 and bad["coherence_ratio"] < 0.7
        assert bad["grey_kl"] > 0.1 > good["grey_kl"]


def test_bad_inputs(truth: np.ndarray) -> None:
    ref = truth_slices(truth, (16, 16, 16), fringes=False)
    with pytest.raises(InvalidInput, match="volume"):
        evaluate_against_truth(ref, truth)
    with pytest.raises(InvalidParameter, match="'block'"):
        truth_slices(truth, (64, 16, 16))
    with pytest.raises(InvalidParameter, match="'axes'"):
        truth_slices(truth, (16, 16, 16), axes=(0, 3))
    with pytest.raises(InvalidInput, match="truth"):
        truth_slices(truth[0], (16, 16, 16))
