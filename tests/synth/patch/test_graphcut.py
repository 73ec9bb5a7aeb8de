"""Graph-cut seam against a brute-force minimum cut on a tiny grid."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from texsynth.synth.patch.graphcut import graph_cut_mask, overlap_graph
from texsynth.synth.patch.layout import Strips, overlap_mask


def _cut_value(graph, labels_old: np.ndarray) -> int:
    """Capacity of the edges from the old side to the new side."""
    coo = graph.tocoo()
    return int(
        sum(
            c
            for u, v, c in zip(coo.row, coo.col, coo.data, strict=True)
            if labels_old[u] and not labels_old[v]
        )
    )


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("kind", ["left", "L"])
def test_graph_cut_is_the_brute_force_minimum(seed, kind):
    rng = np.random.default_rng(seed)
    w, o = 5, 2
    old, new = rng.random((w, w, 3)), rng.random((w, w, 3))
    mask = overlap_mask(w, o, kind)
    graph, nodes, source, sink = overlap_graph(old, new, mask)
    n = graph.shape[0] - 2
    coo = graph.tocoo()
    tied_old = set(coo.col[coo.row == source])
    tied_new = set(coo.row[coo.col == sink])
    free = [v for v in range(n) if v not in tied_old and v not in tied_new]
    assert len(free) <= 14
    best = None
    for bits in itertools.product((False, True), repeat=len(free)):
        labels = np.zeros(n + 2, dtype=bool)
        labels[list(tied_old)] = True
        labels[source] = True
        labels[np.array(free, dtype=int)[np.array(bits, dtype=bool)]] = True
        value = _cut_value(graph, labels)
        best = value if best is None else min(best, value)
    got_new = graph_cut_mask(old, new, mask)
    labels = np.zeros(n + 2, dtype=bool)
    labels[source] = True
    labels[nodes[mask & ~got_new]] = True
    assert _cut_value(graph, labels) == best
    assert got_new[~mask].all()


def test_graph_cut_prefers_the_zero_error_seam():
    w = 8
    old = np.zeros((w, w))
    new = np.ones((w, w))
    new[:, :2] = 0.0  # agrees with the old image on the first two overlap columns
    got = graph_cut_mask(old, new, overlap_mask(w, 4, "left"))
    assert not got[:, 0].any() and got[:, 2:].all()


def test_graph_cut_through_two_opposite_strips():
    """Left and right strips (a wrapped patch): the new patch agrees with the old output on one column
    of each strip; the seams run there, and both outer borders keep the old values."""
    w = 10
    old = np.zeros((w, w))
    new = np.ones((w, w))
    new[:, 1] = 0.0  # agrees inside the left strip (columns 0-2)
    new[:, 8] = 0.0  # and inside the right strip (columns 7-9)
    known = Strips(left=3, right=3).mask(w)
    got = graph_cut_mask(old, new, known)
    assert not got[:, 0].any() and not got[:, 9].any()
    assert got[:, 2:8].all()


def test_graph_cut_keeps_sealed_pixels_old():
    """``keep_old`` ties more pixels to the old side: the top strip's left end of a row's first patch
    (except the one next to the new part, which the new side claims as on every border)."""
    w = 8
    rng = np.random.default_rng(0)
    old, new = rng.random((w, w)), rng.random((w, w))
    known = Strips(top=3).mask(w)
    sealed = np.zeros((w, w), dtype=bool)
    sealed[:3, 0] = True
    got = graph_cut_mask(old, new, known, sealed)
    assert not got[:2, 0].any() and got[2:, :].all()
