"""Targets, directions and verdicts of the headline measures, and which exemplars show fringe statistics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from texsynth.synth.analysis.lattice import fringe_presence, spectral_peak
from texsynth.synth.evaluate.glossary import GLOSSARY, NEAR_FACTOR, fringes_shown, glossary, headline, verdict
from texsynth.synth.io import load_image
from texsynth.synth.io.patterns import grating

EXAMPLES = Path(__file__).resolve().parents[3] / "app" / "examples"


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        ("grey_kl", 0.04, "meets"),
        ("grey_kl", 0.05 * NEAR_FACTOR - 1e-9, "near"),
        ("grey_kl", 0.2, "misses"),
        ("std_difference", -0.015, "meets"),  # a signed difference: its absolute value counts
        ("std_difference", -0.05, "misses"),
        ("seam_visibility", 1.2, "meets"),  # near 1
        ("seam_visibility", 0.5, "misses"),
        ("grey_kl", None, None),
        ("grey_kl", float("nan"), None),
    ],
)
def test_verdicts_follow_each_measures_direction(name, value, expected):
    assert verdict(name, value) == expected


def test_every_headline_measure_has_a_target_and_a_direction():
    for name, entry in glossary().items():
        assert entry["target"] is not None and entry["direction"] in (
            "lower",
            "abs-lower",
            "near-1",
            "higher",
        )
        assert entry["good_below"] == entry["target"] and entry["better"], name
    summary = {"grey_kl": 0.01, "std_difference": -0.1, "log_euclidean": 0.3, "per_axis": {"0": {}}}
    block = headline(summary)
    assert list(block) == ["grey_kl", "std_difference", "log_euclidean"]
    assert block["std_difference"] == {
        "value": -0.1,
        "target": GLOSSARY["std_difference"].target,
        "direction": "abs-lower",
        "verdict": "misses",
        "label": "std difference",
    }


@pytest.mark.parametrize(
    ("name", "shown"),
    [
        ("soot-fringes", True),
        ("laminar", True),
        ("brick", False),  # a few mortar joints: too few lines
        ("grass", False),  # many lines, no regular spacing
        ("gravel", False),
    ],
)
def test_fringe_statistics_are_shown_only_for_lattice_fringes(name, shown):
    ok, reason, measures = fringes_shown(load_image(EXAMPLES / f"{name}.png"))
    assert ok is shown, (reason, measures)
    assert reason and measures["count"] >= 0


def test_the_spectral_peak_finds_a_gratings_period():
    ratio, period = spectral_peak(grating((128, 128), 0.3, period=8.0))
    assert ratio > 100 and period == pytest.approx(8.0, rel=0.1)
    assert spectral_peak(np.zeros((64, 64))) == (0.0, None)
    assert spectral_peak(np.ones((16, 16))) == (0.0, None)
    noise = np.random.default_rng(0).random((128, 128))
    assert spectral_peak(noise)[0] < 3 and fringe_presence(noise)["peak_ratio"] < 3
