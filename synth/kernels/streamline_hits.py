"""From every pixel, follow a strand (an orientation field's streamline) both ways to the first marked pixel.

The hot loop of :func:`texsynth.synth.methods.strand_hints.strand_hints`: each output pixel is traced along
the constraint's strand direction, both ways, up to ``max_steps`` steps of ``step`` pixels, until its
curve enters a pixel of a *cut* (``label >= 0``); the nearer hit wins. The tracing is
:func:`texsynth.synth.analysis.streamlines.trace`'s (midpoint Runge-Kutta on the doubled-angle field, each
step keeping the sign of the previous one; the first step of the "plus" curve goes rightwards, or down when
vertical, the "minus" curve the other way), with the hit tested at the rounded position after every
step (and at the pixel itself before the first). Outside the image a curve stops (``periodic``: wraps).
Its plain reference, built on :func:`texsynth.synth.analysis.streamlines.trace`, lives in the tests
(``tests/synth/kernels/test_streamline_hits.py``): it ties the kernel to the analysis floor above.
"""

from __future__ import annotations

import math

import numpy as np

from texsynth.synth.kernels.options import kernel

__all__ = ["first_hits"]


@kernel(inline="always")
def _sample(field, r, c, periodic):
    """Bilinear value of ``field`` at ``(r, c)``: wrapped, or clamped to the image."""
    h, w = field.shape
    if periodic:
        r = r % h
        c = c % w
    else:
        r = min(max(r, 0.0), h - 1.0)
        c = min(max(c, 0.0), w - 1.0)
    r0, c0 = math.floor(r), math.floor(c)
    fr, fc = r - r0, c - c0
    r1, c1 = r0 + 1, c0 + 1
    if periodic:
        r1, c1 = r1 % h, c1 % w
    else:
        r1, c1 = min(r1, h - 1), min(c1, w - 1)
    top = field[r0, c0] * (1 - fc) + field[r0, c1] * fc
    bot = field[r1, c0] * (1 - fc) + field[r1, c1] * fc
    return top * (1 - fr) + bot * fr


@kernel(inline="always")
def _half_angle(c2, s2):
    """Unit direction ``(d_row, d_col)`` of the angle half of the doubled angle ``(c2, s2)`` (any
    length; y up): ``(-sin phi, cos phi)`` by the half-angle formulas, no trigonometric call."""
    n = math.sqrt(c2 * c2 + s2 * s2)
    if n == 0.0:
        return 0.0, 1.0
    c = c2 / n
    cp = math.sqrt(max(0.5 * (1.0 + c), 0.0))
    sp = math.sqrt(max(0.5 * (1.0 - c), 0.0))
    if s2 < 0:
        sp = -sp
    return -sp, cp


@kernel
def first_hits(c2, s2, label, max_steps, step, periodic):
    """Per pixel: steps to the first cut pixel (-1: none within ``max_steps``), the hit position
    ``(row, col)``, the travel direction at the hit ``(d_row, d_col)``, and the curve's first step
    ``(d_row, d_col)`` (the sign taken). ``c2``, ``s2``: ``cos 2 phi``, ``sin 2 phi`` of the strand
    direction ``phi`` (float64, (H, W)); ``label``: int64 (H, W), cut pixels ``>= 0``."""
    h, w = label.shape
    steps = np.full((h, w), -1, np.int64)
    hit = np.zeros((h, w, 2))
    end = np.zeros((h, w, 2))
    first = np.zeros((h, w, 2))
    for y in range(h):
        for x in range(w):
            pr, pc = _half_angle(c2[y, x], s2[y, x])
            if pc < 0 or (pc == 0 and pr < 0):
                pr, pc = -pr, -pc
            if label[y, x] >= 0:
                steps[y, x] = 0
                hit[y, x, 0], hit[y, x, 1] = y, x
                end[y, x, 0], end[y, x, 1] = pr, pc
                first[y, x, 0], first[y, x, 1] = pr, pc
                continue
            best = max_steps + 1
            for sign in (1.0, -1.0):
                r, c = float(y), float(x)
                vr, vc = sign * pr, sign * pc
                for k in range(1, min(max_steps, best - 1) + 1):
                    k1r, k1c = _half_angle(_sample(c2, r, c, periodic), _sample(s2, r, c, periodic))
                    if k1r * vr + k1c * vc < 0:
                        k1r, k1c = -k1r, -k1c
                    mr, mc = r + 0.5 * step * k1r, c + 0.5 * step * k1c
                    k2r, k2c = _half_angle(_sample(c2, mr, mc, periodic), _sample(s2, mr, mc, periodic))
                    if k2r * k1r + k2c * k1c < 0:
                        k2r, k2c = -k2r, -k2c
                    r, c = r + step * k2r, c + step * k2c
                    vr, vc = k2r, k2c
                    iy, ix = math.floor(r + 0.5), math.floor(c + 0.5)
                    if periodic:
                        iy, ix = iy % h, ix % w
                    elif iy < 0 or iy >= h or ix < 0 or ix >= w:
                        break
                    if label[iy, ix] >= 0:
                        best = k
                        steps[y, x] = k
                        hit[y, x, 0], hit[y, x, 1] = r, c
                        end[y, x, 0], end[y, x, 1] = vr, vc
                        first[y, x, 0], first[y, x, 1] = sign * pr, sign * pc
                        break
    return steps, hit, end, first
