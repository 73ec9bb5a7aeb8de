"""Neighbourhood offsets (texsynth.synth.grid.neighbourhood) and scan orders (texsynth.synth.grid.scan)."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth import InvalidParameter
from texsynth.synth.grid.neighbourhood import neighbourhood_offsets, parent_offsets
from texsynth.synth.grid.scan import SCAN_ORDERS, hilbert_points, morton_points, scan_order


def test_causal_neighbourhood_is_the_raster_past() -> None:
    offs = neighbourhood_offsets(5, "causal")
    assert len(offs) == 12
    assert all(dy < 0 or (dy == 0 and dx < 0) for dy, dx in offs)
    assert len(neighbourhood_offsets(5, "square")) == 24
    assert [0, 0] not in neighbourhood_offsets(5, "square").tolist()
    assert [0, 0] in parent_offsets(3).tolist() and len(parent_offsets(3)) == 9


@pytest.mark.parametrize("size", [4, 1, 0])
def test_neighbourhood_size_must_be_odd_and_at_least_3(size: int) -> None:
    with pytest.raises(InvalidParameter, match="neighbourhood_size"):
        neighbourhood_offsets(size)


@pytest.mark.parametrize("kind", SCAN_ORDERS)
@pytest.mark.parametrize("shape", [(7, 5), (8, 8), (3, 4, 5)])
def test_every_scan_order_visits_every_position_once(kind: str, shape: tuple[int, ...]) -> None:
    order = scan_order(shape, kind, np.random.default_rng(0))
    assert sorted(order.tolist()) == list(range(int(np.prod(shape))))


@pytest.mark.parametrize("ndim", [2, 3])
def test_hilbert_curve_moves_one_step_at_a_time(ndim: int) -> None:
    pts = hilbert_points(ndim, 3)
    assert np.abs(np.diff(pts, axis=0)).sum(axis=1).tolist() == [1] * (len(pts) - 1)


def test_morton_order_known_answer() -> None:
    assert morton_points(2, 1).tolist() == [[0, 0], [0, 1], [1, 0], [1, 1]]
    assert scan_order((4, 4), "morton")[:8].tolist() == [0, 1, 4, 5, 2, 3, 6, 7]


def test_random_scan_needs_a_generator() -> None:
    with pytest.raises(InvalidParameter, match="seeded"):
        scan_order((4, 4), "random")
