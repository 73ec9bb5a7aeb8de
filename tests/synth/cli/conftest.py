"""Shared set-up of the CLI tests: one small laminar exemplar file per test module."""

from __future__ import annotations

from pathlib import Path

import pytest

from texsynth.synth.io import save_image
from texsynth.synth.io.patterns import undulating_laminae


@pytest.fixture(scope="module")
def exemplar(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 40 x 40 PNG of undulating laminae (period 6 px), written once per module."""
    path = tmp_path_factory.mktemp("ex") / "laminae.png"
    save_image(path, undulating_laminae((40, 40), period=6, amplitude=4, wavelength=40))
    return path
