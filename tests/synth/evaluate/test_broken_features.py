"""The broken-feature measure (texsynth.synth.evaluate.broken_features) on constructed known-answer images."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.evaluate import (
    Seams,
    broken_features,
    broken_features_from_masks,
    feature_endpoints,
    seams_from_labels,
    seams_from_sources,
)
from texsynth.synth.evaluate.breaks import count_kinks, seam_crossings

N = 64
ROWS = np.arange(4, 60, 6)  # horizontal feature lines, all inside the 3 px margin


def _lines() -> np.ndarray:
    mask = np.zeros((N, N), dtype=bool)
    mask[ROWS, :] = True
    return mask


def _dashes() -> np.ndarray:
    """Exemplar: horizontal dashes 10 px long with 2 px gaps: two endpoints per dash."""
    mask = np.zeros((N, N), dtype=bool)
    for start in range(0, N, 12):
        mask[ROWS, start : start + 10] = True
    return mask


def _split() -> Seams:
    labels = np.zeros((N, N), dtype=int)
    labels[:, 32:] = 1  # one vertical seam between columns 31 and 32
    return seams_from_labels(labels)


def test_endpoints_of_lines_dashes_and_specks():
    m = np.zeros((9, 9), dtype=bool)
    m[2, 1:8] = True  # a line: two ends
    m[6, 4] = True  # a speck: one isolated pixel
    m[4:7, 0] = True  # a short vertical line
    assert sorted(map(tuple, np.argwhere(feature_endpoints(m)).tolist())) == [
        (2, 1),
        (2, 7),
        (4, 0),
        (6, 0),
        (6, 4),
    ]
    ring = np.zeros((7, 7), dtype=bool)
    ring[1, 1:6] = ring[5, 1:6] = ring[1:6, 1] = ring[1:6, 5] = True
    assert not feature_endpoints(ring).any()  # a closed curve has no end


def test_continuous_features_across_a_seam_are_not_broken():
    res = broken_features_from_masks(_lines(), _dashes(), _split())
    assert res["seam_endpoints"] == 0 and res["ratio"] == 0.0 and res["per_length"] == 0.0


def test_features_cut_at_a_seam_known_answer():
    out = _lines()
    out[:, 31:33] = False  # every line stops one pixel before the seam, on both sides
    res = broken_features_from_masks(out, _dashes(), _split())
    margin = 3  # ceil(radius) + 1
    interior = N - 2 * margin
    # the seam: 58 unit edges between columns 31 and 32; the band: columns 30..33 (centres within 2 px)
    assert res["seam_length"] == interior
    assert res["band_pixels"] == 4 * interior
    assert res["seam_endpoints"] == 2 * len(ROWS)  # columns 30 and 33 of every line
    assert res["per_length"] == pytest.approx(2 * len(ROWS) / interior)
    # exemplar: dash ends inside the margin-free area (columns 3..60):
    # starts 12, 24, 36, 48 and ends 9, 21, 33, 45, 57
    ends_per_row = len([c for c in range(0, N, 12) if margin <= c < N - margin]) + len(
        [c + 9 for c in range(0, N, 12) if margin <= c + 9 < N - margin]
    )
    rho = ends_per_row * len(ROWS) / interior**2
    assert res["exemplar_density"] == pytest.approx(rho)
    assert res["density_ratio"] == pytest.approx((2 * len(ROWS) / (4 * interior)) / rho)
    assert res["expected_per_length"] == pytest.approx(rho * 4 * interior / interior)
    # per feature pixel: the band holds columns 30 and 33 of every line (2 feature pixels, 2 ends);
    # the exemplar's dashes have 10 ends per 48 feature pixels a row (columns 3..60)
    assert res["band_features"] == 2 * len(ROWS)
    assert res["exemplar_end_rate"] == pytest.approx(10 / 48)
    assert res["end_ratio"] == pytest.approx(48 / 10)
    # straight dashes make no kink at the virtual seams; the cut lines do not cross the seam
    assert res["exemplar_kink_rate"] == 0.0 and res["seam_crossings"] == 0
    assert res["ratio"] == pytest.approx(res["end_ratio"])


def test_seams_from_sources_follow_verbatim_copies():
    rows, cols = np.mgrid[0:8, 0:8]
    sources = np.stack([rows + 10, cols + 20], axis=-1)
    s = seams_from_sources(sources)
    assert not s.across_cols.any() and not s.across_rows.any()  # one verbatim copy: no seam
    sources[:, 4:] += np.array([3, 0])  # the right half copied from 3 rows lower
    s = seams_from_sources(sources)
    assert s.across_cols[:, 3].all() and s.across_cols.sum() == 8 and not s.across_rows.any()
    assert np.array_equal(np.flatnonzero(s.pixels().any(axis=0)), [3, 4])


def test_measure_on_images_sees_broken_lines():
    """The detector path: drawn bright lines, continuous vs shifted by half a period at the seam."""
    img = np.zeros((N, N), dtype=np.float32)
    img[ROWS, :] = 1.0
    ex = np.zeros((N, N), dtype=np.float32)
    for start in range(0, N, 12):
        ex[ROWS, start : start + 10] = 1.0
    shifted = img.copy()
    shifted[:, 32:] = np.roll(img[:, 32:], 3, axis=0)
    opts = {"features": "ridges"}
    good = broken_features(img, ex, _split(), **opts)
    bad = broken_features(shifted, ex, _split(), **opts)
    assert good["seam_endpoints"] == 0
    assert bad["seam_endpoints"] >= len(ROWS) and bad["ratio"] > 1.0


def test_bad_arguments_name_the_field():
    with pytest.raises(InvalidInput, match="seams"):
        broken_features_from_masks(np.zeros((10, 12), bool), _dashes(), _split())
    with pytest.raises(InvalidParameter, match="radius"):
        broken_features_from_masks(_lines(), _dashes(), _split(), radius=0.0)
    with pytest.raises(InvalidInput, match="mask"):
        feature_endpoints(np.zeros((4, 4)))
    with pytest.raises(InvalidInput, match="sources"):
        seams_from_sources(np.zeros((4, 4)))


def _seam_at(col: int, shape=(16, 20)) -> Seams:
    labels = np.zeros(shape, dtype=int)
    labels[:, col:] = 1
    return seams_from_labels(labels)


def test_kinks_known_answers():
    """A straight line across a seam: 0 breaks; a line ending at it: 1 break; a kinked line: 1 kink."""
    seam = _seam_at(10)
    straight = np.zeros((16, 20), dtype=bool)
    straight[8, 2:18] = True
    assert count_kinks(straight, seam) == (1, 0)
    ends = np.zeros((16, 20), dtype=bool)
    ends[8, 2:10] = True  # stops at the seam, nothing on the other side
    assert count_kinks(ends, seam) == (0, 0) and seam_crossings(ends, seam) == []
    kinked = np.zeros((16, 20), dtype=bool)
    kinked[8, 2:10] = True
    kinked[[7, 6, 5, 4, 3], [10, 11, 12, 13, 14]] = True  # turns by 45 degrees at the seam
    assert count_kinks(kinked, seam) == (1, 1)
    bent = np.zeros((16, 20), dtype=bool)
    bent[8, 2:10] = True
    bent[[8, 8, 7, 7, 7, 6], [10, 11, 12, 13, 14, 15]] = True  # about 15 degrees: continues
    assert count_kinks(bent, seam) == (1, 0)
    assert count_kinks(kinked, seam, angle=np.radians(50)) == (1, 0)
    # the same shapes in the full measure (exemplar: straight dashes, so no kink is natural)
    ex = np.zeros((16, 20), dtype=bool)
    ex[[4, 8, 12], 1:8] = ex[[4, 8, 12], 10:18] = True
    for mask, ends_, kinks in ((straight, 0, 0), (ends, 1, 0), (kinked, 0, 1)):
        res = broken_features_from_masks(mask, ex, seam, radius=2.0)
        assert (res["seam_endpoints"], res["seam_kinks"]) == (ends_, kinks)
        assert (res["ratio"] > 0) == (ends_ + kinks > 0)


def test_one_patch_is_one_piece_even_where_a_warp_moved_its_pixels():
    rows, cols = np.mgrid[0:6, 0:8]
    sources = np.stack([rows, cols], axis=-1)
    sources[2:4, 2:4] += np.array([1 << 32, 0])  # pixels a warp moved: they continue nothing
    labels = np.zeros((6, 8), dtype=int)
    assert seams_from_sources(sources).across_cols.sum() > 0
    same = seams_from_sources(sources, labels)
    assert not same.across_cols.any() and not same.across_rows.any()
    labels[:, 4:] = 1  # across two patches, the source rule decides
    split = seams_from_sources(sources, labels)
    assert split.across_cols[:, 3].tolist() == [False, False, True, True, False, False]
    with pytest.raises(InvalidInput, match="labels"):
        seams_from_sources(sources, labels[:3])
