"""The writer's two threads: a run's pictures (a 2-D output's or a volume's) are written while the
evaluation, metrics.json and the plots are, the caller then taking those left, with the same files, names
and bytes as on one thread; nothing is written after the evaluation fails, a failed picture reaches the
caller, and no thread is left running."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

from texsynth.synth.api import Result, synthesize
from texsynth.synth.io.patterns import gaussian_random_field, undulating_laminae
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


def _same_files(one: list[str], two: list[str], tmp_path: Path) -> None:
    assert one == two
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


def test_one_and_two_threads_write_the_same_files(run: tuple, tmp_path: Path) -> None:
    one = _write(tmp_path / "one", run, 1)
    two = _write(tmp_path / "two", run, 2)
    assert "exemplar-coherence.png" in one and "constraint_orientation.png" in one
    assert any(name.startswith("plots/") for name in one)
    _same_files(one, two, tmp_path)


def test_a_volume_with_one_and_two_threads_writes_the_same_files(tmp_path: Path) -> None:
    volume = gaussian_random_field((12, 16, 20), (1.5, 3.0, 5.0), 0.4, seed=2)
    planes = {
        plane: gaussian_random_field((24, 24), scales, 0.4, seed=seed)
        for plane, scales, seed in (("xy", (3.0, 5.0), 3), ("xz", (1.5, 5.0), 4), ("yz", (1.5, 3.0), 5))
    }
    result = Result(method="test", image=volume, params={}, seed=0, timings={"total": 1.0})
    names = {}
    for threads, folder in ((1, "one"), (2, "two")):
        with use_threads(threads):
            names[folder], _ = artifacts.write_artifacts(
                tmp_path / folder, result, planes["xy"], exemplars=planes
            )
    assert names["one"][:3] == ["output.png", "output.tiff", "slices.png"]
    assert names["one"].index("cube.png") < names["one"].index("metrics.json")
    _same_files(names["one"], names["two"], tmp_path)


def test_the_plots_are_drawn_while_the_pictures_are_and_the_caller_takes_those_left(
    run: tuple, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plotted, helped = threading.Event(), threading.Event()
    seen: list[str] = []

    def pictures(*args: object, **kwargs: object) -> list[str]:
        seen.append(threading.current_thread().name)
        if threading.current_thread().name == "texsynth-pictures":
            # the main thread draws the plots without waiting for this one, then takes a picture left
            assert plotted.wait(30), "the plots waited for the pictures"
            helped.wait(30)
        else:
            helped.set()
        return original_pictures(*args, **kwargs)

    def plots(*args: object, **kwargs: object) -> list[str]:
        out = original_plots(*args, **kwargs)
        plotted.set()
        return out

    original_pictures, original_plots = artifacts._write_tensor_images, artifacts.write_plots
    monkeypatch.setattr(artifacts, "_write_tensor_images", pictures)
    monkeypatch.setattr(artifacts, "write_plots", plots)
    names = _write(tmp_path / "two", run, 2)
    assert "MainThread" in seen and "texsynth-pictures" in seen
    monkeypatch.setattr(artifacts, "_write_tensor_images", original_pictures)
    assert names == _write(tmp_path / "one", run, 1)  # their names keep their place
    assert not [t for t in threading.enumerate() if t.name == "texsynth-pictures"]


def test_a_failed_picture_reaches_the_caller_and_no_thread_is_left(
    run: tuple, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def failing(*args: object, **kwargs: object) -> list[str]:
        raise OSError("disk full while writing a picture")

    monkeypatch.setattr(artifacts, "_write_tensor_images", failing)
    with pytest.raises(OSError, match="disk full while writing a picture"):
        _write(tmp_path / "run", run, 2)
    assert not [t for t in threading.enumerate() if t.name == "texsynth-pictures"]
    assert not (tmp_path / "run" / "manifest.json").exists()  # the manifest is the last file, not written


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


def test_with_two_threads_the_charts_are_encoded_as_pictures_tasks(
    run: tuple, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every chart is drawn on the calling thread and handed to the pictures' queue to be encoded and
    written (by whichever thread takes it): as many charts saved as plot files, each once."""
    from texsynth.synth.output.chart import Chart

    saved: list[tuple[str, str]] = []
    original = Chart.save

    def save(self: Chart, path: str | Path) -> Path:
        saved.append((Path(path).name, threading.current_thread().name))
        return original(self, path)

    monkeypatch.setattr(Chart, "save", save)
    queued: list[object] = []
    add = artifacts._Pictures.add
    monkeypatch.setattr(artifacts._Pictures, "add", lambda self, task: (queued.append(task), add(self, task)))
    names = _write(tmp_path / "two", run, 2)
    plots = sorted(n.removeprefix("plots/") for n in names if n.startswith("plots/"))
    assert sorted(name for name, _ in saved) == plots and len(queued) == len(plots)
    assert all((tmp_path / "two" / "plots" / name).is_file() for name in plots)


def test_a_task_added_while_the_second_thread_waits_is_run_once() -> None:
    ran: list[str] = []
    first_done = threading.Event()
    pictures = artifacts._Pictures([lambda: (ran.append("first"), first_done.set(), ["a.png"])[2]])
    pictures.start()
    assert first_done.wait(30)
    pictures.add(lambda: ran.append(threading.current_thread().name))  # the second thread is waiting
    assert pictures.finish() == ["a.png"]
    assert ran[0] == "first" and len(ran) == 2
    assert not [t for t in threading.enumerate() if t.name == "texsynth-pictures"]


def test_the_exemplar_made_ahead_gives_the_same_files_and_spares_its_work(
    run: tuple, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """:class:`ExemplarAhead` (made while the output is synthesized): the same files and bytes as without,
    and the writer neither analyses the exemplar nor draws its tensor images or the constraint's again."""
    exemplar, result = run
    with use_threads(2):
        ahead = artifacts.ExemplarAhead(exemplar, exemplar)
        assert ahead.result(exemplar, exemplar) == {}  # not started: nothing made
        ahead.start()
        assert ahead.result(exemplar, exemplar).keys() == {
            "exemplar",
            "fringes_shown",
            "side",
            "diagnostics",
            "exemplar-",
            "constraint_",
        }
    names = _write(tmp_path / "one", run, 1)
    calls: list[str] = []
    for name in ("fringes_shown", "exemplar_diagnostics", "_write_tensor_images"):
        original = getattr(artifacts, name)
        monkeypatch.setattr(
            artifacts, name, lambda *a, _n=name, _f=original, **k: (calls.append(_n), _f(*a, **k))[1]
        )
    with use_threads(2):
        two, _ = artifacts.write_artifacts(
            tmp_path / "two", result, exemplar, exemplar, {"job": "x"}, ahead=ahead
        )
    assert calls == ["_write_tensor_images"]  # the output's own tensor images only
    _same_files(names, two, tmp_path)


def test_an_exemplar_made_ahead_from_another_array_is_not_used(run: tuple, tmp_path: Path) -> None:
    exemplar, result = run
    other = np.ascontiguousarray(exemplar[::-1])
    ahead = artifacts.ExemplarAhead(other)
    ahead.start()
    assert ahead.result(exemplar, None) == {}
    names = _write(tmp_path / "one", run, 1)
    with use_threads(2):
        two, _ = artifacts.write_artifacts(
            tmp_path / "two", result, exemplar, exemplar, {"job": "x"}, ahead=ahead
        )
    _same_files(names, two, tmp_path)


def test_exemplar_side_is_the_evaluations_own_half() -> None:
    from texsynth.synth.evaluate.measures import evaluate_pair_fringes, exemplar_side

    exemplar = undulating_laminae((40, 40), period=6, amplitude=4, wavelength=40)
    output = undulating_laminae((48, 56), period=6, amplitude=3, wavelength=30)
    plain = evaluate_pair_fringes(exemplar, output, fringes=True)[0]
    side = exemplar_side(exemplar, fringes=True)
    handed, handed_fringes = evaluate_pair_fringes(exemplar, output, fringes=True, exemplar_side=side)
    assert json.dumps(plain, sort_keys=True) == json.dumps(handed, sort_keys=True)
    assert handed_fringes["exemplar"] is side.stats.extracted  # taken, not made again
    other = evaluate_pair_fringes(exemplar, output, fringes=False, exemplar_side=side)[0]  # other settings
    assert json.dumps(other, sort_keys=True) == json.dumps(
        evaluate_pair_fringes(exemplar, output, fringes=False)[0], sort_keys=True
    )
