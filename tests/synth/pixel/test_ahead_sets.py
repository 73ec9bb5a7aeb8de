"""The finer levels' k-coherence sets made ahead on another thread (``_AheadSets``): every level's
prediction of the run's generator holds, the run takes them, and its source maps are those of one thread."""

from __future__ import annotations

import numpy as np
import pytest

import texsynth.synth.pixel.synthesis as synthesis
from texsynth.synth.kernels.pixel_search import METRIC_SSD
from texsynth.synth.pixel.synthesis import Guidance, SearchSettings, synthesize_source_map
from texsynth.synth.threads import use_threads

SHAPES = [(24, 24), (12, 12), (6, 6)]


def _exemplar(levels: int, channels: int = 1) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    return [rng.random((40 >> i, 40 >> i, channels), dtype=np.float32) for i in range(levels)]


def _run(settings: SearchSettings, threads: int, **kwargs) -> tuple[list[np.ndarray], list[tuple[int, bool]]]:
    """The source maps of a run on ``threads`` threads, and each ahead level taken: (level, taken)."""
    taken: list[tuple[int, bool]] = []
    take = synthesis._AheadSets.take

    def spy(self, level, state):
        sets = take(self, level, state)
        taken.append((level, sets is not None))
        return sets

    levels = settings.levels
    ex = kwargs.pop("ex", None) or _exemplar(levels)
    with pytest.MonkeyPatch.context() as mp, use_threads(threads):
        mp.setattr(synthesis._AheadSets, "take", spy)
        srcs = synthesize_source_map(ex, SHAPES[:levels], settings, seed=11, **kwargs)[0]
    return srcs, taken


CASES = {
    "defaults": SearchSettings(size=5, levels=2, iterations=2, k=3),
    "square refinement": SearchSettings(
        size=5, levels=3, iterations=2, k=3, refine_square=True, falloff=0.156
    ),
    "periodic, three passes": SearchSettings(size=5, levels=2, iterations=3, k=4, periodic=True),
    "one pass": SearchSettings(size=5, levels=3, iterations=1, k=2, refine_square=True),
    "random scan": SearchSettings(size=5, levels=2, iterations=2, k=3, scan="random"),
    "hilbert scan, histogram": SearchSettings(size=5, levels=2, k=3, scan="hilbert", histogram_weight=5.0),
}


@pytest.mark.parametrize("name", list(CASES))
def test_every_finer_level_takes_its_sets_made_ahead(name: str) -> None:
    settings = CASES[name]
    one, none_taken = _run(settings, 1)
    two, taken = _run(settings, 2)
    assert none_taken == []  # one thread: nothing made ahead
    assert taken == [(level, True) for level in range(settings.levels - 2, -1, -1)]
    assert all(np.array_equal(a, b) for a, b in zip(one, two, strict=True))


def test_guided_run_and_initial_maps_take_their_sets() -> None:
    rng = np.random.default_rng(2)
    settings = SearchSettings(size=5, levels=2, iterations=2, k=3, refine_square=True)
    ex = _exemplar(2, channels=3)
    tens = [rng.random(e.shape, dtype=np.float32) for e in ex]
    guidance = Guidance(
        out_levels=[rng.random((*s, 3), dtype=np.float32) for s in SHAPES[:2]],
        ex_levels=tens,
        metric=METRIC_SSD,
        weight=0.4,
        size=5,
    )
    initial = [
        np.stack(np.meshgrid(*(np.arange(n) % 8 + 3 for n in s), indexing="ij"), axis=-1) for s in SHAPES[:2]
    ]
    for kwargs in ({"guidance": guidance, "p": 0.6}, {"initial": initial}):
        one, _ = _run(settings, 1, ex=ex, **kwargs)
        two, taken = _run(settings, 2, ex=ex, **kwargs)
        assert taken == [(0, True)]
        assert all(np.array_equal(a, b) for a, b in zip(one, two, strict=True))


def test_a_wrong_prediction_is_not_taken_and_the_run_makes_its_own_sets(monkeypatch) -> None:
    """A replay that draws once too often (as if the passes' draws had changed) predicts another state:
    the run makes the sets itself, with the same source maps."""
    settings = CASES["square refinement"]
    one, _ = _run(settings, 1)
    draws = synthesis._pass_draws

    def one_more(settings, shape, started, rng):
        draws(settings, shape, started, rng)
        rng.integers(0, 2)

    monkeypatch.setattr(synthesis, "_pass_draws", one_more)
    two, taken = _run(settings, 2)
    assert taken == [(1, False), (0, False)]
    assert all(np.array_equal(a, b) for a, b in zip(one, two, strict=True))


def test_an_error_while_making_sets_ahead_leaves_the_run_to_make_them(monkeypatch) -> None:
    settings = CASES["defaults"]
    one, _ = _run(settings, 1)
    made = synthesis._level_sets
    calls = {"n": 0}

    def fails_on_its_thread(lv, *args):
        if synthesis.threading.current_thread().name == "texsynth-sets-ahead":
            raise MemoryError("made to fail")
        calls["n"] += 1
        return made(lv, *args)

    monkeypatch.setattr(synthesis, "_level_sets", fails_on_its_thread)
    two, taken = _run(settings, 2)
    assert taken == [(0, False)] and calls["n"] == 2  # both levels made by the run
    assert all(np.array_equal(a, b) for a, b in zip(one, two, strict=True))
