"""The fringe skeleton's graph kernel (texsynth.synth.kernels.fringe_graph) against its plain reference,
the NumPy/SciPy pruning and measuring of texsynth.synth.analysis.fringes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage as ndi
from skimage.draw import line
from skimage.morphology import skeletonize

from texsynth.synth.analysis import fringes
from texsynth.synth.kernels.fringe_graph import PRUNE_ROUNDS, skeleton_paths


def _skeletons() -> list[np.ndarray]:
    """Skeletons of smoothed noise (junctions, spurs, loops), raw noise (not thin) and drawn lines."""
    rng = np.random.default_rng(7)
    out = []
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(8, 80, 2))
        img = ndi.gaussian_filter(rng.random((h, w)), rng.uniform(0.7, 3.0))
        out.append(skeletonize(img > np.quantile(img, rng.uniform(0.3, 0.8))))
        out.append(rng.random((h, w)) < rng.uniform(0.05, 0.5))
    drawn = np.zeros((40, 40), bool)
    for r0, c0, r1, c1 in ((5, 5, 25, 25), (30, 2, 30, 37), (2, 35, 20, 20), (10, 10, 10, 12)):
        drawn[line(r0, c0, r1, c1)] = True
    out += [drawn, np.zeros((9, 9), bool), np.ones((8, 8), bool)]
    return out


@pytest.mark.parametrize("min_length", [0.0, 3.0, 9.0, 15.5])
def test_kernel_matches_the_reference(min_length: float) -> None:
    checked_loops = checked_paths = 0
    for skel in _skeletons():
        prune = min_length > 0
        ref_skel = fringes._prune_branches(skel, min_length) if prune else skel
        ref = fringes._measure(ref_skel)
        got = skeleton_paths(np.ascontiguousarray(skel), min_length, prune)
        assert np.array_equal(got[0], ref_skel)
        for a, b in zip(got[1:6], ref[:5], strict=True):
            assert a.shape == b.shape
            assert np.array_equal(a, b)  # lengths too: the same bits on these cases
        assert got[6] == ref[5]
        checked_loops += got[6]
        checked_paths += len(got[4])
    assert checked_loops > 0 and checked_paths > 100  # the cases reach loops and many paths


def test_rounds_and_measures_agree_with_the_analysis() -> None:
    assert PRUNE_ROUNDS == fringes._PRUNE_ROUNDS
    skel = _skeletons()[0]
    numpy_path = fringes._measure(fringes._prune_branches(skel, 9.0))
    # measure_skeleton goes through the kernel (numba is loaded here)
    measured = fringes.measure_skeleton(skel, min_length=9.0)
    assert measured.count == int(np.sum((numpy_path[3] >= 9.0) & (numpy_path[3] > 0)))
