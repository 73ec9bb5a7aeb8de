"""Patch layout and the masked FFT search against a direct SSD."""

from __future__ import annotations

import numpy as np
import pytest

from synth.patch.layout import PatchLayout, overlap_mask
from synth.patch.search import PatchSearcher, candidates_within, k_nearest


def test_layout_covers_size_and_kinds():
    layout = PatchLayout((50, 37), 10, 3)
    gh, gw = layout.grown_shape
    assert gh >= 50 and gw >= 37 and gh - layout.step < 50
    kinds = {(i, j): k for i, j, _, _, k in layout.patches()}
    assert kinds[(0, 0)] == "none" and kinds[(0, 1)] == "left"
    assert kinds[(1, 0)] == "top" and kinds[(1, 1)] == "L"
    desc = layout.describe()
    assert desc["seam_rows"] == [7, 14, 21, 28, 35, 42] and desc["step"] == 7


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("kind", ["left", "top", "L"])
def test_masked_ssd_matches_direct(channels, kind):
    rng = np.random.default_rng(0)
    ex = rng.random((19, 23, channels))
    template = rng.random((6, 6, channels))
    mask = overlap_mask(6, 2, kind)
    got = PatchSearcher(ex, 6).ssd(template, mask)
    want = np.array(
        [
            [np.sum(mask[..., None] * (ex[y : y + 6, x : x + 6] - template) ** 2) for x in range(18)]
            for y in range(14)
        ]
    )
    np.testing.assert_allclose(got, want, atol=1e-10)


def test_grey_search_finds_the_patch_itself():
    rng = np.random.default_rng(1)
    ex = rng.random((30, 30))
    searcher = PatchSearcher(ex, 8)
    d = searcher.ssd(ex[11:19, 4:12], overlap_mask(8, 3, "L"))
    assert k_nearest(d, 3)[0] == np.ravel_multi_index((11, 4), searcher.positions_shape)
    assert np.allclose(searcher.patches(k_nearest(d, 1))[0][..., 0], ex[11:19, 4:12])


def test_candidates_within_tolerance():
    d = np.array([[1.0, 1.05, 1.2], [3.0, 1.09, 0.99999]])
    assert set(candidates_within(d, 0.1)) == {0, 1, 4, 5}
    assert list(k_nearest(d, 2)) == [5, 0]
