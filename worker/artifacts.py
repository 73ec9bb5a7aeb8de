"""Write every artifact of a finished run into one staging folder (committed atomically by the store).

Artifacts of a 2-D run: ``output.png`` (8-bit), ``output.tiff`` (16-bit), ``coherence.png`` and
``orientation.png`` of the synthesized structure tensor field (and of the constraint, when there is
one), ``metrics.json`` (the engine's evaluation of exemplar vs output), ``plots/*.png`` (comparison
plots) and ``manifest.json`` (method, parameters, seed, versions, timings). A volume gives
``output.tiff`` as a stack and ``output.png`` as its middle slice.
"""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path
from typing import Any

import numpy as np

from synth import __version__ as synth_version
from synth.api import Result
from synth.io import save_image, save_volume
from synth.render import coherence_image, orientation_image
from synth.tensor import coherence, structure_direction, structure_tensor
from worker.imaging import png_bytes
from worker.store import atomic_write_bytes

__all__ = ["versions", "write_artifacts"]


def versions() -> dict[str, str]:
    import numba
    import scipy

    return {
        "texsynth": synth_version,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
    }


def _write_tensor_images(folder: Path, prefix: str, tensors: np.ndarray) -> list[str]:
    names = [f"{prefix}coherence.png", f"{prefix}orientation.png"]
    coh = coherence(tensors)
    atomic_write_bytes(folder / names[0], png_bytes(coherence_image(coh, legend=True)))
    atomic_write_bytes(
        folder / names[1],
        png_bytes(orientation_image(structure_direction(tensors), coherence=coh, legend=True)),
    )
    return names


def _render_extra(arr: np.ndarray) -> np.ndarray | None:
    """A viewable image of an extra map: grey/RGB rescaled to [0, 1]; a 2-channel map (e.g. the
    source coordinates of each pixel) as red = first, green = second channel. ``None`` if neither."""
    if not np.isfinite(arr).all() or arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (2, 3)):
        return None
    if arr.ndim == 3 and arr.shape[2] == 2:
        arr = np.concatenate([arr, np.zeros_like(arr[..., :1])], axis=2)
    lo, hi = arr.min(axis=(0, 1)), arr.max(axis=(0, 1))
    return np.where(hi > lo, (arr - lo) / np.where(hi > lo, hi - lo, 1), 0).astype(np.float32)


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist() if value.size <= 4096 else f"<array {value.shape}>"
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def write_artifacts(
    folder: Path,
    result: Result,
    exemplar: np.ndarray,
    constraint: np.ndarray | None,
    manifest: dict[str, Any],
) -> tuple[list[str], dict[str, Any]]:
    """Write all artifacts of ``result`` into ``folder``; return their names and the metrics."""
    folder.mkdir(parents=True, exist_ok=True)
    image = np.asarray(result.image, dtype=np.float32)
    volume = image.ndim == 3 and image.shape[-1] != 3
    names = ["output.png", "output.tiff"]
    atomic_write_bytes(folder / "output.png", png_bytes(image[image.shape[0] // 2] if volume else image))
    if volume:
        save_volume(folder / "output.tiff", image, bit_depth=16)
    else:
        save_image(folder / "output.tiff", image, bit_depth=16)

    if not volume:
        tensors = result.tensor_field if result.tensor_field is not None else structure_tensor(image)
        names += _write_tensor_images(folder, "", np.asarray(tensors))
    if constraint is not None:
        names += _write_tensor_images(
            folder, "constraint_", structure_tensor(np.asarray(constraint, np.float32))
        )
    for key, extra in sorted(result.extras.items()):
        rendered = _render_extra(np.asarray(extra, dtype=np.float32))
        if rendered is not None:
            atomic_write_bytes(folder / f"{key}.png", png_bytes(rendered))
            names.append(f"{key}.png")

    metrics: dict[str, Any] = {}
    try:
        from synth.evaluate import evaluate_pair
    except ModuleNotFoundError as exc:  # evaluation not in this engine build yet
        if exc.name != "synth.evaluate":
            raise
    else:
        metrics = _jsonable(evaluate_pair(exemplar, image))
    metrics_doc = {"metrics": metrics, "stats": _jsonable(result.stats), "timings": _jsonable(result.timings)}
    atomic_write_bytes(folder / "metrics.json", json.dumps(metrics_doc, indent=2).encode())
    names.append("metrics.json")

    try:
        from synth.plots import write_plots
    except ModuleNotFoundError as exc:
        if exc.name != "synth.plots":
            raise
    else:
        plots = folder / "plots"
        plots.mkdir(exist_ok=True)
        write_plots(exemplar, image, metrics, plots)
        names += sorted(f"plots/{p.name}" for p in plots.glob("*.png"))

    manifest = {
        **manifest,
        "params": _jsonable(result.params),
        "seed": result.seed,
        "output_shape": list(image.shape),
        "timings": _jsonable(result.timings),
        "versions": versions(),
        "argv": sys.argv[:1],
    }
    atomic_write_bytes(folder / "manifest.json", json.dumps(manifest, indent=2).encode())
    names.append("manifest.json")
    return names, metrics
