"""The comparison plots: painted with Pillow, sizes kept, the overlays are the images themselves."""

from __future__ import annotations

import numpy as np
from PIL import Image

from texsynth.synth.evaluate.measures import evaluate_pair_fringes
from texsynth.synth.io.patterns import undulating_laminae
from texsynth.synth.output.chart import nice_ticks
from texsynth.synth.output.plots import _PALETTE, fringe_overlay, write_plots


def _read(path) -> np.ndarray:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"))


def test_nice_ticks_are_round_and_cover_the_range():
    assert nice_ticks(0.0, 1.0, 6) == [0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]
    assert nice_ticks(0.0, 0.14, 8) == [k * 0.02 for k in range(8)]
    assert nice_ticks(3.0, 3.0) == [3.0]


def test_plots_are_written_at_their_sizes_and_overlays_reuse_the_fringes(tmp_path):
    ex = undulating_laminae((48, 48), period=6, amplitude=4, wavelength=40)
    out = undulating_laminae((64, 64), period=6, amplitude=6, wavelength=30)
    metrics, fringes = evaluate_pair_fringes(ex, out)
    paths = {p.name: p for p in write_plots(ex, out, metrics, tmp_path, fringes=fringes)}
    sizes = {name: _read(p).shape[1::-1] for name, p in paths.items()}
    assert sizes["grey_histogram.png"] == (640, 400)
    assert sizes["orientation_rose.png"] == (640, 380)
    assert sizes["fringe_distributions.png"] == (1000, 380)
    # the output's overlay: the image 3x, nearest neighbour, below a title; same pixels as fringe_overlay
    overlay = _read(paths["fringes_output.png"])
    expected = np.round(fringe_overlay(out, fringes["output"]) * 255).astype(np.uint8)
    h = 64 * 3
    assert overlay.shape[0] > h and overlay.shape[1] == 300
    left = (300 - h) // 2
    np.testing.assert_array_equal(overlay[-h:, left : left + h : 3][::3], expected)
    # the charts are not blank: the exemplar's blue and the output's red are drawn
    grey = _read(paths["grey_histogram.png"]).reshape(-1, 3).astype(int)
    assert (np.abs(grey - [0x1F, 0x4E, 0x9A]).sum(axis=1) < 30).any()
    assert (np.abs(grey - [0xD1, 0x49, 0x5B]).sum(axis=1) < 30).any()
    assert len(_PALETTE) == 18 and not (np.ptp(_PALETTE, axis=1) == 0).any()  # no grey in the palette
