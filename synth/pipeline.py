"""Load inputs -> synthesize -> write every artifact: the one sequence behind ``texsynth synthesize``
and the service's worker, so that a job and a command line give the same files for the same inputs.

Inputs come by role (:data:`INPUT_ROLES`): ``exemplar``, or the three per-plane exemplars of a solid
method, and ``constraint``. A role given as bytes is named by its role in error messages (an upload:
no server path); a role given as a path by the path (a command line: the user's own file).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from texsynth.synth.api import PLANES, Progress, Result, find_method, synthesize
from texsynth.synth.errors import InvalidInput
from texsynth.synth.io import ImageSource, InputBits, load_image_bits, sample_bits
from texsynth.synth.threads import current_threads, use_threads

__all__ = ["INPUT_ROLES", "Inputs", "Outcome", "load_inputs", "synthesize_to_folder"]

#: Every input image a method may declare (``MethodSpec.inputs``).
INPUT_ROLES: tuple[str, ...] = ("exemplar", *(f"exemplar_{plane}" for plane in PLANES), "constraint")


class Inputs(dict[str, np.ndarray]):
    """Decoded input images by role, and (``bits``) the bit depth each file had (:class:`InputBits`),
    which :func:`synthesize_to_folder` keeps for the outputs."""

    def __init__(self, images: Mapping[str, np.ndarray], bits: Mapping[str, InputBits]) -> None:
        super().__init__(images)
        self.bits = dict(bits)


@dataclass(frozen=True)
class Outcome:
    """What :func:`synthesize_to_folder` made: the result, the files written, the metrics."""

    result: Result
    files: list[str]
    metrics: dict[str, Any]


def load_inputs(sources: Mapping[str, ImageSource], *, max_pixels: int | None = None) -> Inputs:
    """Decode every input image (float32 in [0, 1]), checking each before any work starts.

    Per-plane exemplars must share one bit depth (an 8-bit and a 16-bit micrograph of one material
    rarely share a grey scale).

    Raises :class:`~texsynth.synth.errors.InvalidInput` (or its 413/415 kinds) naming the role or the file.
    """
    unknown = sorted(set(sources) - set(INPUT_ROLES))
    if unknown:
        raise InvalidInput(unknown[0], f"not an input of any method (inputs: {', '.join(INPUT_ROLES)})")
    images, bits, depths = {}, {}, {}
    for role, source in sources.items():
        name = role if isinstance(source, bytes | bytearray | memoryview) else None
        images[role], depths[role] = load_image_bits(source, name=name, max_pixels=max_pixels)
        if role.startswith("exemplar_"):
            bits[role] = sample_bits(source, name=name)
    if len(set(bits.values())) > 1:
        depths = ", ".join(f"{role} {depth}-bit" for role, depth in bits.items())
        first = next(iter(bits))
        raise InvalidInput(
            first, f"per-plane exemplars must share one bit depth, so their grey levels compare ({depths})"
        )
    return Inputs(images, depths)


def synthesize_to_folder(
    method: str,
    images: Mapping[str, np.ndarray],
    folder: str | os.PathLike[str],
    *,
    size: tuple[int, ...] | None = None,
    params: dict[str, Any] | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    manifest: dict[str, Any] | None = None,
    bit_depth: int | None = None,
    plots: bool = True,
    voxel_size: float | None = None,
    max_output: int | None = None,
    threads: int | None = None,
    voxel_unit: str = "nm",
) -> Outcome:
    """Run ``method`` on decoded ``images`` (by role) and write all artifacts into ``folder``.

    See :func:`texsynth.synth.api.synthesize` for the arguments (``max_output`` too) and
    :func:`texsynth.synth.output.artifacts.write_artifacts` for the files; ``manifest.json`` also records when
    the synthesis started and finished (Unix time). ``threads``: numba threads of the synthesis and the
    evaluation (:mod:`texsynth.synth.threads`; default every core). A volume is evaluated plane by plane
    against its per-plane exemplars when given; ``voxel_size`` (in ``voxel_unit``, nm by default) calibrates
    its TIFF stack (ImageJ spacing and unit) and, in nm, its fringe lengths.
    The exemplar's bit depth (from :func:`load_inputs`' ``bits``, else that of the arrays given) is kept
    for the outputs and said in ``metrics.json`` (``input_bits``).
    """
    with use_threads(threads):
        return _synthesize_to_folder(
            method,
            images,
            folder,
            size,
            params,
            seed,
            progress,
            manifest,
            bit_depth,
            plots,
            voxel_size,
            max_output,
            voxel_unit,
        )


def _synthesize_to_folder(
    method: str,
    images: Mapping[str, np.ndarray],
    folder: str | os.PathLike[str],
    size: tuple[int, ...] | None,
    params: dict[str, Any] | None,
    seed: int,
    progress: Progress | None,
    manifest: dict[str, Any] | None,
    bit_depth: int,
    plots: bool,
    voxel_size: float | None,
    max_output: int | None,
    voxel_unit: str = "nm",
) -> Outcome:
    from texsynth.synth.output.artifacts import (  # deferred: evaluation and plots only when writing
        ExemplarAhead,
        write_artifacts,
    )

    planes = {plane: images[f"exemplar_{plane}"] for plane in PLANES if f"exemplar_{plane}" in images}
    spec = find_method(method)
    ahead = None  # a 2-D run's exemplar analysis and pictures, made while it is synthesized
    report = progress
    if spec is not None and spec.output_ndim == 2 and "exemplar" in images and current_threads() > 1:
        ahead = ExemplarAhead(images["exemplar"], images.get("constraint"))

        def report(stage: str, fraction: float) -> None:  # started once the passes have begun
            ahead.start()
            if progress is not None:
                progress(stage, fraction)

    started = time.time()
    result = synthesize(
        method,
        images.get("exemplar"),
        size=size,
        params=params,
        seed=seed,
        progress=report,
        constraint=images.get("constraint"),
        exemplars=planes or None,
        max_output=max_output,
    )
    manifest = {**(manifest or {}), "started": started, "finished": time.time()}
    if progress is not None:
        progress("writing artifacts", 1.0)
    exemplar = images["exemplar"] if "exemplar" in images else planes["xy"]
    file_bits = images.bits if isinstance(images, Inputs) else {}
    input_bits = file_bits.get("exemplar", file_bits.get("exemplar_xy", result.input_bits))
    files, metrics = write_artifacts(
        Path(folder),
        result,
        exemplar,
        images.get("constraint"),
        manifest,
        bit_depth=bit_depth,
        input_bits=input_bits,
        plots=plots,
        exemplars=planes or None,
        voxel_size=voxel_size,
        unit=voxel_unit,
        progress=progress,
        ahead=ahead,
    )
    return Outcome(result, files, metrics)
