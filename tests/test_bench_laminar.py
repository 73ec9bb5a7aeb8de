"""The real crops' 2D reference line in docs/laminar.md: its table and picture (benchmarks.bench_laminar)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import bench_laminar


def _spread(mean: float, worst: float) -> dict[str, float]:
    return {"mean": mean, "q90": worst, "worst": worst}


def _floor() -> dict:
    row = {
        "coherence_ratio": _spread(0.99, 0.97),
        "orientation_kl": _spread(0.02, 0.03),
        "fringe_ks_length": _spread(0.17, 0.20),
        "fringe_ks_tortuosity": _spread(0.12, 0.14),
        "grey_kl": _spread(0.001, 0.002),
        "contrast": _spread(0.98, 0.80),
    }
    return {"hrtem-onion-128.png": {"counts": {"2d whole": 3}, "2d whole": row}}


def test_reference_table_gives_mean_and_worst_and_marks_only_misses() -> None:
    lines = bench_laminar.reference_table(_floor()).splitlines()
    assert len(lines) == 3
    assert lines[0].count("|") == len(bench_laminar.MEASURES) + 2
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    assert cells[0] == "hrtem-onion-128, 3 seeds"
    assert cells[1:] == [
        "0.99 (0.97)",
        "0.02 (0.03)",
        "0.17 (0.20 **x**)",  # length KS worst above 0.15
        "0.12 (0.14)",
        "0.00 (0.00)",
        "0.98 (0.80 **x**)",  # a ratio misses below 0.85 too
    ]


def test_line_picture_keeps_both_images_at_their_own_scale() -> None:
    crop = np.linspace(0.0, 1.0, 16 * 16, dtype=np.float32).reshape(16, 16)
    output = np.full((32, 32), 0.5, dtype=np.float32)
    picture = bench_laminar.line_picture(crop, output, gap=4)
    assert picture.dtype == np.uint8
    assert picture.shape == (32, 16 + 4 + 32)
    np.testing.assert_array_equal(picture[:16, :16], (crop * 255.0 + 0.5).astype(np.uint8))
    assert (picture[16:, :16] == 255).all() and (picture[:, 16:20] == 255).all()
    assert (picture[:, 20:] == 128).all()


def test_report_shows_the_reference_line_when_the_floor_was_measured(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    saved = json.loads(bench_laminar.RESULTS.read_text())
    monkeypatch.setattr(bench_laminar, "CROP_FLOOR", tmp_path / "missing.json")
    assert "the 2D reference line" not in bench_laminar.report(saved)
    floor = tmp_path / "floor.json"
    floor.write_text(json.dumps(_floor()))
    monkeypatch.setattr(bench_laminar, "CROP_FLOOR", floor)
    text = bench_laminar.report(saved)
    assert "## The real crops: the 2D reference line" in text
    assert "| hrtem-onion-128, 3 seeds | 0.99 (0.97) |" in text
    assert text.index("the 2D reference line") < text.index("## `solid-chen-wang` re-run")


def test_report_shows_the_solids_on_the_crops_beside_the_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--crops``' rows (docs/laminar-crops.json) follow the 2D line: one row per crop and solid, cells as
    the known answers' (per axis means, the worst seed-axis, **x** on a miss); no file, no section."""
    saved = json.loads(bench_laminar.RESULTS.read_text())
    monkeypatch.setattr(bench_laminar, "CROP_FLOOR", tmp_path / "floor.json")
    (tmp_path / "floor.json").write_text(json.dumps(_floor()))
    monkeypatch.setattr(bench_laminar, "CROP_VOLUMES", tmp_path / "missing.json")
    assert "### The solids on the same crops" not in bench_laminar.report(saved)
    axes = {
        a: {
            "coherence_ratio": 1.0,
            "orientation_kl": 0.05,
            "fringe_ks_length": 0.1 + 0.05 * int(a),
            "fringe_ks_tortuosity": 0.2,
            "grey_kl": 0.0,
            "contrast": 1.0,
        }
        for a in bench_laminar.AXES
    }
    volumes = {"hrtem-onion-128, `solid-kopf` defaults, 64^3": [{"cpu": 2.0, "wall": 1.5, "axes": axes}]}
    (tmp_path / "crops.json").write_text(json.dumps(volumes))
    monkeypatch.setattr(bench_laminar, "CROP_VOLUMES", tmp_path / "crops.json")
    text = bench_laminar.report(saved)
    row = next(line for line in text.splitlines() if line.startswith("| hrtem-onion-128, `solid-kopf`"))
    assert "| 0.10 / 0.15 / 0.20 (0.20 **x**) | 0.20 / 0.20 / 0.20 (0.20 **x**) |" in row
    assert "img/laminar-crop-hrtem-onion-128-solid-kopf-64-slices.png" in text
    assert text.index("the 2D reference line") < text.index("### The solids on the same crops")
