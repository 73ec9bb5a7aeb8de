"""Streamlines of an orientation field (texsynth.synth.analysis.streamlines)."""

from __future__ import annotations

import numpy as np

from texsynth.synth.analysis.streamlines import trace


def ring_direction(shape: tuple[int, int], centre: tuple[float, float]) -> np.ndarray:
    """Strand direction of concentric rings (tangent to circles about ``centre``), y up."""
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    gradient = np.arctan2(-(r - centre[0]), c - centre[1])  # radial: the rings' gradient
    return gradient + np.pi / 2


def test_trace_follows_a_straight_field_and_keeps_its_sign() -> None:
    angle = np.full((32, 32), np.radians(30.0))
    pts = trace(angle, np.array([[16.0, 5.0]]), 10)
    step = pts[1:, 0, 0] - pts[:-1, 0, 0], pts[1:, 0, 1] - pts[:-1, 0, 1]
    np.testing.assert_allclose(step[1], np.cos(np.radians(30.0)), atol=1e-9)  # rightwards, every step
    np.testing.assert_allclose(step[0], -np.sin(np.radians(30.0)), atol=1e-9)  # y up: rows decrease
    back = trace(angle, np.array([[16.0, 5.0]]), 3, forward=np.array([[0.0, -1.0]]))
    assert back[-1, 0, 1] < 5.0


def test_trace_turns_with_the_field_around_rings() -> None:
    """A curve along rings stays on its circle (midpoint Runge-Kutta, 1 px steps, a quarter turn)."""
    shape, centre = (64, 64), (31.5, 31.5)
    pts = trace(ring_direction(shape, centre), np.array([[31.5, 51.5]]), 30)
    radius = np.hypot(pts[:, 0, 0] - centre[0], pts[:, 0, 1] - centre[1])
    assert np.abs(radius - 20.0).max() < 0.3
    assert np.hypot(*(pts[-1, 0] - pts[0, 0])) > 25  # it went round, not back and forth
