"""The writer's two threads: a 2-D run's pictures are written while the evaluation runs, with the same
files, names and bytes as on one thread, and nothing written after the evaluation fails."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

from texsynth.synth.api import synthesize
from texsynth.synth.io.patterns import undulating_laminae
from texsynth.synth.output import artifacts
from texsynth.synth.threads import use_threads

_CLOCK = ("timings", "started", "finished")


def _without_clock(value: object) -> object:
    if isinstance(value, dict):
        return {k: _without_clock(v) for k, v in value.items() if k not in _CLOCK}
    if isinstance(value, list):
        return [_without_clock(v) for v in value]
    return value


@pytest.fixture(scope="module")
def run() -> tuple[np.ndarray, artifacts.Result]:
    exemplar = undulating_laminae((40, 40), period=6, amplitude=4, wavelength=40)
    result = synthesize(
        "tensor-constrained", exemplar, size=(48, 48), params={"neighbourhood_size": 5}, seed=1
    )
    return exemplar, result


def _write(folder: Path, run: tuple[np.ndarray, artifacts.Result], threads: int) -> list[str]:
    exemplar, result = run
    with use_threads(threads):
        names, _ = artifacts.write_artifacts(folder, result, exemplar, exemplar, {"job": "x"})
    return names


def test_one_and_two_threads_write_the_same_files(run: tuple, tmp_path: Path) -> None:
    one = _write(tmp_path / "one", run, 1)
    two = _write(tmp_path / "two", run, 2)
    assert one == two
    assert "exemplar-coherence.png" in one and "constraint_orientation.png" in one
    on_disk = sorted(p.relative_to(tmp_path / "one").as_posix() for p in (tmp_path / "one").rglob("*.*"))
    assert sorted(one) == on_disk
    for name in one:
        a, b = tmp_path / "one" / name, tmp_path / "two" / name
        if name.endswith(".json"):
            assert _without_clock(json.loads(a.read_text())) == _without_clock(json.loads(b.read_text())), (
                name
            )
        else:
            assert a.read_bytes() == b.read_bytes(), name


def test_a_failed_evaluation_leaves_no_picture_being_written(
    run: tuple, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    started = threading.Event()
    seen: set[str] = set()

    def slow_pictures(*args: object, **kwargs: object) -> list[str]:
        seen.add(threading.current_thread().name)
        started.set()
        return original(*args, **kwargs)

    def failing(*args: object, **kwargs: object) -> None:
        started.wait(30)
        raise RuntimeError("evaluation failed")

    original = artifacts._write_tensor_images
    monkeypatch.setattr(artifacts, "_write_tensor_images", slow_pictures)
    monkeypatch.setattr(artifacts, "evaluate_pair_fringes", failing)
    with pytest.raises(RuntimeError, match="evaluation failed"):
        _write(tmp_path / "run", run, 2)
    assert seen == {"texsynth-pictures"}  # the pictures were on the second thread ...
    assert not [t for t in threading.enumerate() if t.name == "texsynth-pictures"]  # ... and it ended
    assert (tmp_path / "run" / "exemplar-orientation.png").is_file()  # the thread had finished its work
