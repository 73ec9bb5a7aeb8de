"""A synthesized volume against a known answer: its slices against the truth volume's own slices.

When the exemplars are slices of a known volume (:mod:`texsynth.synth.io.laminar`), the targets of a solid
synthesis are not the exemplar's statistics but those of the truth's slices along each axis: an oblique
cut shows wider fringes than the exemplar, a slice near an onion's pole wider rings, and a volume
consistent with the exemplar has exactly the truth's slice statistics. This compares, per axis, the
slices of ``volume`` with the slices of the truth **at the same slice size** (the truth is cut into
non-overlapping blocks of the volume's shape, all of whose slices are pooled), so that the fringe
lengths of small slices are not compared with those of large ones. The measures are those of
:func:`texsynth.synth.evaluate.evaluate_volume` (the study's multi-2D benchmark: grey KL, energy-weighted
orientation KL, coherence, fringe length and tortuosity by Kolmogorov-Smirnov); each axis's summary adds
``coherence_ratio`` (mean structure-tensor coherence of the volume's slices over the truth's) and
``contrast`` (standard deviation over the truth's), the quickest checks that sheets formed rather than
blobs (ALGORITHMS.md, section 8).

Reference: R. D. Urs, J.-P. Da Costa, J.-M. Leyssale, G. Vignoles, C. Germain, "Non-parametric
synthesis of laminar volumetric textures from a 2D sample", BMVC 2012, section 3.2.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.evaluate.measures import (
    PLANES,
    ImageStats,
    MeasureSettings,
    check_values,
    compare_stats,
    image_stats,
    moments,
    to_json_types,
)

__all__ = ["TruthSlices", "evaluate_against_truth", "truth_slices"]


@dataclass(frozen=True)
class TruthSlices:
    """The truth's pooled slice statistics per axis, at one slice size (reused across many volumes)."""

    block: tuple[int, int, int]
    axes: tuple[int, ...]
    settings: MeasureSettings
    stats: dict[int, ImageStats]
    moments: dict[str, Any]
    blocks: int


def _volume(array: np.ndarray, name: str) -> np.ndarray:
    vol = np.asarray(array)
    if vol.ndim != 3 or min(vol.shape) < 8:
        raise InvalidInput(
            name, f"expected a grey (D, H, W) volume with every side >= 8, got shape {vol.shape}"
        )
    vol = vol.astype(np.float64, copy=False)
    check_values(vol, name)
    return vol


def _axes(axes: Iterable[int]) -> tuple[int, ...]:
    out = tuple(int(a) for a in axes)
    if not out or any(a not in (0, 1, 2) for a in out) or len(set(out)) != len(out):
        raise InvalidParameter("axes", out, "must be distinct values among 0, 1, 2")
    return out


def truth_slices(
    truth: np.ndarray,
    block: tuple[int, int, int],
    *,
    axes: Iterable[int] = (0, 1, 2),
    fringes: bool = True,
    slice_step: int = 1,
    fringe_options: Mapping[str, Any] | None = None,
) -> TruthSlices:
    """The statistics of every slice of every ``block``-shaped sub-volume of ``truth``, pooled per axis.

    Parameters
    ----------
    truth : ndarray, shape (D, H, W)
        The known volume, grey in [0, 1]; every side at least the block's.
    block : (d, h, w)
        The shape of the volumes it will be compared with; the truth is cut into
        ``(D // d) * (H // h) * (W // w)`` non-overlapping blocks from its corner.
    axes, fringes, fringe_options
        As :func:`texsynth.synth.evaluate.evaluate_volume`.
    slice_step : int
        Take every ``slice_step``-th slice of each block (1: all).
    """
    vol = _volume(truth, "truth")
    shape = tuple(int(b) for b in block)
    if len(shape) != 3 or any(not 8 <= b <= n for b, n in zip(shape, vol.shape, strict=False)):
        raise InvalidParameter(
            "block", block, f"must be (d, h, w), each side in [8, the truth's {vol.shape}]"
        )
    if not (isinstance(slice_step, int | np.integer) and slice_step >= 1):
        raise InvalidParameter("slice_step", slice_step, "must be a positive integer")
    axes = _axes(axes)
    settings = MeasureSettings(fringes=fringes, fringe_options=dict(fringe_options or {}))
    counts = [n // b for n, b in zip(vol.shape, shape, strict=True)]
    cubes = [
        vol[
            i * shape[0] : (i + 1) * shape[0],
            j * shape[1] : (j + 1) * shape[1],
            k * shape[2] : (k + 1) * shape[2],
        ]
        for i, j, k in np.ndindex(*counts)
    ]
    stats = {
        axis: ImageStats.pool(
            image_stats(s, settings) for cube in cubes for s in np.moveaxis(cube, axis, 0)[::slice_step]
        )
        for axis in axes
    }
    used = np.concatenate([c.ravel() for c in cubes])
    return TruthSlices(shape, axes, settings, stats, moments(used), len(cubes))  # type: ignore[arg-type]


def evaluate_against_truth(reference: TruthSlices | np.ndarray, volume: np.ndarray) -> dict[str, Any]:
    """Per axis, the slices of ``volume`` against the truth's slices of the same size.

    Parameters
    ----------
    reference : TruthSlices or ndarray (D, H, W)
        :func:`truth_slices` of the truth at the volume's shape, or the truth itself (then cut here).
    volume : ndarray, shape (d, h, w)
        The synthesized volume, grey in [0, 1].

    Returns
    -------
    dict
        JSON-serialisable: ``{"kind": "truth", "blocks": n, "axes": {"0": {<evaluate_pair blocks>,
        "plane": "xy"}, ...}, "summary": {"per_axis": {"0": {"grey_kl", "orientation_kl",
        "fringe_ks_length", "fringe_ks_tortuosity", "coherence_ratio", "contrast", ...}, ...}}}``.
    """
    vol = _volume(volume, "volume")
    ref = reference if isinstance(reference, TruthSlices) else truth_slices(reference, vol.shape)
    if tuple(vol.shape) != ref.block:
        raise InvalidInput("volume", f"shape {vol.shape} differs from the truth's blocks {ref.block}")
    out_moments = moments(vol)
    per_axis: dict[str, Any] = {}
    for axis in ref.axes:
        pooled = ImageStats.pool(image_stats(s, ref.settings) for s in np.moveaxis(vol, axis, 0))
        block = compare_stats(ref.stats[axis], pooled, ref.moments, out_moments, ref.settings)
        coh = block["structure"]["coherence_mean"]
        block["summary"]["coherence_ratio"] = coh["output"] / coh["exemplar"] if coh["exemplar"] else None
        std = block["moments"]
        block["summary"]["contrast"] = (
            std["output"]["std"] / std["exemplar"]["std"] if std["exemplar"]["std"] else None
        )
        block["plane"] = PLANES[axis]
        per_axis[str(axis)] = block
    result = {
        "kind": "truth",
        "blocks": ref.blocks,
        "shape": {"truth_block": list(ref.block), "volume": list(vol.shape)},
        "axes": per_axis,
        "summary": {"per_axis": {k: v["summary"] for k, v in per_axis.items()}},
    }
    return to_json_types(result)
