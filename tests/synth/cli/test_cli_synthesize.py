"""``texsynth synthesize``: files written, options honoured, bad input as one line and exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image

from texsynth.synth.cli import main
from texsynth.synth.cli.synthesize import parse_size
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.params import parse_assignments

FAST = ["--set", "neighbourhood_size=5", "--set", "parent_size=3", "--no-plots"]


def test_parse_size_and_assignments() -> None:
    assert parse_size("96x64") == (64, 96)
    assert parse_size("32x16x8") == (8, 16, 32)
    assert parse_assignments(["levels=3", "metric=ED", "p=0.25"]) == {"levels": 3, "metric": "ED", "p": 0.25}
    with pytest.raises(InvalidParameter, match="WxH"):
        parse_size("big")
    with pytest.raises(InvalidParameter, match="name=value"):
        parse_assignments(["levels"])


def test_tensor_method_writes_every_artifact(exemplar: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [
        "synthesize",
        "tensor-constrained",
        "--exemplar",
        str(exemplar),
        "--size",
        "48x32",
        "--seed",
        "4",
        "--set",
        "structure_levels=2",
        *FAST,
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    for name in (
        "output.png",
        "output.tiff",
        "manifest.json",
        "metrics.json",
        "coherence.png",
        "orientation.png",
    ):
        assert (out / name).is_file(), name
    assert np.asarray(Image.open(out / "output.png")).shape == (32, 48)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["method"] == "tensor-constrained" and manifest["seed"] == 4
    assert manifest["params"]["structure_levels"] == 2 and manifest["params"]["metric"] == "LE"
    assert {"texsynth", "numpy", "numba"} <= set(manifest["versions"])
    assert "total" in manifest["timings"]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["metrics"]["grey"]["kl"] >= 0.0
    assert tifffile.imread(out / "output.tiff").dtype == np.uint16


def test_sixteen_bit_output_and_same_seed_same_bytes(exemplar: Path, tmp_path: Path) -> None:
    runs = []
    for name in ("a", "b"):
        out = tmp_path / name
        assert (
            main(
                [
                    "synthesize",
                    "wei-levoy",
                    "--exemplar",
                    str(exemplar),
                    "--size",
                    "32x32",
                    "--bit-depth",
                    "16",
                    "--set",
                    "levels=2",
                    *FAST,
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
        runs.append((out / "output.png").read_bytes())
        assert np.asarray(Image.open(out / "output.png")).dtype == np.uint16
    assert runs[0] == runs[1]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--set", "levels=9"], "parameter 'levels'"),
        (["--set", "colour=red"], "unknown parameter"),
        (["--size", "0x10"], "WxH"),
        (["--bit-depth", "12"], "bit-depth"),
    ],
)
def test_bad_options_exit_2_with_one_line(
    exemplar: Path, tmp_path: Path, capsys: pytest.CaptureFixture, extra: list[str], message: str
) -> None:
    code = main(
        ["synthesize", "wei-levoy", "--exemplar", str(exemplar), *extra, "--out", str(tmp_path / "x")]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_unknown_method_and_missing_exemplar(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["synthesize", "nope", "--exemplar", "x.png", "--out", str(tmp_path)]) == 2
    assert "unknown method" in capsys.readouterr().err
    assert (
        main(["synthesize", "wei-levoy", "--exemplar", str(tmp_path / "none.png"), "--out", str(tmp_path)])
        == 2
    )
    assert "none.png: no such file" in capsys.readouterr().err


def test_same_bytes_whatever_the_number_of_threads(exemplar: Path, tmp_path: Path) -> None:
    """BLAS (the k-coherence PCA) and numba thread counts must not change a single byte."""
    import os
    import subprocess
    import sys

    outputs = []
    for threads in ("1", "2"):
        env = dict(
            os.environ, OPENBLAS_NUM_THREADS=threads, OMP_NUM_THREADS=threads, NUMBA_NUM_THREADS=threads
        )
        out = tmp_path / f"t{threads}"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "texsynth.synth.cli",
                "synthesize",
                "tensor-constrained",
                "--exemplar",
                str(exemplar),
                "--size",
                "40x40",
                "--seed",
                "2",
                "--set",
                "structure_levels=2",
                *FAST,
                "--out",
                str(out),
            ],
            env=env,
            check=True,
            capture_output=True,
        )
        outputs.append((out / "output.png").read_bytes())
    assert outputs[0] == outputs[1]
