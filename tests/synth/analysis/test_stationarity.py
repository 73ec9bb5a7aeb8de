"""Exemplar stationarity (texsynth.synth.analysis.stationarity): quiet on one texture, a warning on mixed
crops."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

from tests.paths import SHARED_DATA
from texsynth.synth.analysis.stationarity import THRESHOLD, exemplar_diagnostics, stationarity
from texsynth.synth.errors import InvalidInput
from texsynth.synth.io import load_image
from texsynth.synth.io.laminar import onion_volume, turbostratic_volume
from texsynth.synth.io.patterns import (
    concentric_rings,
    grating,
    undulating_laminae,
    voronoi_cells,
    wood_grain,
)


@pytest.fixture(scope="module")
def onion() -> np.ndarray:
    return onion_volume((128, 128, 128), seed=11)[64]


@pytest.fixture(scope="module")
def turbo() -> np.ndarray:
    return turbostratic_volume((128, 128, 128), seed=11)[64]


def _soot(name: str) -> np.ndarray:
    path = SHARED_DATA / name
    if not path.exists():
        pytest.skip(f"{name} not found in {SHARED_DATA} (set TEXSYNTH_SHARED_DATA)")
    return load_image(path, mode="grey")


def _noise(shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    return np.clip(0.5 + 0.15 * np.random.default_rng(seed).standard_normal(shape), 0, 1).astype(np.float32)


STATIONARY = {
    "grating": lambda: grating((128, 128), 0.4, 6, noise=0.3),
    "laminae": lambda: undulating_laminae((128, 128), 7, 16, 128, noise=0.3),
    "rings": lambda: concentric_rings((128, 128), 6, noise=0.3),
    "wood": lambda: wood_grain((128, 128)),
    "cells": lambda: voronoi_cells((128, 128)),
    "brick": lambda: data.brick() / 255.0,
    "grass": lambda: data.grass() / 255.0,
    "gravel": lambda: data.gravel() / 255.0,
    "soot-128": lambda: _soot("hrtem-soot-128.png"),
    "soot-256": lambda: _soot("hrtem-soot-256.png"),
    "soot-downsampled": lambda: _soot("hrtem-soot-128-downsampled.png"),
}


@pytest.mark.parametrize("name", sorted(STATIONARY))
def test_stationary_textures_get_no_warning(name: str) -> None:
    found = stationarity(STATIONARY[name]())
    assert found.stationary and found.score <= THRESHOLD and found.warning is None
    assert found.windows >= 9


def test_laminar_slices_are_stationary(onion: np.ndarray, turbo: np.ndarray) -> None:
    for image in (onion, turbo):
        assert stationarity(image).warning is None


def _disc(radius: float) -> np.ndarray:
    yy, xx = np.mgrid[0:128, 0:128]
    return np.hypot(yy - 64, xx - 64) < radius


def test_mixed_crops_get_the_warning(onion: np.ndarray, turbo: np.ndarray) -> None:
    cores = onion.copy()
    cores[_disc(36)] = _noise((128, 128))[_disc(36)]
    halves = np.concatenate([turbo[:, :64], _noise((128, 64))], axis=1)
    textures = np.concatenate([data.brick()[:256, :128], data.grass()[:256, :128]], axis=1) / 255.0
    laminae = undulating_laminae((128, 128), 7, 16, 128, noise=0.3)
    for image in (cores, halves, textures, np.where(np.arange(128) < 64, laminae, _noise((128, 128), 1))):
        found = stationarity(image)
        assert not found.stationary
        assert found.warning is not None and "crop" in found.warning and "not stationary" in found.warning


def test_an_ordered_shell_around_a_soot_core_is_caught(onion: np.ndarray) -> None:
    mixed = onion.copy()
    mixed[_disc(36)] = _soot("hrtem-soot-128.png")[_disc(36)]
    found = stationarity(mixed)
    assert found.warning is not None and found.components["coherence"] > 0.085


def test_same_image_same_report_and_rgb_is_judged_as_grey(turbo: np.ndarray) -> None:
    a, b = stationarity(turbo), stationarity(turbo.copy())
    assert a == b
    rgb = np.repeat(turbo[..., None], 3, axis=2)
    assert stationarity(rgb).score == pytest.approx(a.score, rel=1e-5)


def test_bad_inputs() -> None:
    with pytest.raises(InvalidInput, match="too small"):
        stationarity(np.zeros((16, 64), np.float32))
    with pytest.raises(InvalidInput, match="NaN"):
        stationarity(np.full((32, 32), np.nan, np.float32))
    with pytest.raises(InvalidInput, match="grey or RGB"):
        stationarity(np.zeros((4, 32, 32), np.float32))
    with pytest.raises(InvalidInput, match="window"):
        stationarity(np.zeros((64, 64), np.float32), window=40)


def test_diagnostics_by_role_note_small_exemplars_and_collect_warnings(turbo: np.ndarray) -> None:
    halves = np.concatenate([turbo[:, :64], _noise((128, 64))], axis=1)
    found = exemplar_diagnostics(
        {"exemplar_xy": turbo, "exemplar_xz": halves, "exemplar_yz": turbo[:16, :16]}
    )
    reports = found["stationarity"]
    assert reports["exemplar_xy"]["stationary"] is True and reports["exemplar_xz"]["stationary"] is False
    assert reports["exemplar_yz"]["score"] is None and "too small" in reports["exemplar_yz"]["note"]
    assert len(found["warnings"]) == 1 and found["warnings"][0].startswith("exemplar_xz: ")
