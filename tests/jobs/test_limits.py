"""One home for the size limits: texsynth.synth.io.limits defines each limit and its one environment variable;
the engine and the service's Settings read the same variable, and the worker runs under the service's."""

from __future__ import annotations

import io

import pytest
from PIL import Image

from texsynth.jobs.config import Settings
from texsynth.synth.errors import InputTooLarge, InvalidParameter
from texsynth.synth.io import load_image
from texsynth.synth.io.limits import LIMITS


def _png(side: int) -> bytes:
    buf = io.BytesIO()
    Image.new("L", (side, side)).save(buf, "PNG")
    return buf.getvalue()


def test_settings_take_their_limit_defaults_from_the_engine() -> None:
    settings = Settings.from_env(environ={})
    assert settings.max_input_pixels == LIMITS["max_input_pixels"].default
    assert settings.max_output_pixels == LIMITS["max_output_pixels"].default


@pytest.mark.parametrize("variable", ["TEXSYNTH_MAX_INPUT_PIXELS", "TEXSYNTH_MAX_PIXELS"])
def test_one_variable_limits_the_engine_and_the_service(monkeypatch, variable: str) -> None:
    """TEXSYNTH_MAX_INPUT_PIXELS (and, deprecated, TEXSYNTH_MAX_PIXELS) is read by both, in one place."""
    monkeypatch.delenv("TEXSYNTH_MAX_INPUT_PIXELS", raising=False)
    monkeypatch.delenv("TEXSYNTH_MAX_PIXELS", raising=False)
    monkeypatch.setenv(variable, "1000")
    with pytest.raises(InputTooLarge, match="limit of 1000"):
        load_image(_png(64))
    settings = Settings.from_env()
    assert settings.max_input_pixels == 1000
    assert settings.to_env()["TEXSYNTH_MAX_INPUT_PIXELS"] == "1000"  # a worker child reads it back
    monkeypatch.setenv(variable, "lots")
    with pytest.raises(InvalidParameter, match=variable):
        load_image(_png(64))


def test_the_new_name_wins_over_the_deprecated_one(monkeypatch) -> None:
    monkeypatch.setenv("TEXSYNTH_MAX_INPUT_PIXELS", "5000")
    monkeypatch.setenv("TEXSYNTH_MAX_PIXELS", "1000")
    assert load_image(_png(64)).shape == (64, 64)
    assert Settings.from_env().max_input_pixels == 5000
