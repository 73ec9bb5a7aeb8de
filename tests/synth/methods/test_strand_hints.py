"""Hints laid along the constraint's strands (texsynth.synth.methods.strand_hints)."""

from __future__ import annotations

import numpy as np

from texsynth.synth.analysis.tensor import (
    dominant_orientation,
    orientation,
    structure_direction,
    structure_tensor,
)
from texsynth.synth.evaluate.strands import strand_grey
from texsynth.synth.io.patterns import concentric_rings, waves, wood_grain
from texsynth.synth.methods.strand_hints import fibre_table, strand_hints


def _setup(constraint: np.ndarray):
    ex = wood_grain((64, 64), seed=1)
    s_ex = structure_tensor(ex, 1.0, 3.0)
    table = fibre_table(structure_direction(s_ex), dominant_orientation(s_ex) + np.pi / 2, 5)
    strand = orientation(structure_tensor(constraint, 1.0, 3.0)).astype(np.float64) + np.pi / 2
    return ex, table, strand


def test_fibre_table_follows_the_exemplars_fibres_inside_the_margin() -> None:
    ex, table, _ = _setup(waves((32, 32)))
    assert table.n_fibres > 40
    assert (table.lo <= table.centre).all() and (table.hi >= table.centre).all()
    for a in (5, 20, 35):
        pts = table.positions[a, table.lo[a] : table.hi[a] + 1]
        assert pts.min() >= 5 and pts.max() <= 63 - 5
        # along a wood fibre the grey level hardly changes (wood_grain: fibres 5 px wide)
        vals = ex[np.rint(pts[:, 0]).astype(int), np.rint(pts[:, 1]).astype(int)]
        assert np.std(vals) < 0.5 * np.std(ex)


def test_hints_keep_one_fibre_along_each_strand_and_linked_cuts_keep_it_longer() -> None:
    for con in (waves((96, 96), amplitude=8.0, wavelength=64.0), concentric_rings((96, 96))):
        ex, table, strand = _setup(con)
        ratios = {}
        for linked in (False, True):
            hints = strand_hints(strand, table, 32, np.random.default_rng(1), linked=linked)
            assert hints.source.shape == (96, 96, 2) and hints.missed < 0.05
            img = ex[hints.source[..., 0], hints.source[..., 1]]
            ratios[linked] = strand_grey(img, strand)["ratio"]
        assert ratios[True] < ratios[False] < 0.8, ratios
        assert ratios[True] < 0.35, ratios


def test_same_seed_same_hints() -> None:
    _, table, strand = _setup(concentric_rings((48, 48)))
    a, b = (strand_hints(strand, table, 24, np.random.default_rng(3)) for _ in range(2))
    assert np.array_equal(a.source, b.source) and np.array_equal(a.copy_angle, b.copy_angle)


def test_an_output_shorter_than_the_spacing_still_gets_one_cut_across_it() -> None:
    """Cuts start half a spacing in; a side shorter than the spacing (a 48 px output, the default 128 px)
    gets one cut at its middle instead of none (an empty layout crashed before)."""
    _, table, strand = _setup(waves((48, 40), amplitude=4.0, wavelength=32.0))
    hints = strand_hints(strand, table, 128, np.random.default_rng(0))
    assert hints.source.shape == (48, 40, 2) and hints.missed < 0.5
    inside = (hints.source[..., 0] >= 0) & (hints.source[..., 0] < 64)
    assert inside.mean() > 0.5
