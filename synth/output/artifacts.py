"""Every artifact of a synthesis, written into one folder: what the CLI and the service's worker keep.

A 2-D run gives ``output.png`` (8-bit, or 16-bit on request), ``output.tiff`` (16-bit),
``coherence.png`` and ``orientation.png`` of the synthesized structure tensor field (of the output
when the method has none; ``constraint_*`` of the constraint when there is one), renderings of the
method's extra maps, ``metrics.json`` (:func:`texsynth.synth.evaluate.evaluate_pair`: exemplar vs output),
``plots/*.png`` (:func:`texsynth.synth.output.plots.write_plots`) and ``manifest.json`` (method, full
parameters, seed, versions, timings). A volume gives ``output.tiff`` as a multi-page stack (16-bit, with the
ImageJ voxel size when one is given) and ``output.png`` as its middle ``xy`` slice; ``slices.png`` (the three
orthogonal mid-slices beside their exemplars), ``cube.png`` (the block and its cut-away corner), the
mid-slices' ``coherence_{xy,xz,yz}.png`` and ``orientation_{xy,xz,yz}.png``
(:mod:`texsynth.synth.output.volume`); its metrics are the multi-2D ones with per-plane exemplars and
two-point correlations (:func:`texsynth.synth.evaluate.evaluate_volume`), its plots per plane plus
``plots/s2.png``. The metrics also carry the exemplars' diagnostics under ``exemplar`` (their
stationarity and any warning, :func:`texsynth.synth.analysis.stationarity.exemplar_diagnostics`), which the
manifest repeats in short (``exemplar_stationarity``); ``headline``, each headline measure with its
target, direction and verdict (:func:`texsynth.synth.evaluate.glossary.headline`); and ``fringes.shown``:
fringe statistics only for an exemplar with lattice fringes
(:func:`texsynth.synth.evaluate.glossary.fringes_shown`), else ``{"shown": false, "reason"}``. Every run also
gets ``exemplar-coherence.png`` and
``exemplar-orientation.png``, the exemplar's own tensor images (the ``xy`` one's for per-plane
exemplars). Every file is written atomically; with two threads or more the pictures (and the charts'
encodings) are written on a second thread while the first evaluates and draws the plots, then helps with
what is left, and a 2-D run's exemplar work may be made during its synthesis (:class:`ExemplarAhead`):
the same files and bytes.
"""

from __future__ import annotations

import io
import platform
import threading
from collections.abc import Callable, Mapping
from contextlib import suppress
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from texsynth.synth import __version__
from texsynth.synth.analysis.stationarity import exemplar_diagnostics
from texsynth.synth.analysis.tensor import coherence, structure_direction, structure_tensor
from texsynth.synth.api import Result
from texsynth.synth.evaluate.glossary import fringes_shown, headline
from texsynth.synth.evaluate.measures import (
    as_grey,
    evaluate_pair_fringes,
    evaluate_volume,
    exemplar_side,
    to_json_types,
)
from texsynth.synth.io import (
    PICTURE_PNG_LEVEL,
    InputBits,
    array_to_unit,
    atomic_write_bytes,
    atomic_write_json,
    image_to_png_bytes,
    save_image,
    save_volume,
)
from texsynth.synth.output.plots import write_plots, write_s2_plot
from texsynth.synth.output.render import coherence_image, orientation_image
from texsynth.synth.output.volume import write_volume_images
from texsynth.synth.threads import current_threads, use_threads

__all__ = ["ExemplarAhead", "versions", "write_artifacts"]


def versions() -> dict[str, str]:
    """Versions of texsynth and of the libraries that decide its results."""
    import numba
    import scipy
    import skimage

    return {
        "texsynth": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "scikit-image": skimage.__version__,
        "numba": numba.__version__,
    }


class _Pictures:
    """The pictures' tasks (each writes its files and returns their names), taken in order one at a time by
    a second thread (:meth:`start`) and, once it is done with its own work, by the caller (:meth:`finish`):
    whichever branch ends first takes what is left. Tasks may be added while they run (:meth:`add`: the
    plots' encodings); the second thread waits for more until :meth:`finish`. The names come back in the
    tasks' order."""

    def __init__(self, tasks: list[Callable[[], list[str]]]) -> None:
        self.tasks = tasks
        self.done: list[list[str]] = [[] for _ in tasks]
        self.failed: list[BaseException] = []
        self.next = 0  # the next task to take
        self.closed = False  # no more tasks will be added
        self.cond = threading.Condition()
        self.thread: threading.Thread | None = None

    def add(self, task: Callable[[], object]) -> None:
        """Queue ``task`` (whatever it returns, it names no file here)."""

        def run() -> list[str]:
            task()
            return []

        with self.cond:
            self.tasks.append(run)
            self.done.append([])
            self.cond.notify()

    def _take(self, wait: bool) -> int | None:
        with self.cond:
            while not self.failed and self.next >= len(self.tasks) and wait and not self.closed:
                self.cond.wait()
            if self.failed or self.next >= len(self.tasks):
                return None
            self.next += 1
            return self.next - 1

    def _work(self, wait: bool = False) -> None:
        while (k := self._take(wait)) is not None:
            try:
                self.done[k] = self.tasks[k]()
            except BaseException as err:  # raised again in the calling thread
                with self.cond:
                    self.failed.append(err)
                    self.cond.notify_all()

    def start(self) -> None:
        self.thread = threading.Thread(target=self._work, args=(True,), name="texsynth-pictures")
        self.thread.start()

    def finish(self, help_out: bool = True) -> list[str]:
        """Take the tasks left (unless ``help_out`` is false: the caller failed), wait for the second thread
        (which ends the tasks queued), raise the first task's error or return every name in order."""
        with self.cond:
            self.closed = True
            self.cond.notify_all()
        if help_out:
            self._work()
        if self.thread is not None:
            self.thread.join()
        if self.failed:
            raise self.failed[0]
        return [name for names in self.done for name in names]


def _png_bytes(rendering: np.ndarray) -> bytes:
    if rendering.dtype == np.uint8:  # already quantised: encoded as it is, with the pictures' zlib effort
        buf = io.BytesIO()
        Image.fromarray(rendering).save(buf, format="PNG", compress_level=PICTURE_PNG_LEVEL)
        return buf.getvalue()
    return image_to_png_bytes(rendering)


def _tensor_pngs(tensors: np.ndarray) -> list[bytes]:
    """The PNG files of a tensor field's coherence and orientation images."""
    coh = coherence(tensors)
    return [
        _png_bytes(coherence_image(coh, legend=True)),
        _png_bytes(orientation_image(structure_direction(tensors), coherence=coh, legend=True)),
    ]


def _tensor_names(prefix: str) -> list[str]:
    return [f"{prefix}coherence.png", f"{prefix}orientation.png"]


def _write_pngs(folder: Path, prefix: str, pngs: list[bytes]) -> list[str]:
    """Write a tensor field's encoded images (:func:`_tensor_pngs`) under their names; return the names."""
    names = _tensor_names(prefix)
    for name, data in zip(names, pngs, strict=True):
        atomic_write_bytes(folder / name, data)
    return names


def _write_tensor_images(folder: Path, prefix: str, tensors: np.ndarray) -> list[str]:
    return _write_pngs(folder, prefix, _tensor_pngs(tensors))


class ExemplarAhead:
    """What the artifacts of a 2-D run need of its exemplar (and constraint) alone, made on a thread of its
    own while the output is synthesized (:func:`texsynth.synth.pipeline.synthesize_to_folder` starts it at the
    synthesis' first progress report: after its first kernel calls, which hold Python's lock), for
    :func:`write_artifacts`' ``ahead``: whether fringes are shown, the exemplar's diagnostics, its half of
    the evaluation (:func:`texsynth.synth.evaluate.measures.exemplar_side`, the evaluation kernels' first
    calls with it) and its tensor images (and the constraint's), encoded. Nothing is written until
    :func:`write_artifacts` writes it; the values are those it would compute (one thread: numba's
    kernels give the same bytes on any number)."""

    def __init__(self, exemplar: np.ndarray, constraint: np.ndarray | None = None) -> None:
        self.source, self.constraint = exemplar, constraint
        self.values: dict[str, Any] = {}
        self.thread = threading.Thread(target=self._work, name="texsynth-exemplar", daemon=True)
        self.lock = threading.Lock()

    def start(self) -> None:
        """Start making the values (once, from whichever thread first asks; :meth:`result` without a start
        gives none)."""
        with self.lock:
            if self.thread.ident is None:
                self.thread.start()

    def _work(self) -> None:
        try:
            with use_threads(1):
                ex = _unit(self.source, "exemplar")
                shown = fringes_shown(ex)
                self.values["exemplar"] = ex
                self.values["fringes_shown"] = shown
                self.values["side"] = exemplar_side(ex, fringes=shown[0])
                self.values["diagnostics"] = exemplar_diagnostics({"exemplar": ex})
                self.values["exemplar-"] = _tensor_pngs(structure_tensor(as_grey(ex, "exemplar")))
                if self.constraint is not None:
                    tensors = structure_tensor(np.asarray(self.constraint, np.float32))
                    self.values["constraint_"] = _tensor_pngs(tensors)
        except BaseException:  # what is missing the writer computes itself (and meets the error there)
            return

    def result(self, exemplar: np.ndarray, constraint: np.ndarray | None) -> dict[str, Any]:
        """The values made, once made, if made from ``exemplar`` and ``constraint`` (these objects)."""
        with self.lock:
            if self.thread.ident is None:
                return {}
        self.thread.join()
        if exemplar is not self.source or constraint is not self.constraint:
            return {}
        return self.values


#: Extra maps rendered on a fixed scale ``(black, white)`` instead of their own min-max, so that maps of
#: different runs compare: ``copy_map`` is the RMS distance to the nearest exemplar patch
#: (:func:`texsynth.synth.evaluate.copy_map`): black = verbatim copy, white = 0.05 or more away. The RGB
# overlays
#: of ``feature-guided`` (feature maps, seams) are already pictures in [0, 1].
FIXED_RANGES: dict[str, tuple[float, float]] = {
    "copy_map": (0.0, 0.05),
    **dict.fromkeys(("features_exemplar", "features_output", "seams"), (0.0, 1.0)),
}


def _render_extra(arr: np.ndarray, value_range: tuple[float, float] | None = None) -> np.ndarray | None:
    """A viewable image of an extra map: grey/RGB rescaled to [0, 1] (from ``value_range`` when given,
    else its own min-max); a 2-channel map (e.g. the source coordinates of each pixel) as red = first,
    green = second channel; ``None`` otherwise."""
    if not np.isfinite(arr).all() or arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (2, 3)):
        return None
    if value_range is not None:
        lo_v, hi_v = value_range
        return np.clip((arr - lo_v) / (hi_v - lo_v), 0.0, 1.0).astype(np.float32)
    if arr.ndim == 3 and arr.shape[2] == 2:
        arr = np.concatenate([arr, np.zeros_like(arr[..., :1])], axis=2)
    lo, hi = arr.min(axis=(0, 1)), arr.max(axis=(0, 1))
    return np.where(hi > lo, (arr - lo) / np.where(hi > lo, hi - lo, 1), 0).astype(np.float32)


def _unit(image: np.ndarray, name: str) -> np.ndarray:
    """Integer or bool exemplars in [0, 1] by the one dtype policy; float ones as they are (checked later)."""
    arr = np.asarray(image)
    return arr if np.issubdtype(arr.dtype, np.floating) else array_to_unit(arr, name)[0]


def write_artifacts(
    folder: Path,
    result: Result,
    exemplar: np.ndarray,
    constraint: np.ndarray | None = None,
    manifest: dict[str, Any] | None = None,
    *,
    bit_depth: int | None = None,
    input_bits: InputBits | None = None,
    plots: bool = True,
    exemplars: Mapping[str, np.ndarray] | None = None,
    voxel_size: float | tuple[float, float, float] | None = None,
    unit: str = "nm",
    progress: Callable[[str, float], None] | None = None,
    ahead: ExemplarAhead | None = None,
) -> tuple[list[str], dict[str, Any]]:
    """Write all artifacts of ``result`` into ``folder``; return their names and the metrics.

    Parameters
    ----------
    folder : Path
        Created if missing.
    result : Result
        A 2-D image or a ``(D, H, W)`` volume.
    exemplar : ndarray
        The exemplar (for a volume made from per-plane exemplars, the ``xy`` one; ``exemplars`` then
        gives all three).
    constraint : ndarray, optional
        The constraint image, whose tensor field is rendered too.
    manifest : dict, optional
        Fields added to ``manifest.json`` (e.g. a job id).
    bit_depth : {8, 16}, optional
        That of ``output.png``; ``output.tiff`` is always 16-bit. Default: from ``input_bits``.
    input_bits : InputBits, optional
        The exemplar's bit depth (:mod:`texsynth.synth.io.depth`; default ``result.input_bits``). An input of
        more than 8 bits gives a 16-bit grey ``output.png``; one that uses fewer bits than its 16-bit
        container (12-bit camera data: 0-4095) gives ``output.tiff`` at that depth (values 0-4095;
        ``output.png`` stays full-scale, the picture to look at), and ``metrics.json`` says it:
        ``input_bits: {container, used}``.
    plots : bool
        Write the comparison plots under ``plots/``.
    exemplars : mapping ``{'xy', 'xz', 'yz'} -> ndarray``, optional
        A volume's per-plane exemplars: each plane's slices are evaluated against, and drawn beside,
        their own exemplar. Ignored for 2-D results.
    voxel_size : float or (float, float, float), optional
        A volume's voxel size in ``unit`` (one value, or ``(z, y, x)``): ImageJ calibration of
        ``output.tiff`` (:func:`texsynth.synth.io.save_volume`); with cubic voxels in nm, fringe lengths are
        also reported in nm. Ignored for 2-D results.
    unit : str
        The unit of ``voxel_size``.
    progress : callable ``(stage, fraction)``, optional
        Told each stage (writing the output, its pictures, the evaluation, the plots) and, for a
        volume, how far the TIFF stack and the slices' evaluation are: minutes at 512^3.
    ahead : ExemplarAhead, optional
        What a 2-D run needs of this ``exemplar`` and ``constraint`` alone, made while the output was
        synthesized (the same files and bytes; ignored for a volume or other arrays).

    Returns
    -------
    (list of str, dict)
        The files written (relative to ``folder``) and the metrics.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)

    def tell(stage: str, fraction: float = 0.0) -> None:
        if progress is not None:
            progress(stage, fraction)

    tell("writing output.png")
    image = np.asarray(result.image, dtype=np.float32)
    volume = image.ndim == 3 and image.shape[-1] != 3
    made = ahead.result(exemplar, constraint) if ahead is not None and not volume else {}
    exemplar = made["exemplar"] if "exemplar" in made else _unit(exemplar, "exemplar")
    if exemplars is not None:
        exemplars = {plane: _unit(ex, f"exemplar_{plane}") for plane, ex in exemplars.items()}
    depth = input_bits if input_bits is not None else result.input_bits
    if depth is not None and depth.container > 16:  # float data: no integer depth to keep
        depth = None
    if bit_depth is None:
        rgb = image.ndim == 3 and not volume
        bit_depth = 16 if depth is not None and depth.container == 16 and not rgb else 8
    # data that use fewer bits than their 16-bit container (12-bit cameras) are written back as such
    used = depth.used if depth is not None and depth.container == 16 and depth.used < 16 else None
    names = ["output.png", "output.tiff"]
    # output.png is the picture to look at (full scale); output.tiff the data, at the input's depth
    save_image(folder / "output.png", image[image.shape[0] // 2] if volume else image, bit_depth=bit_depth)
    if volume:
        save_volume(
            folder / "output.tiff",
            image,
            bit_depth=16,
            voxel_size=voxel_size,
            unit=unit,
            used_bits=used,
            progress=progress,
        )

    def tensor_images(prefix: str, tensors: Callable[[], np.ndarray]) -> Callable[[], list[str]]:
        if prefix in made:  # encoded while the output was synthesized
            return partial(_write_pngs, folder, prefix, made[prefix])
        return lambda: _write_tensor_images(folder, prefix, np.asarray(tensors()))

    def extra(key: str, arr: np.ndarray) -> Callable[[], list[str]]:
        def write() -> list[str]:
            rendered = _render_extra(np.asarray(arr, dtype=np.float32), FIXED_RANGES.get(key))
            if rendered is None:
                return []
            save_image(folder / f"{key}.png", rendered)
            return [f"{key}.png"]

        return write

    # a volume's slices, cube and mid-slice tensor images, the 2-D output's TIFF and tensor images, and
    # every run's exemplar (and constraint) tensor images and extra maps, in the order of their names
    tasks: list[Callable[[], list[str]]] = []
    if volume:
        targets = exemplars if exemplars is not None else exemplar
        tasks.append(lambda: write_volume_images(folder, image, targets))
    else:

        def tiff() -> list[str]:
            save_image(folder / "output.tiff", image, bit_depth=16, used_bits=used)
            return []

        tasks.append(tiff)
        tasks.append(
            tensor_images(
                "",
                lambda: (
                    result.tensor_field
                    if result.tensor_field is not None
                    else structure_tensor(image, mode="wrap")
                ),
            )
        )
    tasks.append(tensor_images("exemplar-", lambda: structure_tensor(as_grey(exemplar, "exemplar"))))
    if constraint is not None:
        tasks.append(
            tensor_images("constraint_", lambda: structure_tensor(np.asarray(constraint, np.float32)))
        )
    for key, arr in sorted(result.extras.items()):
        if key not in ("coherence", "orientation"):  # already rendered above, with legends
            tasks.append(extra(key, arr))
    pictures = _Pictures(tasks)

    # with two threads or more the pictures are drawn and written on a second thread while this one
    # evaluates, writes metrics.json and draws the plots, then takes the pictures left (mostly NumPy,
    # SciPy and zlib, which release the GIL; neither reads what the other makes); their names keep their
    # place in the list
    at = len(names)
    two = current_threads() > 1
    if two:
        tell("drawing the pictures; evaluating")
        pictures.start()
    else:
        tell(
            "drawing slices, cube and tensor images"
            if volume
            else "writing output.tiff and the tensor images"
        )
        names += pictures.finish()
    try:
        metrics, plot_metrics, fringes = _evaluate(
            folder, result, image, exemplar, exemplars, volume, depth, voxel_size, unit, tell, progress, made
        )
        names.append("metrics.json")
        if plots:  # with two threads, the charts are encoded and written with the pictures
            submit = pictures.add if two else None
            names += _plots(folder, image, exemplar, exemplars, volume, plot_metrics, fringes, tell, submit)
    except BaseException:
        if two:  # no file is written after the evaluation or the plots fail
            with suppress(BaseException):
                pictures.finish(help_out=False)
        raise
    if two:
        names[at:at] = pictures.finish()
    _write_manifest(folder, result, image, exemplar, exemplars, volume, voxel_size, unit, manifest, metrics)
    names.append("manifest.json")
    return names, metrics


def _evaluate(
    folder: Path,
    result: Result,
    image: np.ndarray,
    exemplar: np.ndarray,
    exemplars: Mapping[str, np.ndarray] | None,
    volume: bool,
    depth: InputBits | None,
    voxel_size: float | tuple[float, float, float] | None,
    unit: str,
    tell: Callable[..., None],
    progress: Callable[[str, float], None] | None,
    made: Mapping[str, Any],
) -> tuple[dict[str, Any], dict[str, Any], Any]:
    """Evaluate the output, write ``metrics.json``; return the metrics, those the plots read (as
    evaluated) and the output's fringes (2-D). ``made``: the exemplar's values made ahead (2-D)."""
    fringes = None
    shown, reason, presence = made["fringes_shown"] if "fringes_shown" in made else fringes_shown(exemplar)
    if volume:
        pixel_size = None
        if voxel_size is not None and unit.strip() == "nm" and len(set(np.broadcast_to(voxel_size, 3))) == 1:
            pixel_size = float(np.broadcast_to(voxel_size, 3)[0])
        targets = exemplars if exemplars is not None else exemplar
        tell("evaluating the volume's slices")
        metrics = to_json_types(
            evaluate_volume(targets, image, pixel_size=pixel_size, fringes=shown, progress=progress)
        )
    else:
        tell("evaluating")
        metrics, fringes = evaluate_pair_fringes(
            exemplar, image, fringes=shown, exemplar_side=made.get("side")
        )
    plot_metrics = dict(metrics)  # the plots read the metrics as evaluated
    status = {"shown": shown, "reason": reason, "presence": to_json_types(presence)}  # of the exemplar
    if isinstance(metrics.get("fringes"), dict):
        metrics["fringes"] = {**metrics["fringes"], **status}
    else:
        metrics["fringes"] = status
    metrics["headline"] = headline(metrics.get("summary", {}))
    roles = (
        {f"exemplar_{p}": e for p, e in exemplars.items()}
        if volume and exemplars is not None
        else {"exemplar": exemplar}
    )
    metrics["exemplar"] = made["diagnostics"] if "diagnostics" in made else exemplar_diagnostics(roles)
    doc = {"metrics": metrics, "stats": to_json_types(result.stats), "timings": to_json_types(result.timings)}
    if depth is not None:
        doc["input_bits"] = depth.as_json()
    atomic_write_json(folder / "metrics.json", doc)
    return metrics, plot_metrics, fringes


def _plots(
    folder: Path,
    image: np.ndarray,
    exemplar: np.ndarray,
    exemplars: Mapping[str, np.ndarray] | None,
    volume: bool,
    plot_metrics: dict[str, Any],
    fringes: Any,
    tell: Callable[..., None],
    submit: Callable[[Callable[[], object]], None] | None = None,
) -> list[str]:
    """Draw the comparison plots under ``plots/``; return their names (sorted). With ``submit``, each
    chart's encoding and writing is handed to it (:func:`texsynth.synth.output.plots.write_plots`)."""
    tell("drawing the plots")
    plot_dir = folder / "plots"
    plot_dir.mkdir(exist_ok=True)
    targets = exemplars if volume and exemplars is not None else exemplar
    written = write_plots(targets, image, plot_metrics, plot_dir, fringes=fringes, submit=submit)
    if volume:
        s2_plot = write_s2_plot(plot_metrics, plot_dir)
        written += [s2_plot] if s2_plot is not None else []
    return sorted(f"plots/{Path(p).name}" for p in written)


def _write_manifest(
    folder: Path,
    result: Result,
    image: np.ndarray,
    exemplar: np.ndarray,
    exemplars: Mapping[str, np.ndarray] | None,
    volume: bool,
    voxel_size: float | tuple[float, float, float] | None,
    unit: str,
    manifest: dict[str, Any] | None,
    metrics: dict[str, Any],
) -> None:
    doc = {
        **(manifest or {}),
        "method": result.method,
        "params": to_json_types(result.params),
        "seed": result.seed,
        "exemplar_shape": list(np.shape(exemplar)),
        **(
            {"exemplar_shapes": {p: list(np.shape(e)) for p, e in exemplars.items()}}
            if volume and exemplars is not None
            else {}
        ),
        **(
            {"voxel_size": to_json_types(voxel_size), "unit": unit}
            if volume and voxel_size is not None
            else {}
        ),
        "output_shape": list(image.shape),
        "exemplar_stationarity": {
            role: {k: v for k, v in report.items() if k in ("score", "stationary", "warning", "note")}
            for role, report in metrics["exemplar"]["stationarity"].items()
        },
        "timings": to_json_types(result.timings),
        "versions": versions(),
    }
    atomic_write_json(folder / "manifest.json", doc)
