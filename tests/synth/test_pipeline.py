"""load -> synthesize -> write, shared by ``texsynth synthesize`` and the worker: per-plane inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.synth.test_api import SOLID
from texsynth.synth.api import METHODS as REGISTRY
from texsynth.synth.cli import main
from texsynth.synth.errors import InvalidInput
from texsynth.synth.io import save_image
from texsynth.synth.pipeline import load_inputs


@pytest.fixture
def solid():
    REGISTRY[SOLID.name] = SOLID
    yield SOLID
    REGISTRY.pop(SOLID.name, None)


@pytest.fixture
def planes(tmp_path):
    rng = np.random.default_rng(3)
    paths = {}
    for plane, shape in (("xy", (24, 24)), ("xz", (16, 24)), ("yz", (16, 24))):
        paths[plane] = tmp_path / f"{plane}.png"
        save_image(paths[plane], rng.random(shape, dtype=np.float32))
    return paths


def test_per_plane_exemplars_of_different_bit_depth_are_refused_before_decoding_work(planes, tmp_path):
    deep = tmp_path / "xz16.png"
    save_image(deep, np.linspace(0, 1, 16 * 24, dtype=np.float32).reshape(16, 24), bit_depth=16)
    sources = {"exemplar_xy": planes["xy"], "exemplar_xz": deep, "exemplar_yz": planes["yz"]}
    with pytest.raises(InvalidInput, match=r"one bit depth.*exemplar_xy 8-bit, exemplar_xz 16-bit"):
        load_inputs(sources)


def test_unknown_role_is_named():
    with pytest.raises(InvalidInput, match=r"^mask: not an input of any method"):
        load_inputs({"mask": b"\x89PNG"})


def test_cli_takes_per_plane_exemplars_and_writes_a_volume(solid, planes, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["synthesize", "probe-solid", "--size", "10x9x8", "--no-plots", "--out", str(out)]
    for plane, path in planes.items():
        argv += [f"--exemplar-{plane}", str(path)]
    assert main(argv) == 0
    assert "probe-solid: 10x9x8 in" in capsys.readouterr().out
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["output_shape"] == [8, 9, 10]
    assert manifest["exemplar_shapes"] == {"xy": [24, 24], "xz": [16, 24], "yz": [16, 24]}
    assert manifest["finished"] >= manifest["started"]
    assert (out / "output.tiff").exists() and (out / "slices.png").exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--exemplar-xy", "PLANE"], "exemplar_xz: missing: per-plane exemplars come as all three"),
        (["--exemplar", "PLANE", "--exemplar-xy", "PLANE"], "exemplar: give one exemplar or one per plane"),
        ([], "exemplar: missing: method 'probe-solid' needs an exemplar image"),
    ],
)
def test_cli_input_errors_are_one_line_before_any_work(solid, planes, tmp_path, capsys, extra, message):
    argv = ["synthesize", "probe-solid", "--out", str(tmp_path / "o")]
    argv += [str(planes["xy"]) if a == "PLANE" else a for a in extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "o").exists()


def test_wei_levoy_refuses_per_plane_exemplars(planes, tmp_path, capsys):
    argv = ["synthesize", "wei-levoy", "--exemplar-xy", str(planes["xy"]), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "exemplar_xy: method 'wei-levoy' takes one exemplar, not one per plane" in capsys.readouterr().err


def test_a_2d_run_on_two_threads_takes_its_exemplar_work_made_during_the_synthesis(tmp_path, monkeypatch):
    """synthesize_to_folder starts ExemplarAhead at the synthesis' first progress report and the writer
    takes all of it; the files are those of one thread (the JSON files but for their clocks)."""
    from texsynth.synth.io.patterns import undulating_laminae
    from texsynth.synth.output import artifacts
    from texsynth.synth.pipeline import synthesize_to_folder

    taken: list[set[str]] = []
    result = artifacts.ExemplarAhead.result

    def spy(self, exemplar, constraint):
        values = result(self, exemplar, constraint)
        taken.append(set(values))
        return values

    monkeypatch.setattr(artifacts.ExemplarAhead, "result", spy)
    exemplar = undulating_laminae((40, 40), period=6, amplitude=4, wavelength=40)
    files = {}
    for threads in (1, 2):
        outcome = synthesize_to_folder(
            "wei-levoy",
            {"exemplar": exemplar},
            tmp_path / str(threads),
            size=(48, 48),
            seed=2,
            threads=threads,
        )
        files[threads] = outcome.files
    assert taken == [{"exemplar", "fringes_shown", "side", "diagnostics", "exemplar-"}]  # two threads only
    assert files[1] == files[2]
    for name in files[1]:
        a, b = (tmp_path / str(t) / name for t in (1, 2))
        if name.endswith(".json"):
            clock = ("timings", "started", "finished")
            da, db = (json.loads(p.read_text()) for p in (a, b))
            assert {k: v for k, v in da.items() if k not in clock} == {
                k: v for k, v in db.items() if k not in clock
            }
        else:
            assert a.read_bytes() == b.read_bytes(), name
