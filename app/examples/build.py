"""Make the bundled examples' PNGs again from their sources: ``python -m texsynth.app.examples.build
[--check]``.

Sources: the soot crop of ``benchmarks/data`` (MIT; kept in the repository, not in the wheel), the
scikit-image wheel's brick, grass and gravel (CC0), and texsynth's own generators with fixed seeds.
``--check`` compares with the files in the folder instead of writing them (exit 1 when one differs).
"""

from __future__ import annotations

import argparse
import io
import sys

import numpy as np
from PIL import Image

from texsynth.app.examples import EXAMPLES, FOLDER, _as_uint8

SIDE = 128
_REPO = FOLDER.parent.parent


def _skimage(name: str) -> np.ndarray:
    """The top-left 256 px of scikit-image's 512 px texture, halved to 128 px (area average)."""
    import skimage.data

    crop = getattr(skimage.data, name)()[:256, :256].astype(np.float64)
    return crop.reshape(SIDE, 2, SIDE, 2).mean(axis=(1, 3)) / 255.0


def images() -> dict[str, np.ndarray]:
    """Every example as float grey in [0, 1], by name."""
    from texsynth.synth.io import load_image
    from texsynth.synth.io.laminar import turbostratic_volume
    from texsynth.synth.io.patterns import waves

    soot = load_image(_REPO / "benchmarks" / "data" / "hrtem-onion-128.png")
    laminar = turbostratic_volume((16, SIDE, SIDE), period=6.0, seed=27)[8]
    out = {
        "soot-fringes": soot,
        "brick": _skimage("brick"),
        "grass": _skimage("grass"),
        "gravel": _skimage("gravel"),
        "laminar": laminar,
        "constraint-waves": waves((SIDE, SIDE), period=8.0, amplitude=10.0, wavelength=64.0),
    }
    assert set(out) == set(EXAMPLES), "every example has a source"
    return out


def png_bytes(image: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(_as_uint8(image)).save(buf, "PNG", optimize=True)
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    args = parser.parse_args(argv)
    differ = []
    for name, image in images().items():
        data, path = png_bytes(image), FOLDER / f"{name}.png"
        if args.check:
            if not path.is_file() or np.asarray(Image.open(path)).tobytes() != _as_uint8(image).tobytes():
                differ.append(name)
        else:
            path.write_bytes(data)
            print(f"{path.name}: {image.shape[1]}x{image.shape[0]}")
    if differ:
        print(f"differ from their sources: {', '.join(differ)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
