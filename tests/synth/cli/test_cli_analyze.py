"""``texsynth analyze`` and ``texsynth methods`` through :func:`texsynth.synth.cli.main`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from texsynth.synth.api import available_methods
from texsynth.synth.cli import main
from texsynth.synth.cli import methods as methods_cli
from texsynth.synth.output.render import legend_shape, orientation_image

SIZE = 128
THETA_DEG = 32.0  # gradient direction of the test grating (inside a 5-degree bin); fringes at -58


def grating(theta_deg: float, size: int = SIZE, period: float = 8.0) -> np.ndarray:
    """``sin(2 pi (x cos t + y sin t) / period)`` in [0, 1], ``x = col``, ``y = -row``."""
    t = np.radians(theta_deg)
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    return 0.5 + 0.5 * np.sin(2 * np.pi * (cols * np.cos(t) - rows * np.sin(t)) / period)


def write_png(path: Path, image: np.ndarray) -> Path:
    Image.fromarray(np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)).save(path)
    return path


def wrapped_deg(a: float) -> float:
    """Degrees wrapped to (-90, 90]."""
    return 90.0 - (90.0 - a) % 180.0


@pytest.fixture
def grating_png(tmp_path: Path) -> Path:
    return write_png(tmp_path / "grating.png", grating(THETA_DEG))


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


# --- analyze: files and content ---------------------------------------------------------------


def test_analyze_writes_decodable_files(
    grating_png: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = tmp_path / "out" / "nested"
    code, out, err = run_cli(["analyze", str(grating_png), "--out", str(out_dir)], capsys)
    assert code == 0, err
    assert err == ""
    assert "tensor.json" in out and len(out.strip().splitlines()) == 1
    assert sorted(p.name for p in out_dir.iterdir()) == [
        "coherence.png",
        "composite.png",
        "orientation.png",
        "tensor.json",
    ]
    for name, mode, kind in [
        ("coherence.png", "L", "coherence"),
        ("orientation.png", "RGB", "orientation"),
        ("composite.png", "RGB", "composite"),
    ]:
        with Image.open(out_dir / name) as im:
            im.load()
            assert im.format == "PNG" and im.mode == mode
            h_leg, w_leg = legend_shape(kind, SIZE)  # type: ignore[arg-type]
            assert im.size == (max(SIZE, w_leg), SIZE + h_leg)  # the image and its legend


def test_analyze_json_for_a_grating(
    grating_png: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(["analyze", str(grating_png), "--out", str(tmp_path)], capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "tensor.json").read_text())
    assert report["shape"] == [SIZE, SIZE]
    assert report["sigma_d"] == 1.0 and report["sigma_w"] == 3.0
    assert report["source"] == str(grating_png)
    assert report["mean_coherence"] > 0.9
    dominant = report["dominant_orientation_deg"]
    assert dominant["gradient"] == pytest.approx(THETA_DEG, abs=1.0)
    assert dominant["fringe"] == pytest.approx(wrapped_deg(THETA_DEG + 90.0), abs=1.0)
    hist = report["orientation_histogram"]
    edges = np.array(hist["bin_edges_deg"])
    assert hist["bins"] == 36 and edges.shape == (37,)
    assert edges[0] == pytest.approx(-90.0) and edges[-1] == pytest.approx(90.0)
    for key, expected in (("gradient", THETA_DEG), ("fringe", wrapped_deg(THETA_DEG + 90.0))):
        counts = np.array(hist[key])
        assert counts.shape == (36,) and counts.sum() == pytest.approx(1.0)
        peak = int(np.argmax(counts))
        assert edges[peak] <= expected <= edges[peak + 1]


def test_analyze_options_and_rgb_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    grey = grating(-75.0, size=96)
    rgb = np.stack([grey, 0.5 * grey, 1.0 - grey], axis=-1)
    src = write_png(tmp_path / "rgb.png", rgb)
    argv = [
        "analyze",
        str(src),
        "--out",
        str(tmp_path / "o"),
        "--sigma-d",
        "1.5",
        "--sigma-w",
        "4",
        "--bins",
        "18",
    ]
    code, _, err = run_cli(argv, capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "o" / "tensor.json").read_text())
    assert report["shape"] == [96, 96, 3]
    assert report["sigma_d"] == 1.5 and report["sigma_w"] == 4.0
    assert len(report["orientation_histogram"]["gradient"]) == 18
    assert report["dominant_orientation_deg"]["gradient"] == pytest.approx(-75.0, abs=1.0)
    assert report["dominant_orientation_deg"]["fringe"] == pytest.approx(15.0, abs=1.0)


def test_analyze_orientation_png_shows_fringe_direction(
    grating_png: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Fringes at -58 degrees: hue (-58 + 90) / 180 ~ 0.18, a yellow, not the gradient's violet."""
    assert run_cli(["analyze", str(grating_png), "--out", str(tmp_path)], capsys)[0] == 0
    with Image.open(tmp_path / "orientation.png") as im:
        rgb = np.asarray(im.convert("RGB")).astype(int)
    centre = rgb[SIZE // 2 - 8 : SIZE // 2 + 8, SIZE // 2 - 8 : SIZE // 2 + 8].reshape(-1, 3)
    fringe_colour = orientation_image(np.radians([[wrapped_deg(THETA_DEG + 90.0)]]))[0, 0].astype(int)
    gradient_colour = orientation_image(np.radians([[THETA_DEG]]))[0, 0].astype(int)
    assert fringe_colour.tolist() == [238, 255, 0]
    assert np.abs(centre - fringe_colour).max() <= 8
    assert np.abs(centre - gradient_colour).max() > 100


# --- analyze: errors --------------------------------------------------------------------------


def assert_one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("texsynth analyze: error:")
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0]


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.png"
    code, _, err = run_cli(["analyze", str(missing), "--out", str(tmp_path / "o")], capsys)
    assert_one_line_error(code, err, "nope.png")
    assert not (tmp_path / "o").exists()


def test_text_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = tmp_path / "notes.png"
    text.write_text("these are lab notes, not an image\n")
    code, _, err = run_cli(["analyze", str(text), "--out", str(tmp_path / "o")], capsys)
    assert_one_line_error(code, err, "notes.png")


@pytest.mark.parametrize(
    ("option", "value", "name"),
    [
        ("--sigma-d", "0", "sigma_d"),
        ("--sigma-d", "-1", "sigma_d"),
        ("--sigma-d", "nan", "sigma_d"),
        ("--sigma-w", "inf", "sigma_w"),
        ("--sigma-w", "1e9", "sigma_w"),  # larger than the image: refused, not a kernel of 8e9 taps
        ("--bins", "0", "bins"),
    ],
)
def test_invalid_parameter(
    grating_png: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str, name: str
) -> None:
    code, _, err = run_cli(
        ["analyze", str(grating_png), "--out", str(tmp_path / "o"), f"{option}={value}"], capsys
    )
    assert_one_line_error(code, err, name)
    assert not (tmp_path / "o").exists()


def test_out_is_a_file(grating_png: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = run_cli(["analyze", str(grating_png), "--out", str(blocker / "sub")], capsys)
    assert_one_line_error(code, err, "out")


@pytest.mark.parametrize(
    "argv",
    [
        ["analyze", "x.png", "--out", "o", "--sigma-d", "wide"],  # not a number
        ["analyze", "x.png"],  # --out missing
        ["analyze"],
        ["frobnicate"],
    ],
)
def test_usage_errors_exit_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert "error:" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--help"], ["analyze", "--help"], ["methods", "--help"]])
def test_help_exits_0(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: texsynth")
    if argv[0] == "analyze":
        assert "--sigma-d" in out and "fringe direction" in out


# --- methods ----------------------------------------------------------------------------------


def test_methods_json_lists_registry_with_schemas(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["methods", "--json"], capsys)
    assert code == 0 and err == ""
    listed = json.loads(out)
    registry = available_methods()
    assert [m["name"] for m in listed] == sorted(registry)
    for item in listed:
        assert item["schema"] == registry[item["name"]].schema()
        assert {"summary", "paper", "constraint", "output_ndim"} <= set(item)


def test_methods_text(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["methods"], capsys)
    assert code == 0
    for name, spec in available_methods().items():
        assert f"{name}: {spec.summary}" in out
        for param in spec.schema().get("properties", {}):
            assert f"    {param} (" in out


def test_methods_with_an_empty_registry(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(methods_cli, "available_methods", dict)
    assert run_cli(["methods", "--json"], capsys)[:2] == (0, "[]\n")
    code, out, _ = run_cli(["methods"], capsys)
    assert code == 0 and "no synthesis methods" in out
