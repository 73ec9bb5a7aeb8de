"""The whole solid path against a known answer: a two-phase volume with known statistics (a level cut of an
anisotropic Gaussian random field), its three orthogonal mid-slices as per-plane exemplars, and the
synthesized volume's two-point correlation S2(r) along each axis against the truth's, for r up to the
truth's correlation length (issue 10: within 10%)."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.api import synthesize
from texsynth.synth.evaluate.correlation import compare_s2, volume_s2
from texsynth.synth.io.patterns import gaussian_random_field

pytestmark = pytest.mark.slow

TRUTH_SHAPE = (64, 64, 64)
LENGTHS = (2.0, 3.5, 6.0)  # correlation lengths along z, y, x: strongly anisotropic


@pytest.fixture(scope="module")
def truth() -> np.ndarray:
    return gaussian_random_field(TRUTH_SHAPE, LENGTHS, 0.4, seed=11)


#: Issue 10 asks 10% on every axis. Measured with the defaults (32^3, seeds 1-3): 0.033-0.044 along
#: z, 0.034-0.041 along y, 0.039-0.042 along x. The automatic level count matters: with the paper's 5
#: levels (4 fit here) z was 0.13-0.17 and x up to 0.10 (``structure_schedule``, tested below).
BOUNDS = {
    "solid-kopf": {"z": 0.10, "y": 0.10, "x": 0.10},
    # Measured (seeds 1-3): 0.075-0.084 along z, 0.054-0.057 along y, 0.057-0.058 along x.
    "solid-chen-wang": {"z": 0.10, "y": 0.10, "x": 0.10},
}


@pytest.mark.parametrize("method", sorted(BOUNDS))
def test_s2_along_each_axis_matches_the_truth(truth, method):
    d, h, w = truth.shape
    planes = {"xy": truth[d // 2], "xz": truth[:, h // 2, :], "yz": truth[:, :, w // 2]}
    result = synthesize(method, exemplars=planes, size=(32, 32, 32), seed=1)
    # two-phase output: cut at 0.5 like the truth's indicator
    want = volume_s2(truth, threshold=0.5, periodic=True, max_lag=16)
    got = volume_s2(result.image, threshold=0.5, periodic=True, max_lag=16)
    errors = {axis: compare_s2(want[axis], got[axis])["relative_error"] for axis in ("z", "y", "x")}
    assert all(errors[axis] < bound for axis, bound in BOUNDS[method].items()), errors


def test_the_schedule_adapts_to_the_structure(truth):
    """Micro-structures get 2 levels, laminae 10 iterations; ``adapt_to_structure=False`` is literal."""
    from texsynth.synth.io.patterns import laminae_volume
    from texsynth.synth.pixel.solid import (
        LAMINAR_ITERATIONS,
        MICROSTRUCTURE_LEVELS,
        is_laminar,
        structure_schedule,
    )

    d = truth.shape[0]
    grains = [truth[d // 2], truth[:, d // 2, :], truth[:, :, d // 2]]
    sheets = laminae_volume((48, 48, 48), (1, 0, 0), 7, 4, 48, noise=0.2, seed=1)
    assert not is_laminar(grains) and is_laminar([sheets[:, 24, :]])
    assert structure_schedule(grains, 5, 4) == (MICROSTRUCTURE_LEVELS, 4)
    assert structure_schedule([sheets[:, 24, :]], 5, 4) == (5, LAMINAR_ITERATIONS)
    assert structure_schedule([sheets[:, 24, :]], 5, 20) == (5, 20)
    assert structure_schedule(grains, 1, 4) == (1, 4)
    literal = synthesize(
        "solid-kopf", grains[0], size=(16, 16, 16), params={"adapt_to_structure": False}, seed=1
    )
    adapted = synthesize("solid-kopf", grains[0], size=(16, 16, 16), seed=1)
    assert literal.stats["levels"] > adapted.stats["levels"] == MICROSTRUCTURE_LEVELS
    assert literal.stats["iterations"] == adapted.stats["iterations"] == 4
    # Chen-Wang takes the iterations only: with 2 levels its S2 error here doubled (0.13 against 0.06).
    cw = synthesize("solid-chen-wang", grains[0], size=(16, 16, 16), seed=1)
    assert cw.stats["levels"] > MICROSTRUCTURE_LEVELS and cw.stats["iterations"] == 3
    laminar = synthesize("solid-chen-wang", sheets[:, 24, :], size=(8, 8, 8), params={"levels": 1}, seed=1)
    assert laminar.stats["iterations"] == LAMINAR_ITERATIONS
    literal = synthesize(
        "solid-chen-wang",
        sheets[:, 24, :],
        size=(8, 8, 8),
        params={"levels": 1, "adapt_to_structure": False},
        seed=1,
    )
    assert literal.stats["iterations"] == 3
