"""The grain table of docs/solid.md: benchmarks.bench_grain."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage as ndi

from benchmarks import bench_grain
from benchmarks.bench_laminar import AXES, MEASURES


def _rows(grain: float, blend: float | None, shells: str | None) -> list[dict]:
    axes = {a: {key: 0.05 for key, *_ in MEASURES} for a in AXES}
    for a in AXES:
        axes[a]["coherence_ratio"] = axes[a]["contrast"] = 1.0
    return [
        {
            "seed": s,
            "wall": 2.0,
            "shells": shells,
            "final_blend": blend,
            "grain": [grain, grain + 0.1 * s, grain],
        }
        | {"axes": axes}
        for s in (1, 2, 3)
    ]


def test_the_table_gives_grain_mean_worst_and_the_blends() -> None:
    saved = {
        "machine": "2 cores",
        "exemplars": {
            "x": {
                "stem": "hrtem-x",
                "rows": {
                    "solid-chen-wang discrete (paper, before)": _rows(2.0, 0.0, "domains"),
                    "solid-chen-wang default": _rows(1.0, 0.7, "domains"),
                    "solid-kopf default": _rows(1.5, None, None),
                },
            }
        },
    }
    lines = [line for line in bench_grain.report(saved).splitlines() if line.startswith("| x ")]
    assert len(lines) == 3
    assert "| solid-chen-wang discrete (paper, before) (domains) | 2.07 (2.30) | 0.00-0.00 |" in lines[0]
    assert "| solid-chen-wang default (domains) | 1.07 (1.30) | 0.70-0.70 |" in lines[1]
    assert "| solid-kopf default | 1.57 (1.80) |  |" in lines[2]
    assert "img/grain-hrtem-x.png" in bench_grain.report(saved)


def test_grain_ratio_is_one_for_the_exemplar_repeated_and_above_for_speckle() -> None:
    rng = np.random.default_rng(0)
    ex = ndi.gaussian_filter(rng.normal(size=(32, 32)), 1.5)
    volume = np.repeat(ex[None], 16, axis=0)
    assert bench_grain.grain_ratio(volume, ex)[0] == pytest.approx(1.0)
    speckled = volume + 0.3 * ex.std() * rng.normal(size=volume.shape)
    assert min(bench_grain.grain_ratio(speckled, ex)) > 1.5
