"""Fingerprints of every method's output: same code, same bytes; a refactor that moves code proves it moved
nothing by comparing these before and after.

    python -m benchmarks.output_hashes --record before.json   # on the old tree
    python -m benchmarks.output_hashes --check before.json    # on the new tree: exit 1 and name what moved

Each method runs with its default parameters and a fixed seed on a small input (the real HRTEM soot
crop when ``../shared/data`` is there, else a generated laminae pattern), through
:func:`texsynth.synth.api.synthesize` only, so the script does not depend on where the machinery lives. The
hashes are of the float32 output bytes and of the tensor field when the method returns one. They are
machine-specific (BLAS and the CPU's vector width may move the last bit), so compare hashes taken on
the same machine.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from texsynth.synth.api import available_methods, synthesize

# Small but real: each case runs in seconds with the method's default parameters.
_SIZE_2D = (96, 96)
_SIZE_3D = (32, 32, 32)


def _exemplar() -> np.ndarray:
    from benchmarks._report import DATA

    path = DATA / "hrtem-soot-128.png"
    if path.is_file():
        from texsynth.synth.io import load_image

        return load_image(path)[:64, :64].copy()
    from texsynth.synth.io.patterns import undulating_laminae

    return undulating_laminae((64, 64))


def _constraint() -> np.ndarray:
    yy, xx = np.mgrid[0 : _SIZE_2D[0], 0 : _SIZE_2D[1]].astype(np.float32)
    return (0.5 + 0.5 * np.sin(2 * np.pi * (xx + 6 * np.sin(2 * np.pi * yy / 48)) / 12)).astype(np.float32)


def _digest(array: np.ndarray | None) -> str | None:
    if array is None:
        return None
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def fingerprints() -> dict[str, dict[str, str | None]]:
    """``{method: {'image': sha256, 'tensor_field': sha256 | None}}`` for every registered method."""
    exemplar = _exemplar()
    out: dict[str, dict[str, str | None]] = {}
    for name, spec in sorted(available_methods().items()):
        size = _SIZE_3D if spec.output_ndim == 3 else _SIZE_2D
        constraint = _constraint() if spec.constraint == "required" else None
        result = synthesize(name, exemplar, size=size, seed=7, constraint=constraint)
        out[name] = {"image": _digest(result.image), "tensor_field": _digest(result.tensor_field)}
        print(f"{name}: {out[name]['image']}", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--record", type=Path, help="write the fingerprints to this JSON file")
    group.add_argument("--check", type=Path, help="compare with fingerprints recorded earlier")
    args = parser.parse_args(argv)
    now = fingerprints()
    if args.record:
        args.record.write_text(json.dumps(now, indent=2, sort_keys=True) + "\n")
        return 0
    before = json.loads(args.check.read_text())
    moved = [name for name in before if name in now and before[name] != now[name]]
    for name in moved:
        print(f"MOVED: {name}: {before[name]} -> {now[name]}")
    missing = sorted(set(before) - set(now))
    for name in missing:
        print(f"MISSING: {name}")
    print(f"{len(before) - len(moved) - len(missing)} of {len(before)} methods give identical bytes")
    return 1 if moved or missing else 0


if __name__ == "__main__":
    sys.exit(main())
