"""The exemplar's stationarity in metrics.json, the manifest and the output of `synthesize` and `analyze`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from texsynth.synth.cli import main
from texsynth.synth.io import save_image
from texsynth.synth.io.patterns import grating


def _mixed() -> np.ndarray:
    ordered = grating((96, 96), 0.4, 6, noise=0.2)
    noise = np.clip(0.5 + 0.15 * np.random.default_rng(0).standard_normal((96, 96)), 0, 1)
    return np.where(np.arange(96) < 48, ordered, noise).astype(np.float32)


@pytest.fixture
def inputs(tmp_path: Path) -> dict[str, Path]:
    paths = {"mixed": tmp_path / "mixed.png", "one": tmp_path / "one.png"}
    save_image(paths["mixed"], _mixed())
    save_image(paths["one"], grating((96, 96), 0.4, 6, noise=0.2))
    return paths


@pytest.mark.parametrize("kind", ["mixed", "one"])
def test_synthesize_reports_stationarity_everywhere(
    inputs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    out = tmp_path / kind
    args = ["synthesize", "random-phase", "--exemplar", str(inputs[kind]), "--size", "64x64"]
    assert main([*args, "--no-plots", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]["exemplar"]
    manifest = json.loads((out / "manifest.json").read_text())["exemplar_stationarity"]["exemplar"]
    report = metrics["stationarity"]["exemplar"]
    assert report["score"] == manifest["score"] and set(report["components"]) == {
        "mean",
        "contrast",
        "coherence",
        "orientation",
    }
    assert "exemplar stationarity" in printed
    if kind == "mixed":
        assert report["score"] > 1 and manifest["stationary"] is False
        assert metrics["warnings"] and "crop" in manifest["warning"]
        assert "warning: The exemplar is not stationary" in printed
    else:
        assert report["score"] <= 1 and manifest["stationary"] is True and manifest["warning"] is None
        assert not metrics["warnings"] and "warning" not in printed


def test_analyze_reports_stationarity(
    inputs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["analyze", str(inputs["mixed"]), "--out", str(tmp_path / "a")]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((tmp_path / "a" / "tensor.json").read_text())
    assert summary["stationarity"]["stationary"] is False and "warning: The exemplar" in printed
    assert main(["analyze", str(inputs["one"]), "--out", str(tmp_path / "b")]) == 0
    assert "warning" not in capsys.readouterr().out
