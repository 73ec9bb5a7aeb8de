"""Solid methods (solid-kopf, solid-wei-levoy) end to end: reproducibility, tiling, scans, planes, errors."""

from __future__ import annotations

import numpy as np
import pytest

from synth import InvalidInput, InvalidParameter
from synth.analysis.tensor import dominant_orientation, structure_tensor, wrap_angle
from synth.api import synthesize
from synth.errors import Cancelled
from synth.grid.scan import SCAN_ORDERS
from synth.io.patterns import undulating_laminae

SMALL = {"iterations": 2, "levels": 3}
SIZE = (16, 16, 16)


def _soft(seed: int = 0) -> np.ndarray:
    return undulating_laminae((32, 32), period=6.0, amplitude=4.0, wavelength=32.0, noise=0.1, seed=seed)


def _stripes(shape: tuple[int, int], along: str, period: float = 6.0) -> np.ndarray:
    """Stripes varying along rows ('rows': horizontal stripes), columns, or rows + columns (diagonal)."""
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    phase = {"rows": r, "cols": c, "diag": (r + c) / np.sqrt(2.0)}[along]
    return (0.5 + 0.5 * np.cos(2 * np.pi * phase / period)).astype(np.float32)


@pytest.mark.parametrize("method", ["solid-kopf", "solid-wei-levoy"])
def test_same_seed_same_bytes_and_valid_volume(method: str) -> None:
    ex = _soft()
    a = synthesize(method, ex, size=SIZE, params=SMALL, seed=3)
    b = synthesize(method, ex, size=SIZE, params=SMALL, seed=3)
    c = synthesize(method, ex, size=SIZE, params=SMALL, seed=4)
    assert a.image.shape == SIZE and a.image.dtype == np.float32
    assert a.image.min() >= 0.0 and a.image.max() <= 1.0
    assert a.image.tobytes() == b.image.tobytes()
    assert a.image.tobytes() != c.image.tobytes()
    assert a.method == method and a.params["iterations"] == 2 and a.seed == 3
    assert set(a.stats["mean_best_distance"]) == {"level 1", "level 2", "level 3"}


@pytest.mark.parametrize("scan", SCAN_ORDERS)
def test_every_scan_order_runs(scan: str) -> None:
    res = synthesize("solid-kopf", _soft(), size=(12, 16, 20), params={**SMALL, "scan": scan}, seed=0)
    assert res.image.shape == (12, 16, 20) and np.isfinite(res.image).all()
    assert res.image.std() > 0.05  # not collapsed to a flat grey


def _steps(vol: np.ndarray, axis: int) -> tuple[np.ndarray, float]:
    """Mean |difference| between successive slices along ``axis`` inside the volume, and across the wrap."""
    v = np.moveaxis(vol.astype(np.float64), axis, 0)
    inside = np.abs(np.diff(v, axis=0)).mean(axis=(1, 2))
    return inside, float(np.abs(v[0] - v[-1]).mean())


def test_periodic_volume_tiles_seamlessly() -> None:
    """Across the wrap, neighbouring slices differ no more than neighbouring slices inside do."""
    res = synthesize("solid-kopf", _soft(), size=SIZE, params={**SMALL, "periodic": True}, seed=1)
    for axis in range(3):
        inside, across = _steps(res.image, axis)
        assert 0.9 * inside.min() <= across <= 1.1 * inside.max(), axis


def _orientation(images: np.ndarray) -> float:
    tensors = np.concatenate([structure_tensor(im, 1.0, 2.0).reshape(-1, 3) for im in images])
    return dominant_orientation(tensors)


@pytest.mark.parametrize("method", ["solid-kopf", "solid-wei-levoy"])
def test_per_plane_exemplars_set_each_planes_orientation(method: str) -> None:
    """A volume varying along y + z: xy and xz slices show horizontal stripes, yz slices diagonal ones."""
    planes = {
        "xy": _stripes((32, 32), "rows"),
        "xz": _stripes((32, 32), "rows"),
        "yz": _stripes((32, 32), "diag"),
    }
    res = synthesize(method, exemplars=planes, size=SIZE, params={**SMALL, "iterations": 3}, seed=2)
    vol = res.image
    slices = {"xy": vol, "xz": np.moveaxis(vol, 1, 0), "yz": np.moveaxis(vol, 2, 0)}
    for plane, ex in planes.items():
        want = _orientation(ex[None])
        got = _orientation(slices[plane])
        assert abs(np.degrees(wrap_angle(got - want))) < 15.0, plane


def test_kopf_fast_search_matches_exact_search_within_5_percent() -> None:
    ex = _soft()
    params = {**SMALL, "iterations": 5}  # k-coherence needs a few iterations to settle
    fast = synthesize("solid-kopf", ex, size=SIZE, params=params, seed=5)
    exact = synthesize("solid-kopf", ex, size=SIZE, params={**params, "search": "exact"}, seed=5)
    d_fast = fast.stats["mean_best_distance"]["level 1"]
    d_exact = exact.stats["mean_best_distance"]["level 1"]
    assert d_fast <= 1.05 * d_exact


def test_histogram_matching_keeps_the_exemplar_grey_levels() -> None:
    ex = _soft()
    on = synthesize("solid-kopf", ex, size=SIZE, params=SMALL, seed=6).image
    off = synthesize("solid-kopf", ex, size=SIZE, params={**SMALL, "histogram_matching": False}, seed=6).image
    assert abs(on.std() - ex.std()) < 0.02
    assert on.std() > off.std()


def test_progress_reaches_one_in_small_steps_and_cancel_stops() -> None:
    seen: list[float] = []
    synthesize("solid-kopf", _soft(), size=SIZE, params=SMALL, seed=0, progress=lambda s, f: seen.append(f))
    assert seen[-1] == 1.0
    assert np.all(np.diff(seen) >= 0) and np.max(np.diff([0.0, *seen])) <= 0.02 + 1e-9

    calls = []

    def cancel(stage: str, fraction: float) -> None:
        calls.append(fraction)
        if fraction > 0.3:
            raise Cancelled("stop")

    for method in ("solid-kopf", "solid-wei-levoy"):
        calls.clear()
        with pytest.raises(Cancelled):
            synthesize(method, _soft(), size=SIZE, params=SMALL, seed=0, progress=cancel)
        assert calls[-1] > 0.3 and calls[-1] < 0.4


def test_bad_inputs_are_named() -> None:
    ex = _soft()
    with pytest.raises(InvalidParameter, match="size"):
        synthesize("solid-kopf", ex, size=(16, 16), params=SMALL)
    with pytest.raises(InvalidParameter, match="neighbourhood_size"):
        synthesize("solid-kopf", ex, size=SIZE, params={"neighbourhood_size": 6})
    with pytest.raises(InvalidParameter, match="'r'"):
        synthesize("solid-kopf", ex, size=SIZE, params={"r": 0.0})
    with pytest.raises(InvalidParameter, match="iterations"):
        synthesize("solid-wei-levoy", ex, size=SIZE, params={"iterations": 0})
    with pytest.raises(InvalidInput, match=r"exemplar: 5x6 pixels is smaller than the 7x7 neighbourhood"):
        synthesize("solid-kopf", ex[:5, :6].copy(), size=SIZE)
    planes = {"xy": ex, "xz": ex[:6].copy(), "yz": ex}
    with pytest.raises(InvalidInput, match=r"exemplar_xz: 6x32 pixels"):
        synthesize("solid-wei-levoy", exemplars=planes, size=SIZE)
