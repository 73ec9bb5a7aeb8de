"""Chen & Wang solid synthesis: kernels against references, reproducibility, options, histograms, errors."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys

import numpy as np
import pytest

from texsynth.synth import InvalidInput, InvalidParameter
from texsynth.synth.analysis.tensor import dominant_orientation, structure_tensor, wrap_angle
from texsynth.synth.api import PLANES, synthesize
from texsynth.synth.errors import Cancelled
from texsynth.synth.grid.scan import SCAN_ORDERS, scan_order
from texsynth.synth.io.patterns import undulating_laminae
from texsynth.synth.kernels.solid_kcoherence import (
    SolidState,
    SolverWeights,
    new_scratch,
    search_pass,
    search_reference,
    solve_pass,
    solve_reference,
)
from texsynth.synth.methods.solid_chen_wang import (
    _GREY_BINS,
    SolidChenWangParams,
    _bank,
    _geometry,
    _grey_target,
    _random_matches,
    _targets,
    synthesize_solid_chen_wang,
)
from texsynth.synth.pixel.solid import plan_levels

#: Small and fast: 2 levels, 1 iteration.
FAST = {"levels": 2, "iterations": 1, "neighbourhood_size": 5}


def _laminae(side: int = 32, seed: int = 0) -> np.ndarray:
    return undulating_laminae((side, side), period=6.0, amplitude=4.0, wavelength=side, seed=seed)


def _setup(shape=(6, 7, 8), periodic=True, k=4, anisotropic=False, seed=0, planes=PLANES):
    ex = _laminae(16)
    images = dict.fromkeys(PLANES, ex)
    if anisotropic:
        images = {"xy": ex, "xz": _laminae(16, seed=1)[:, :14], "yz": np.ascontiguousarray(ex.T)}
    plan = plan_levels(images, shape, 1, 5)
    bank = _bank(plan, 0, k)
    geo = _geometry(5, bank.layout, periodic, planes)
    rng = np.random.default_rng(seed)
    match = _random_matches(bank, shape, rng)
    it, pt = _targets(bank, int(np.prod(shape)), geo.active)
    state = SolidState(
        volume=rng.random(shape).astype(np.float32),
        match=match,
        weight=rng.random((3, *shape)).astype(np.float32) + 0.5,
        origin=np.full(shape, -1, np.int32),
        index_count=np.bincount(match[geo.active].ravel(), minlength=len(bank.values)).astype(np.int64),
        index_target=it,
        position_count=np.zeros(len(bank.values), np.int64),
        position_target=pt,
        grey_count=np.zeros(_GREY_BINS, np.int64),
        grey_target=_grey_target(bank, int(np.prod(shape)), geo.active),
        # arbitrary orientation re-weighting factors, so that the kernel and the reference apply them alike
        orientation_factor=1.0 + 2.0 * rng.random((3, len(bank.values))),
    )
    return bank, geo, state, rng


def _copy(state: SolidState) -> SolidState:
    return SolidState(*(np.array(getattr(state, f)) for f in state._fields))


def _scratch(bank, state) -> dict[str, np.ndarray]:
    return new_scratch(bank, state)


def _assert_same(a: SolidState, b: SolidState) -> None:
    for name in a._fields:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


# ---------------------------------------------------------------- kernels against references


@pytest.mark.parametrize(
    ("periodic", "anisotropic", "planes", "options"),
    [
        (True, False, PLANES, {"rerank": 0}),
        (True, False, PLANES, {"rerank": 4, "n_random": 2, "kset_window": 5, "solve_radius": 1}),
        (False, False, PLANES, {"rerank": 4, "grey_weight": 3.0, "consensus": 0.0}),
        (False, True, PLANES, {"rerank": 4, "solve_radius": 2, "kset_window": 2}),
        (True, True, ("xz", "yz"), {"rerank": 4, "n_random": 1, "grey_weight": 1.0, "solve_radius": 1}),
        (False, False, ("xy", "yz"), {"rerank": 0, "consensus": 4.0}),
    ],
)
def test_search_and_solve_kernels_equal_their_references(periodic, anisotropic, planes, options) -> None:
    bank, geo, state, rng = _setup(periodic=periodic, anisotropic=anisotropic, planes=planes)
    order = scan_order(state.volume.shape, "random", rng)
    weights = SolverWeights(index_weight=2.0, position_weight=2.0, seed_key=12345, **options)
    n = len(order)
    free = [p for p, name in enumerate(PLANES) if name not in planes]
    before = state.match[free].copy()
    for _ in range(2):  # a solve from random voxels, a search, a solve with counts
        for kern, ref in ((solve_pass, solve_reference), (search_pass, search_reference)):
            a, b = _copy(state), _copy(state)
            sa, sb = _scratch(bank, a), _scratch(bank, b)
            for lo, hi in ((0, n // 2), (n // 2, n)):  # a pass in two calls, as the driver makes them
                kern(bank, geo, a, weights, order, lo, hi, sa)
                ref(bank, geo, b, weights, order, lo, hi, sb)
            _assert_same(a, b)
            np.testing.assert_allclose(sa["acc"], sb["acc"], rtol=1e-9)
            if kern is solve_pass:  # the proposals' least-squares voxel, which the last step may blend in
                np.testing.assert_allclose(sa["consensus"], sb["consensus"], rtol=1e-12)
            state = a
    # A free plane is neither searched nor counted.
    np.testing.assert_array_equal(state.match[free], before)
    counted = np.bincount(state.match[geo.active].ravel(), minlength=len(bank.values))
    np.testing.assert_array_equal(state.index_count, counted)


def test_whole_run_equals_the_reference_run(monkeypatch: pytest.MonkeyPatch) -> None:
    import texsynth.synth.methods.solid_chen_wang as method

    ex = _laminae(16)
    params = SolidChenWangParams(levels=2, iterations=1, neighbourhood_size=5, k=4, grey_weight=1.0)
    planes = dict.fromkeys(PLANES, ex)
    fast, _ = synthesize_solid_chen_wang(planes, (8, 8, 8), params, seed=3)
    # The same driver with the plain NumPy passes in place of the kernels.
    calls: list[str] = []

    def spy(name, reference):  # type: ignore[no-untyped-def]
        def run(*args):  # type: ignore[no-untyped-def]
            calls.append(name)
            return reference(*args)

        return run

    monkeypatch.setattr(method, "search_pass", spy("search", search_reference))
    monkeypatch.setattr(method, "solve_pass", spy("solve", solve_reference))
    slow, _ = synthesize_solid_chen_wang(planes, (8, 8, 8), params, seed=3)
    assert {"search", "solve"} <= set(calls)
    np.testing.assert_array_equal(fast, slow)


# ---------------------------------------------------------------- the method


def test_same_seed_same_bytes_and_voxels_are_exemplar_pixels() -> None:
    ex = _laminae()
    a = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params=FAST, seed=7)
    b = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params=FAST, seed=7)
    c = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params=FAST, seed=8)
    assert a.image.shape == (16, 16, 16) and a.image.dtype == np.float32
    assert a.image.tobytes() == b.image.tobytes()
    assert a.image.tobytes() != c.image.tobytes()
    # The discrete solver copies pixels: no blur, no grey level the exemplar lacks.
    assert np.isin(a.image, ex).all()


@pytest.mark.parametrize("scan", SCAN_ORDERS)
def test_every_scan_order_runs(scan) -> None:
    r = synthesize("solid-chen-wang", _laminae(), size=(12, 16, 20), params={**FAST, "scan": scan}, seed=1)
    assert r.image.shape == (12, 16, 20)
    assert np.all(np.isfinite(r.image)) and r.image.std() > 0.05


def test_per_plane_exemplars_of_different_shapes() -> None:
    ex = _laminae()
    planes = {"xy": ex, "xz": ex[:, :28], "yz": np.ascontiguousarray(ex.T[:30])}
    r = synthesize("solid-chen-wang", exemplars=planes, size=(16, 16, 16), params=FAST, seed=1)
    assert r.image.shape == (16, 16, 16)
    pool = np.concatenate([im.ravel() for im in planes.values()])
    assert np.isin(r.image, pool).all()


def test_two_planes_leave_the_third_free() -> None:
    ex = _laminae()
    a = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params={**FAST, "planes": ["yz", "xz"]}, seed=5)
    b = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params={**FAST, "planes": ("xz", "yz")}, seed=5)
    c = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params=FAST, seed=5)
    assert a.params["planes"] == ("xz", "yz")  # normalised to PLANES order
    assert a.image.tobytes() == b.image.tobytes()
    assert a.image.tobytes() != c.image.tobytes()
    assert np.isin(a.image, ex).all()


def _seam_ratios(vol: np.ndarray) -> np.ndarray:
    """Per axis: mean squared jump across the wrapped faces over the mean jump between neighbouring slices."""
    ratios = []
    for axis in range(3):
        v = np.moveaxis(vol, axis, 0).astype(np.float64)
        inner = np.mean((v[1:] - v[:-1]) ** 2)
        ratios.append(np.mean((v[0] - v[-1]) ** 2) / inner)
    return np.asarray(ratios)


def test_periodic_volumes_tile() -> None:
    ex = _laminae()
    params = {**FAST, "iterations": 2}
    tiled = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params={**params, "periodic": True}, seed=2)
    free = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params={**params, "periodic": False}, seed=2)
    # Measured (seeds 2, 3): wrapped faces 1.1-1.7 times an inner step, free faces 1.9-5.3 times.
    assert _seam_ratios(tiled.image).max() < 2.0
    assert _seam_ratios(free.image).mean() > _seam_ratios(tiled.image).mean()


def test_position_histogram_pushes_use_toward_uniform() -> None:
    ex = _laminae()
    base = {"levels": 2, "iterations": 2, "neighbourhood_size": 5}
    spread = {}
    for weight in (0.0, 1.0, 5.0):
        r = synthesize(
            "solid-chen-wang", ex, size=(16, 16, 16), params={**base, "position_weight": weight}, seed=4
        )
        spread[weight] = r.stats["usage_spread"]
    # Measured (seeds 4, 5): 0.92 / 0.90 off, 0.66-0.72 at 1, 0.66-0.67 at 5 (the effect saturates).
    assert spread[1.0] < 0.85 * spread[0.0]
    assert spread[5.0] < 0.85 * spread[0.0]


def test_grey_remap_gives_the_exemplar_histogram_and_keeps_the_order() -> None:
    ex = _laminae()
    on = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params=FAST, seed=3)
    off = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params={**FAST, "grey_remap": False}, seed=3)
    # The paper's volume (off) is made of exemplar pixels; the remap replaces them rank for rank by the
    # exemplar's quantiles: the sorted volume is the sorted exemplar sampled evenly, the order is kept.
    n, ref = on.image.size, np.sort(ex.ravel())
    assert np.array_equal(np.sort(on.image.ravel()), ref[(np.arange(n) * ref.size) // n])
    a, b = off.image.ravel().astype(np.float64), on.image.ravel().astype(np.float64)
    i, j = np.argsort(a, kind="stable")[:-1], np.argsort(a, kind="stable")[1:]
    assert np.all(b[j] >= b[i])  # monotone: a brighter voxel never becomes darker than a darker one
    assert off.stats["contrast_before_remap"] == on.stats["contrast_before_remap"]
    assert abs(on.image.std() / ex.std() - 1.0) < 0.02


def test_progress_reaches_one_and_a_raising_callback_cancels() -> None:
    seen: list[float] = []
    synthesize(
        "solid-chen-wang", _laminae(), size=(16, 16, 16), params=FAST, progress=lambda s, f: seen.append(f)
    )
    assert seen[-1] == 1.0
    assert all(b >= a for a, b in itertools.pairwise(seen))
    assert max(np.diff([0.0, *seen])) <= 0.02 + 1e-9

    calls = []

    def stop(stage: str, fraction: float) -> None:
        calls.append(fraction)
        if fraction > 0.3:
            raise Cancelled("stop")

    with pytest.raises(Cancelled):
        synthesize("solid-chen-wang", _laminae(), size=(16, 16, 16), params=FAST, progress=stop)
    assert calls[-1] < 0.4

    def broken(stage: str, fraction: float) -> None:
        raise RuntimeError("worker gone")

    # texsynth.synth.methods.common.checked_progress: only Cancelled means "stop"; a broken callback fails
    # loudly.
    with pytest.raises(RuntimeError, match="worker gone"):
        synthesize("solid-chen-wang", _laminae(), size=(16, 16, 16), params=FAST, progress=broken)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"params": {"neighbourhood_size": 6}}, InvalidParameter, "neighbourhood_size.*odd"),
        ({"params": {"k": -1}}, InvalidParameter, "'k'"),
        ({"params": {"scan": "spiral"}}, InvalidParameter, "scan"),
        ({"params": {"structure": "stacked"}}, InvalidParameter, "structure"),
        ({"params": {"oriented_length": 0.0}}, InvalidParameter, "oriented_length"),
        ({"params": {"shells": "rings"}}, InvalidParameter, "shells"),
        ({"params": {"centre_spacing": 1.0}}, InvalidParameter, "centre_spacing"),
        ({"params": {"centre_spacing": 25.0}}, InvalidParameter, "centre_spacing"),
        ({"params": {"centre_spacing": "wide"}}, InvalidParameter, "centre_spacing"),
        ({"params": {"structure_length": "long"}}, InvalidParameter, "structure_length"),
        ({"params": {"structure_length": 0.0}}, InvalidParameter, "structure_length"),
        ({"params": {"structure_length": 65.0}}, InvalidParameter, "structure_length"),
        ({"params": {"histogram": 1}}, InvalidParameter, "unknown parameter"),
        ({"params": {"planes": ["xy"]}}, InvalidParameter, "planes must be two or three distinct planes"),
        ({"params": {"planes": ["xy", "xy"]}}, InvalidParameter, "planes must be two or three distinct"),
        ({"params": {"planes": ["xy", "zx"]}}, InvalidParameter, "planes must be names among"),
        (
            {"params": {"neighbourhood_size": 15}, "exemplar": np.zeros((12, 12), np.float32)},
            InvalidInput,
            "15x15",
        ),
        ({"size": (16, 16)}, InvalidParameter, "size"),
        ({"exemplar": np.full((32, 32), np.nan, np.float32)}, InvalidInput, "NaN"),
        ({"exemplar": np.zeros((32, 32, 3), np.float32)}, InvalidInput, "grey"),
    ],
)
def test_bad_inputs_say_what_is_wrong(kwargs, error, match) -> None:
    args = {"exemplar": _laminae(), "size": (16, 16, 16), "params": FAST, **kwargs}
    if "params" in kwargs:
        args["params"] = {**FAST, **kwargs["params"]}
    with pytest.raises(error, match=match):
        synthesize("solid-chen-wang", **args)


@pytest.mark.parametrize("start", ["none", "oriented"])
def test_same_bytes_with_one_or_two_threads(start: str) -> None:
    """The parallel search and solve write only their own slots, sum in a fixed order and split their
    work into a fixed number of blocks: one thread and two give the same bytes (from noise and from the
    oriented start)."""
    code = (
        "import hashlib; from texsynth.synth.api import synthesize; from texsynth.synth.io.patterns import "
        "undulating_laminae;"
        "ex = undulating_laminae((32, 32), period=6.0, amplitude=4.0, wavelength=32.0, noise=0.1, seed=0);"
        "r = synthesize('solid-chen-wang', ex, size=(12, 12, 12), params={'iterations': 2, 'levels': 2,"
        f" 'adapt_to_structure': False, 'structure': '{start}'}}, seed=3);"
        "assert r.stats['start'] == " + repr(start) + ";"
        "print(hashlib.sha256(r.image.tobytes()).hexdigest())"
    )
    digests = []
    for threads in ("1", "2"):
        env = {**os.environ, "NUMBA_NUM_THREADS": threads}
        out = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
        )
        digests.append(out.stdout.strip())
    assert digests[0] == digests[1] and len(digests[0]) == 64


def test_orientation_gain_defaults_to_laminae_only() -> None:
    """``orientation_gain=None``: the laminar gain for a laminar exemplar, off for a weakly oriented one,
    and whatever is given when given; the re-weighting changes the volume."""
    from texsynth.synth.io.patterns import undulating_laminae
    from texsynth.synth.methods.solid_chen_wang import LAMINAR_ORIENTATION_GAIN

    laminae = undulating_laminae((32, 32), 6, 4, 32, noise=0.2)
    noise = np.random.default_rng(0).random((32, 32)).astype(np.float32)
    small = {"iterations": 1, "levels": 2, "adapt_to_structure": True}
    lam = synthesize("solid-chen-wang", laminae, size=(12, 12, 12), params=small, seed=1)
    assert lam.stats["orientation_gain"] == LAMINAR_ORIENTATION_GAIN
    off = synthesize(
        "solid-chen-wang", laminae, size=(12, 12, 12), params={**small, "orientation_gain": 0.0}, seed=1
    )
    assert off.stats["orientation_gain"] == 0.0
    assert not np.array_equal(lam.image, off.image)
    grains = synthesize("solid-chen-wang", noise, size=(12, 12, 12), params=small, seed=1)
    assert grains.stats["orientation_gain"] == 0.0
    literal = synthesize(
        "solid-chen-wang", laminae, size=(12, 12, 12), params={**small, "adapt_to_structure": False}, seed=1
    )
    assert literal.stats["orientation_gain"] == 0.0


def test_solve_radius_defaults_to_one_for_laminae_only() -> None:
    """``solve_radius=None``: the solver also scores the neighbours' shifted matches (radius 1) for a
    laminar exemplar, only the voxel's own matches (0) for a weakly oriented one or when
    ``adapt_to_structure`` is off; a given radius is taken literally, and radius 1 is what the default
    gives on laminae (the same volume)."""
    from texsynth.synth.io.patterns import undulating_laminae
    from texsynth.synth.methods.solid_chen_wang import LAMINAR_SOLVE_RADIUS

    laminae = undulating_laminae((32, 32), 6, 4, 32, noise=0.2)
    noise = np.random.default_rng(0).random((32, 32)).astype(np.float32)
    small = {"iterations": 1, "levels": 2, "adapt_to_structure": True}
    lam = synthesize("solid-chen-wang", laminae, size=(12, 12, 12), params=small, seed=1)
    assert lam.stats["solve_radius"] == LAMINAR_SOLVE_RADIUS == 1
    given = synthesize(
        "solid-chen-wang", laminae, size=(12, 12, 12), params={**small, "solve_radius": 1}, seed=1
    )
    assert np.array_equal(lam.image, given.image)
    own = synthesize(
        "solid-chen-wang", laminae, size=(12, 12, 12), params={**small, "solve_radius": 0}, seed=1
    )
    assert own.stats["solve_radius"] == 0 and not np.array_equal(lam.image, own.image)
    grains = synthesize("solid-chen-wang", noise, size=(12, 12, 12), params=small, seed=1)
    assert grains.stats["solve_radius"] == 0
    literal = synthesize(
        "solid-chen-wang", laminae, size=(12, 12, 12), params={**small, "adapt_to_structure": False}, seed=1
    )
    assert literal.stats["solve_radius"] == 0


def test_oriented_start_keeps_a_tilted_stack_and_auto_takes_it_for_crumpled_stacks() -> None:
    """Per-plane slices of sheets normal to (1, 1, 1): the oriented start (solid-kopf's crumpled stack) gives
    each plane its orientation and the stack's spacing. 'auto' takes it, with its short schedule, for one
    crumpled anisotropic exemplar on the three planes and for a crumpled stack's three per-plane slices (the
    same bytes as asking for it), not for bent laminae, one exemplar or per plane (measured better from
    noise), two views, nor noise."""
    from texsynth.synth.io.laminar import turbostratic_volume
    from texsynth.synth.io.patterns import laminae_volume
    from texsynth.synth.methods.solid_chen_wang import (
        ORIENTED_COARSE_ITERATIONS,
        ORIENTED_ITERATIONS,
        ORIENTED_MAX_LENGTH,
        SolidChenWangParams,
        _Schedule,
        orientation_length,
    )
    from texsynth.synth.output.volume import mid_slices

    planes = mid_slices(turbostratic_volume((48, 48, 48), crumple=0.1, noise=0.1, seed=4))
    small = {"iterations": 1, "coarse_iterations": 4}
    res = synthesize(
        "solid-chen-wang",
        exemplars=planes,
        size=(24, 24, 24),
        params={**small, "structure": "oriented"},
        seed=2,
    )
    assert res.stats["start"] == "oriented" and res.stats["laminar_start"] and 5.0 < res.stats["period"] < 7.0
    for axis, plane in enumerate(("xy", "xz", "yz")):
        got = dominant_orientation(structure_tensor(np.take(res.image, 12, axis=axis)))
        want = dominant_orientation(structure_tensor(planes[plane]))
        assert abs(wrap_angle(got - want)) < np.radians(15), plane
    per_plane = _Schedule.resolve(SolidChenWangParams(), planes)
    assert (per_plane.start, per_plane.iterations) == ("oriented", ORIENTED_ITERATIONS)
    auto, asked = (
        synthesize(
            "solid-chen-wang", exemplars=planes, size=(16, 16, 16), params={**small, "structure": s}, seed=3
        )
        for s in ("auto", "oriented")
    )
    assert auto.stats["start"] == "oriented" and auto.image.tobytes() == asked.image.tobytes()
    # Per-plane bent sheets (laminae across two planes, contour bands on xy) keep the random start.
    sheets = laminae_volume((128, 128, 128), (1.0, 0.0, 0.0), 7, 6, 64, noise=0.2, seed=1)
    bent_planes = {"xy": sheets[64], "xz": sheets[:, 64, :], "yz": sheets[:, :, 64]}
    assert _Schedule.resolve(SolidChenWangParams(), bent_planes).start == "none"
    # Two views of the stack: not measured with the oriented start, so 'auto' keeps the random start.
    two = SolidChenWangParams(planes=("xz", "yz"))
    assert _Schedule.resolve(two, dict.fromkeys(PLANES, planes["xy"])).start == "none"
    one = dict.fromkeys(PLANES, planes["xy"])
    schedule = _Schedule.resolve(SolidChenWangParams(), one)
    assert (schedule.start, schedule.iterations, schedule.coarse_iterations) == (
        "oriented",
        ORIENTED_ITERATIONS,
        ORIENTED_COARSE_ITERATIONS,
    )
    auto, asked = (
        synthesize(
            "solid-chen-wang", exemplars=one, size=(16, 16, 16), params={**small, "structure": s}, seed=2
        )
        for s in ("auto", "oriented")
    )
    assert auto.stats["start"] == "oriented" and auto.image.tobytes() == asked.image.tobytes()
    # After the oriented start the schedule is shorter (nothing to grow); from noise the laminae's.
    assert (auto.stats["iterations"], auto.stats["coarse_iterations"]) == (ORIENTED_ITERATIONS, 4)
    noise = np.random.default_rng(0).random((32, 32)).astype(np.float32)
    grains = synthesize("solid-chen-wang", noise, size=(12, 12, 12), params={**small, "levels": 2}, seed=1)
    assert grains.stats["start"] == "none"
    # Bent laminae (one bend across the exemplar) keep their orientation for several periods: from noise.
    bent = undulating_laminae((128, 128), 7, 16, 128, noise=0.3)
    assert orientation_length(planes["xy"]) < ORIENTED_MAX_LENGTH < 3.0 < orientation_length(bent)
    assert _Schedule.resolve(SolidChenWangParams(), dict.fromkeys(PLANES, bent)).start == "none"


def test_sheet_length_is_the_fit_within_three_to_four_periods_or_as_given() -> None:
    """``structure_length`` empty (the default, or ``'auto'``) is solid-kopf's fit to the exemplars kept
    within 3-4 periods (shorter sheets break the shells into worms, longer lose the orientations); the
    length used is in the stats; a number is used as given; the random start has none, the oriented start
    its crumples' length."""
    from texsynth.synth.io.laminar import onion_volume, turbostratic_volume
    from texsynth.synth.methods.solid_chen_wang import MAX_STRUCTURE_LENGTH, MIN_STRUCTURE_LENGTH, _Schedule
    from texsynth.synth.methods.solid_kopf import ORIENTED_LENGTH
    from texsynth.synth.output.volume import mid_slices
    from texsynth.synth.pixel.laminar import fitted_structure_length

    r, c = np.mgrid[0:64, 0:64].astype(np.float64)
    shells = (0.5 + 0.4 * np.cos(2 * np.pi * np.hypot(r - 30.0, c - 34.0) / 6.0)).astype(np.float32)
    small_onions = mid_slices(onion_volume((64, 64, 64), seed=1))["xy"]
    rng = np.random.default_rng(0)  # three onions in 64 px (tests/synth/pixel/test_laminar.py's shells)
    d = np.min([np.hypot(r - y, c - x) for y, x in rng.uniform(0, 64, size=(3, 2))], axis=0)
    three = np.clip(0.5 + 0.4 * np.cos(2 * np.pi * d / 6.0) + rng.normal(0, 0.05, d.shape), 0, 1)
    three = three.astype(np.float32)
    fits = [fitted_structure_length([im]) for im in (small_onions, three, shells)]
    assert fits[0] < MIN_STRUCTURE_LENGTH < fits[1] < MAX_STRUCTURE_LENGTH < fits[2]
    laminar = {"structure": "laminar", "shells": "surfaces"}  # the length shapes the surfaces only
    for image, want in (
        (small_onions, MIN_STRUCTURE_LENGTH),
        (three, fits[1]),
        (shells, MAX_STRUCTURE_LENGTH),
    ):
        for empty in (None, "auto"):
            params = SolidChenWangParams(**laminar, structure_length=empty)
            assert _Schedule.resolve(params, dict.fromkeys(PLANES, image)).length == pytest.approx(want)
    params = {**FAST, **laminar}
    run = synthesize("solid-chen-wang", three, size=(16, 16, 16), params=params, seed=1)
    assert run.stats["start_length"] == pytest.approx(fits[1])
    assert run.params["structure_length"] is None  # the request as given; the stats say what was used
    given = synthesize(
        "solid-chen-wang", three, size=(16, 16, 16), params={**params, "structure_length": 2.5}, seed=1
    )
    assert given.stats["start_length"] == 2.5 and given.image.tobytes() != run.image.tobytes()
    noise = synthesize("solid-chen-wang", shells, size=(16, 16, 16), params={**FAST, "structure": "none"})
    assert noise.stats["start_length"] is None
    stack = mid_slices(turbostratic_volume((48, 48, 48), crumple=0.1, noise=0.1, seed=4))["xy"]
    oriented = SolidChenWangParams(structure="oriented")
    assert _Schedule.resolve(oriented, dict.fromkeys(PLANES, stack)).length == ORIENTED_LENGTH


@pytest.mark.parametrize("periodic", [True, False])
def test_centre_phase_is_the_distance_to_the_nearest_centre(periodic: bool) -> None:
    """``centre_phase`` (k-d tree) equals its brute-force reference, wrapped at the sides when periodic;
    one centre per ``spacing**3`` voxels, each at distance 0 from itself."""
    from texsynth.synth.pixel.laminar import centre_phase, centre_phase_reference

    shape = (12, 16, 20)
    got = centre_phase(shape, 6.0, np.random.default_rng(5), periodic=periodic)
    want = centre_phase_reference(shape, 6.0, np.random.default_rng(5), periodic=periodic)
    assert got.shape == shape and np.allclose(got, want, atol=1e-9)
    assert got.min() < 0.9  # a centre lies within a voxel's half-diagonal of a grid point
    if periodic:  # no voxel is farther from a centre than half the box's diagonal
        assert got.max() <= 0.5 * np.sqrt(12**2 + 16**2 + 20**2) + 1e-9
    one = centre_phase(shape, 100.0, np.random.default_rng(1), periodic=False)  # a single centre
    (cz, cy, cx) = np.unravel_index(np.argmin(one), shape)
    z, y, x = np.indices(shape)
    assert (
        np.corrcoef(one.ravel(), np.sqrt((z - cz) ** 2 + (y - cy) ** 2 + (x - cx) ** 2).ravel())[0, 1] > 0.99
    )


def test_centre_shells_start_from_onions_only_with_the_laminar_start(monkeypatch: pytest.MonkeyPatch) -> None:
    """``shells='centres'``: the laminar start's sheets are the shells of :func:`centre_phase`, its centres
    ``centre_spacing`` periods apart at the coarsest level (fitted to the exemplar when empty, the stats say
    it); the volume differs from the surfaces' start, the same seed gives the same bytes, and without the
    laminar start the option changes nothing."""
    import texsynth.synth.methods.solid_chen_wang as cw
    from texsynth.synth.pixel.laminar import fringe_centres

    calls: list[tuple[tuple[int, ...], float]] = []
    real = cw.centre_phase

    def spy(shape, spacing, rng, *, periodic=True):
        calls.append((tuple(shape), spacing))
        return real(shape, spacing, rng, periodic=periodic)

    monkeypatch.setattr(cw, "centre_phase", spy)
    ex = undulating_laminae((48, 48), period=6.0, amplitude=4.0, wavelength=24.0, noise=0.05, seed=0)
    params = {**FAST, "structure": "laminar", "structure_length": 3.0}
    runs = {
        shells: synthesize(
            "solid-chen-wang", ex, size=(16, 16, 16), params={**params, "shells": shells}, seed=2
        )
        for shells in ("surfaces", "centres")
    }
    assert len(calls) == 1  # the coarsest level only, and only for 'centres'
    shape, spacing = calls[0]
    stats = runs["centres"].stats
    scale = 2 ** (stats["levels"] - 1)
    assert shape == (16 // scale,) * 3
    assert stats["shells"] == "centres" and runs["surfaces"].stats["shells"] == "surfaces"
    assert stats["centre_spacing"] == pytest.approx(fringe_centres([ex])[1])
    assert spacing == pytest.approx(stats["centre_spacing"] * stats["period"] / scale)
    given = synthesize(
        "solid-chen-wang",
        ex,
        size=(16, 16, 16),
        params={**params, "shells": "centres", "centre_spacing": 7.5},
        seed=2,
    )
    assert given.stats["centre_spacing"] == 7.5
    assert calls[-1][1] == pytest.approx(7.5 * stats["period"] / scale)
    calls.pop()
    assert runs["centres"].image.tobytes() != runs["surfaces"].image.tobytes()
    again = synthesize(
        "solid-chen-wang", ex, size=(16, 16, 16), params={**params, "shells": "centres"}, seed=2
    )
    assert again.image.tobytes() == runs["centres"].image.tobytes()
    noise = [
        synthesize(
            "solid-chen-wang", ex, size=(12, 12, 12), params={**FAST, "structure": "none", "shells": s}
        )
        for s in ("surfaces", "centres")
    ]
    assert noise[0].image.tobytes() == noise[1].image.tobytes() and noise[1].stats["shells"] is None


def test_shells_default_to_auto_and_take_what_is_asked() -> None:
    """``shells`` defaults to 'auto' (session cw8: the fringes' curvature decides, not the fitted sheet
    length; session 14 refused a rule by the length); 'surfaces' and 'centres' are taken as asked whatever
    the exemplar; no shells without the laminar start."""
    from texsynth.synth.io.laminar import onion_volume
    from texsynth.synth.methods.solid_chen_wang import SolidChenWangParams, _Schedule
    from texsynth.synth.output.volume import mid_slices

    small = mid_slices(onion_volume((64, 64, 64), seed=1))["xy"]
    r, c = np.mgrid[0:64, 0:64].astype(np.float64)
    large = (0.5 + 0.4 * np.cos(2 * np.pi * np.hypot(r + 100.0, c - 30.0) / 6.0)).astype(np.float32)

    def shells(image: np.ndarray, **params: object) -> str | None:
        return _Schedule.resolve(SolidChenWangParams(**params), dict.fromkeys(PLANES, image)).shells

    assert SolidChenWangParams().shells == "auto"
    assert shells(small, structure="laminar") == "centres"
    assert shells(large, structure="laminar") == "surfaces"
    assert shells(small, structure="laminar", shells="surfaces") == "surfaces"
    assert shells(large, structure="laminar", shells="centres") == "centres"
    assert shells(small, structure="none", shells="centres") is None


def test_auto_shells_take_centres_only_where_the_fringes_curve_around_points() -> None:
    """``shells='auto'``: the centres for small onions (their fringes' centres of curvature gather: the
    onion truth's 64^3 mid-slice), the surfaces for one large ring set seen off-centre and for gently bent
    laminae (their centres scatter or lie outside); the stats say the concentration and the spacing, and
    ``'auto'`` without the laminar start changes nothing."""
    from texsynth.synth.io.laminar import onion_volume
    from texsynth.synth.methods.solid_chen_wang import _Schedule
    from texsynth.synth.output.volume import mid_slices
    from texsynth.synth.pixel.laminar import CENTRED_MIN_CONCENTRATION

    small_onions = mid_slices(onion_volume((96, 96, 96), seed=1))["xy"]
    r, c = np.mgrid[0:96, 0:96].astype(np.float64)
    far = (0.5 + 0.4 * np.cos(2 * np.pi * np.hypot(r + 150.0, c - 40.0) / 6.0)).astype(np.float32)
    bent = undulating_laminae((96, 96), period=6.0, amplitude=4.0, wavelength=48.0, noise=0.2, seed=1)
    laminar = SolidChenWangParams(structure="laminar", shells="auto")
    picks = {}
    for name, image in (("onions", small_onions), ("far rings", far), ("bent", bent)):
        schedule = _Schedule.resolve(laminar, dict.fromkeys(PLANES, image))
        picks[name] = (schedule.shells, schedule.concentration)
    assert picks["onions"][0] == "centres" and picks["onions"][1] >= CENTRED_MIN_CONCENTRATION
    assert picks["far rings"][0] == "surfaces" and picks["bent"][0] == "surfaces"
    assert max(picks["far rings"][1], picks["bent"][1]) < CENTRED_MIN_CONCENTRATION
    none = SolidChenWangParams(structure="none", shells="auto")
    schedule = _Schedule.resolve(none, dict.fromkeys(PLANES, small_onions))
    assert schedule.shells is None and schedule.centre_spacing is None


def test_auto_shells_take_centres_for_one_particle_seen_whole() -> None:
    """``shells='auto'`` also takes the centres where one centre explains the fringes' orientations (a
    particle seen whole, bent rings whose centres of curvature do not gather) and the fringes are long (they
    keep their orientation 2.2 periods or more), with the fitted spacing of their curvature; the stats say
    how much one centre explains. The same particle with short fringes takes the domains (session 20:
    measured better on the onion's top and core crops); rings around a far centre stay surfaces."""
    from texsynth.synth.methods.solid_chen_wang import _Schedule
    from texsynth.synth.pixel.laminar import (
        CENTRED_MIN_CONCENTRATION,
        CONCENTRIC_MIN_EXPLAINED,
        DOMAIN_MAX_BEND,
        concentric_fit,
        fringe_centres,
    )

    r, c = np.mgrid[0:96, 0:96].astype(np.float64)
    d, angle = np.hypot(r - 46.0, c - 50.0), np.arctan2(r - 46.0, c - 50.0)
    noise = np.random.default_rng(3).normal(0, 0.1, d.shape)

    def rings(wiggle: float) -> np.ndarray:
        image = 0.5 + 0.4 * np.cos(2 * np.pi * (d + wiggle * np.sin(5 * angle + d / 10.0)) / 6.0) + noise
        return np.clip(image, 0.0, 1.0).astype(np.float32)

    particle, short = rings(2.0), rings(3.0)
    laminar = SolidChenWangParams(structure="laminar")
    short_schedule = _Schedule.resolve(laminar, dict.fromkeys(PLANES, short))
    assert short_schedule.shells == "domains" and short_schedule.bend < DOMAIN_MAX_BEND
    schedule = _Schedule.resolve(laminar, dict.fromkeys(PLANES, particle))
    assert schedule.bend >= DOMAIN_MAX_BEND
    assert schedule.concentration is not None and schedule.concentration < CENTRED_MIN_CONCENTRATION
    assert schedule.concentric == pytest.approx(concentric_fit(particle).explained)
    assert schedule.concentric >= CONCENTRIC_MIN_EXPLAINED and schedule.shells == "centres"
    assert schedule.centre_spacing == pytest.approx(fringe_centres([particle])[1])
    far = (0.5 + 0.4 * np.cos(2 * np.pi * np.hypot(r + 150.0, c - 40.0) / 6.0)).astype(np.float32)
    far_schedule = _Schedule.resolve(laminar, dict.fromkeys(PLANES, far))
    assert far_schedule.shells == "surfaces" and far_schedule.concentric < CONCENTRIC_MIN_EXPLAINED
    params = {**FAST, "structure": "laminar"}
    result = synthesize("solid-chen-wang", particle, size=(12, 12, 12), params=params)
    assert result.stats["shells"] == "centres"
    assert result.stats["concentric_explained"] == pytest.approx(schedule.concentric)


# ---------------------------------------------------------------- the last step: grain


def _smooth(side: int = 32, seed: int = 0) -> np.ndarray:
    """Blobs (a blurred noise, a little noise on top): the discrete solver's copies speckle on it."""
    from scipy import ndimage as ndi

    rng = np.random.default_rng(seed)
    x = ndi.gaussian_filter(rng.normal(size=(side, side)), 1.0, mode="wrap")
    x = (x - x.min()) / (x.max() - x.min()) + 0.1 * rng.normal(size=x.shape)
    return np.clip(x, 0.0, 1.0).astype(np.float32)


def test_final_step_auto_blends_the_average_in_until_no_grainier_than_the_exemplar() -> None:
    ex = _smooth()
    runs = {
        step: synthesize(
            "solid-chen-wang", ex, size=(16, 16, 16), params={**FAST, "final_step": step}, seed=2
        )
        for step in ("auto", "discrete", "average")
    }
    auto, discrete, average = (runs[s] for s in ("auto", "discrete", "average"))
    # The paper's discrete volume is grainier than the exemplar (measured 1.47x, blend 0.66).
    assert auto.stats["grain_ratio"]["discrete"] > 1.3
    assert 0.0 < auto.stats["final_blend"] < 1.0 and auto.stats["grain_ratio"]["final"] <= 1.0
    assert discrete.stats["final_blend"] == 0.0 and average.stats["final_blend"] == 1.0
    assert average.stats["grain_ratio"]["final"] < auto.stats["grain_ratio"]["final"]
    # The grain measured on the returned slices follows: discrete > auto > average.
    from texsynth.synth.analysis.grain import fine_share

    def grain(vol: np.ndarray) -> float:
        return float(np.mean([fine_share(s) for s in vol]))

    assert grain(discrete.image) > grain(auto.image) > grain(average.image)
    assert np.isin(discrete.image, ex).all()  # the paper: exemplar pixels (after the remap, its quantiles)


def test_final_step_auto_keeps_the_discrete_volume_where_it_is_not_grainier() -> None:
    # White noise: nothing is grainier than the exemplar, so 'auto' returns the paper's bytes.
    ex = np.random.default_rng(5).random((32, 32)).astype(np.float32)
    auto = synthesize("solid-chen-wang", ex, size=(16, 16, 16), params=FAST, seed=3)
    paper = synthesize(
        "solid-chen-wang", ex, size=(16, 16, 16), params={**FAST, "final_step": "discrete"}, seed=3
    )
    assert auto.stats["final_blend"] == 0.0 and auto.stats["grain_ratio"]["discrete"] <= 1.0
    assert auto.image.tobytes() == paper.image.tobytes()
