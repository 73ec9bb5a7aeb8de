"""Comparison plots of an evaluation (PNG, painted with Pillow by :mod:`texsynth.synth.output.chart`).

:func:`write_plots` draws, from the metrics of :func:`texsynth.synth.evaluate.evaluate_pair` or
:func:`texsynth.synth.evaluate.evaluate_volume` and the images themselves:

- ``grey_histogram.png``: the exemplar's and the output's grey-level histograms, overlaid;
- ``orientation_rose.png``: rose diagrams of the energy-weighted orientation histograms, one per
  image (per axis for a volume). Roses show the **fringe (structure) direction**, the gradient
  orientation plus 90 degrees, as OrientationJ and materials tools do; orientations cover 180
  degrees, so each petal is drawn twice, mirrored through the centre;
- ``fringe_distributions.png``: fringe length and tortuosity distributions, exemplar vs output;
- ``fringes_exemplar.png``, ``fringes_output.png``: the extracted fringes, one colour per fringe,
  over the image (for a volume, the middle slice along axis 0, and the ``xy`` exemplar).

A volume compared with one exemplar per plane gets per-plane panels: grey histograms and roses of
each axis's slices against its own plane's exemplar. :func:`write_s2_plot` draws ``s2.png``, the
two-point correlation ``S2(r)`` of a volume along ``x``, ``y`` and ``z`` against the exemplars'
(Torquato, *Random Heterogeneous Materials*, 2002, chapter 2).

The charts are painted with Pillow (:mod:`texsynth.synth.output.chart`), the overlays are the images
themselves enlarged with a title: a synthesis writes them every run, and with matplotlib its import
and the drawing of the five plots took 1.5-2.5 s of a 256 x 256 run (docs/benchmarks.md, "The whole
command"). No state is shared but a cache of fonts, so this module is safe in worker processes and
threads.

References
----------
R. D. Urs, J.-P. Da Costa, J.-M. Leyssale, G. Vignoles, C. Germain, "Non-parametric synthesis of
laminar volumetric textures from a 2D sample", Proc. BMVC 2012 (Figs 7-10 are the model).
M. L. Botero et al., Carbon 96 (2016) 459-473 (fringe overlays).
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from PIL import Image

from texsynth.synth.errors import InvalidInput
from texsynth.synth.output.chart import Axes, Chart, Rose, hex_colour

if TYPE_CHECKING:
    from texsynth.synth.analysis.fringes import Fringes

__all__ = ["fringe_overlay", "save_fringe_overlay", "write_plots", "write_s2_plot"]

_EXEMPLAR_COLOUR = "#1f4e9a"
_OUTPUT_COLOURS = ("#d1495b", "#2a9d8f", "#e9a03b")
#: Fringe colours: matplotlib's tab20 (the same values, written out) without its two greys, which vanish
#: on a grey micrograph.
_TAB20 = (
    "#1f77b4", "#aec7e8", "#ff7f0e", "#ffbb78", "#2ca02c", "#98df8a", "#d62728", "#ff9896", "#9467bd",
    "#c5b0d5", "#8c564b", "#c49c94", "#e377c2", "#f7b6d2", "#7f7f7f", "#c7c7c7", "#bcbd22", "#dbdb8d",
    "#17becf", "#9edae5",
)  # fmt: skip
_PALETTE = np.asarray(
    [[c / 255.0 for c in hex_colour(h)] for i, h in enumerate(_TAB20) if i not in (14, 15)], dtype=np.float64
)
_DASH = (3.7, 1.6)  # matplotlib's '--' and ':' (multiples of the line width)
_DOTTED = (1.0, 1.65)


def _as_grey(image: np.ndarray, name: str) -> np.ndarray:
    from texsynth.synth.evaluate.measures import as_grey

    return as_grey(image, name)


def fringe_overlay(image: np.ndarray, fringes: Fringes) -> np.ndarray:
    """RGB image (float in [0, 1]) of ``image`` in grey with every fringe in its own colour.

    Colours cycle through matplotlib's ``tab20`` palette (without its greys) by fringe number.
    """
    grey = _as_grey(image, "image")
    rgb = np.repeat(grey[..., None], 3, axis=2)
    labels = fringes.labels
    if labels.shape != grey.shape:
        raise InvalidInput("fringes", f"label image {labels.shape} does not match image {grey.shape}")
    on = labels > 0
    rgb[on] = _PALETTE[(labels[on] - 1) % len(_PALETTE)]
    return rgb


def _overlay_chart(image: np.ndarray, fringes: Fringes, title: str, scale: int = 3) -> Chart:
    """The overlay enlarged ``scale`` times (nearest neighbour), at least 300 px wide, under its title."""
    rgb = fringe_overlay(image, fringes)
    h, w = rgb.shape[:2]
    scale = max(1, min(scale, 1200 // max(h, w)))
    width = max(w * scale, 300)
    lines = textwrap.wrap(title, width=max(30, int(width / 100 * 14)))
    title_h = round(8 + 16 * len(lines))
    chart = Chart(width, h * scale + title_h)
    chart.lines((width / 2, 4), lines, 8)
    # in place: the same bits as round(clip(rgb) * 255) without two float64 copies of the picture
    np.clip(rgb, 0.0, 1.0, out=rgb)
    rgb *= 255.0
    pixels = np.round(rgb, out=rgb).astype(np.uint8)
    del rgb
    big = np.repeat(np.repeat(pixels, scale * 2, axis=0), scale * 2, axis=1)  # the chart is supersampled
    chart.image.paste(Image.fromarray(big), (round((width - w * scale) / 2) * 2, title_h * 2))
    return chart


def _fringe_title(name: str, fringes: Fringes) -> str:
    s = fringes.summary()
    if not s["count"]:
        return f"{name}: no fringe found"
    unit = f" = {s['median_length_nm']:.2f} nm" if fringes.pixel_size else ""
    return (
        f"{name}: {s['count']} fringes, median length {s['median_length']:.1f} px{unit}, "
        f"median tortuosity {s['median_tortuosity']:.2f}, {100 * s['share_tortuous']:.0f}% above 1.5"
    )


#: Runs a chart's encoding and writing somewhere else (another thread) instead of here.
Submit = Callable[[Callable[[], object]], None]


def _save(chart: Chart, path: Path, dpi: int = 100, submit: Submit | None = None) -> Path:
    """Write ``chart`` as a PNG; drawn for 100 dpi, resampled for another ``dpi``. With ``submit``, the
    PNG is encoded and written by the job handed to it (the same bytes), and the path returned at once."""
    if dpi != 100:
        image = chart.to_image()
        size = (max(1, round(image.width * dpi / 100)), max(1, round(image.height * dpi / 100)))
        chart.image = image.resize(size, Image.Resampling.LANCZOS).resize(
            (size[0] * 2, size[1] * 2), Image.Resampling.NEAREST
        )
    if submit is not None:
        submit(lambda: chart.save(path))
        return Path(path)
    return chart.save(path)


def save_fringe_overlay(
    image: np.ndarray, fringes: Fringes, path: str | Path, *, title: str | None = None, scale: int = 3
) -> Path:
    """Write the fringe overlay of ``image`` as a PNG (enlarged ``scale`` times, nearest neighbour)."""
    chart = _overlay_chart(
        image, fringes, title if title is not None else _fringe_title("fringes", fringes), scale
    )
    return _save(chart, Path(path))


def _blocks(metrics: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any]]]:
    """``(label, block)`` for the output side: one block for a pair, one per axis for a volume."""
    if metrics.get("kind") == "volume":
        return [
            (f"{block['plane']} slices (axis {k})" if "plane" in block else f"slices along axis {k}", block)
            for k, block in metrics["axes"].items()
        ]
    return [("output", metrics)]


def _per_plane(metrics: Mapping[str, Any]) -> bool:
    """Whether a volume was compared with one exemplar per plane (each axis has its own exemplar)."""
    return metrics.get("kind") == "volume" and not metrics.get("isotropic", True)


def _fmt(value: float | None, digits: int = 3) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _colour(i: int) -> tuple[int, int, int]:
    return hex_colour(_OUTPUT_COLOURS[i % len(_OUTPUT_COLOURS)])


_EXEMPLAR = hex_colour(_EXEMPLAR_COLOUR)


def _grey_chart(metrics: Mapping[str, Any]) -> Chart:
    if _per_plane(metrics):
        return _grey_chart_per_plane(metrics)
    block = metrics["overall"] if metrics.get("kind") == "volume" else metrics
    grey = block["grey"]
    ex = np.asarray(grey["histogram"]["exemplar"])
    out = np.asarray(grey["histogram"]["output"])
    edges = np.linspace(0.0, 1.0, len(ex) + 1)
    chart = Chart(640, 400)
    ax = Axes(chart, (70, 52, 625, 345))
    label = "volume (all slices)" if metrics.get("kind") == "volume" else "output"
    ax.stairs(out, edges, colour=_colour(0), width=1.6, label=label)
    ax.stairs(ex, edges, colour=_EXEMPLAR, width=1.8, dash=_DASH, label="exemplar")
    ax.xlabel, ax.ylabel = "grey level", "fraction of pixels"
    m = block["moments"]
    ax.title_text = (
        f"Grey-level histograms ({len(ex)} bins): KL(exemplar || output) = {grey['kl']:.4f} nats\n"
        f"std {m['exemplar']['std']:.3f} vs {m['output']['std']:.3f}, "
        f"skewness {_fmt(m['exemplar']['skewness'])} vs {_fmt(m['output']['skewness'])}"
    )
    ax.finish()
    return chart


def _grey_chart_per_plane(metrics: Mapping[str, Any]) -> Chart:
    """One panel per axis: the pooled slices of that axis against the exemplar of their plane."""
    blocks = _blocks(metrics)
    chart = Chart(420 * len(blocks), 390)
    chart.title(
        "Grey-level histograms per plane (KL(exemplar || slices)); each plane against its own exemplar", 10
    )
    for i, (label, block) in enumerate(blocks):
        ax = Axes(chart, (420 * i + (68 if i == 0 else 50), 80, 420 * (i + 1) - 14, 340))
        grey = block["grey"]
        ex = np.asarray(grey["histogram"]["exemplar"])
        out = np.asarray(grey["histogram"]["output"])
        edges = np.linspace(0.0, 1.0, len(ex) + 1)
        ax.stairs(out, edges, colour=_colour(i), width=1.6, label=label)
        ax.stairs(
            ex,
            edges,
            colour=_EXEMPLAR,
            width=1.8,
            dash=_DASH,
            label=f"exemplar {block.get('plane', '')}".strip(),
        )
        m = block["moments"]
        ax.title_text = (
            f"{label}: KL = {grey['kl']:.4f} nats\n"
            f"std {m['exemplar']['std']:.3f} vs {m['output']['std']:.3f}, "
            f"skewness {_fmt(m['exemplar']['skewness'])} vs {_fmt(m['output']['skewness'])}"
        )
        ax.title_size = 8
        ax.xlabel = "grey level"
        ax.ylabel = "fraction of pixels" if i == 0 else ""
        ax.finish()
    return chart


def _orientation_chart(metrics: Mapping[str, Any]) -> Chart:
    blocks = _blocks(metrics)
    if _per_plane(metrics):
        # two rows: each plane's exemplar above the pooled slices of that plane
        chart = Chart(330 * len(blocks), 780)
        chart.title(
            [
                "Fringe-direction roses per plane (energy-weighted structure tensor, 7x7 window;",
                "0 degrees along the slice's columns, 90 degrees up its rows)",
            ],
            10,
        )
        for i, (label, block) in enumerate(blocks):
            s = block["structure"]
            cx = 330 * i + 165
            Rose(chart, (cx, 235), 108).draw(
                s["orientation_histogram"]["exemplar"], _EXEMPLAR, f"exemplar {block['plane']}"
            )
            Rose(chart, (cx, 600), 108).draw(
                s["orientation_histogram"]["output"],
                _colour(i),
                [label, f"KL = {s['orientation_kl']:.3f}, LE = {s['log_euclidean']:.3f}"],
            )
        return chart
    panels = 1 + len(blocks)
    chart = Chart(320 * panels, 380)
    chart.title("Fringe-direction roses (energy-weighted structure tensor, 7x7 window)", 10)
    first = blocks[0][1]["structure"]
    Rose(chart, (160, 225), 112).draw(first["orientation_histogram"]["exemplar"], _EXEMPLAR, "exemplar")
    for i, (label, block) in enumerate(blocks):
        s = block["structure"]
        Rose(chart, (320 * (i + 1) + 160, 225), 112).draw(
            s["orientation_histogram"]["output"],
            _colour(i),
            [label, f"KL = {s['orientation_kl']:.3f}, LE = {s['log_euclidean']:.3f}"],
        )
    return chart


def _fringe_chart(metrics: Mapping[str, Any]) -> Chart | None:
    blocks = _blocks(metrics)
    if "fringes" not in blocks[0][1]:
        return None
    pixel_size = metrics.get("settings", {}).get("pixel_size_nm")
    chart = Chart(1000, 380)
    fr = blocks[0][1]["fringes"]["exemplar"]
    chart.title(
        f"Fringe morphology: exemplar {fr['count']} fringes, "
        f"median tortuosity {_fmt(fr['median_tortuosity'], 2)}",
        10,
    )
    ax_len, ax_tort = Axes(chart, (72, 34, 480, 322)), Axes(chart, (572, 34, 985, 322))
    for ax, key, xlabel in (
        (ax_len, "length_histogram", "fringe length (nm)" if pixel_size else "fringe length (px)"),
        (ax_tort, "tortuosity_histogram", "tortuosity (last bin: 3 and above)"),
    ):
        ks_key = "ks_length" if key == "length_histogram" else "ks_tortuosity"

        def scaled(hist: Mapping[str, Any], side: str, key: str = key) -> tuple[np.ndarray, np.ndarray]:
            # every axis block has its own length bins (spanning the exemplar's and that axis's
            # fringes): lengths are drawn as densities (fraction per unit length); tortuosity bins
            # are fixed and drawn as fractions
            edges = np.asarray(hist["edges"], dtype=np.float64)
            if key == "length_histogram":
                edges = edges * (pixel_size or 1.0)
                return np.asarray(hist[side]) / np.diff(edges), edges
            return np.asarray(hist[side]), edges

        for i, (label, block) in enumerate(blocks):
            values, edges = scaled(block["fringes"][key], "output")
            ks = block["fringes"][ks_key]["statistic"]
            ax.stairs(values, edges, colour=_colour(i), width=1.4, label=f"{label} (KS {_fmt(ks, 2)})")
        # the exemplar last and dashed, so that an identical output does not hide it
        if _per_plane(metrics):
            for i, (_, block) in enumerate(blocks):
                values, edges = scaled(block["fringes"][key], "exemplar")
                ax.stairs(
                    values,
                    edges,
                    colour=_colour(i),
                    width=1.4,
                    dash=_DASH,
                    label=f"exemplar {block['plane']}",
                )
        else:
            values, edges = scaled(blocks[0][1]["fringes"][key], "exemplar")
            ax.stairs(values, edges, colour=_EXEMPLAR, width=1.8, dash=_DASH, label="exemplar")
        ax.xlabel = xlabel
        if key == "length_histogram":
            ax.ylabel = "fraction of fringes per nm" if pixel_size else "fraction of fringes per px"
        else:
            ax.ylabel = "fraction of fringes"
        ax.finish()
    return chart


_PLANE_COLOURS = {"xy": "#d1495b", "xz": "#2a9d8f", "yz": "#e9a03b"}


def _s2_chart(metrics: Mapping[str, Any]) -> Chart | None:
    """Per physical axis: the volume's S2(r) and that of each exemplar whose plane contains the axis."""
    s2 = metrics.get("s2")
    if not s2:
        return None
    axes_order = [a for a in ("x", "y", "z") if a in s2["axes"]]
    one = not _per_plane(metrics)  # one exemplar for every plane: name it once
    chart = Chart(430 * len(axes_order), 400)
    values = list(s2["thresholds"].values())
    if all(t == values[0] for t in values):
        thresholds = f"{values[0]:.3g}"
    else:
        thresholds = ", ".join(f"{p} {t:.3g}" for p, t in s2["thresholds"].items())
    chart.title(
        f"Two-point correlation, phase 1 = grey >= threshold ({thresholds}); "
        "dotted: exemplar correlation lengths (the error's window)",
        9,
    )
    for i, axis_name in enumerate(axes_order):
        ax = Axes(chart, (430 * i + (68 if i == 0 else 50), 56, 430 * (i + 1) - 14, 345))
        drawn_ex: list[list[float]] = []
        drawn_vol: list[list[float]] = []
        errors = []
        for plane, comp in s2["axes"][axis_name].items():
            colour = hex_colour(_PLANE_COLOURS.get(plane, _EXEMPLAR_COLOUR))
            ex, vol = comp["s2"]["exemplar"], comp["s2"]["volume"]
            direction = "columns" if comp["exemplar_direction"] == "col" else "rows"
            if vol not in drawn_vol:
                label = "volume" if not drawn_vol else f"volume (threshold of {plane})"
                ax.plot(np.arange(len(vol)), vol, colour=(0, 0, 0), width=1.6, label=label)
                drawn_vol.append(vol)
            if ex not in drawn_ex:
                ax.plot(
                    np.arange(len(ex)),
                    ex,
                    colour=colour,
                    width=1.6,
                    dash=_DASH,
                    label=f"exemplar, along its {direction}"
                    if one
                    else f"exemplar {plane}, along its {direction}",
                )
                drawn_ex.append(ex)
                length = comp["correlation_length"]["exemplar"]
                if length is not None:
                    ax.axvline(length, colour=colour, dash=_DOTTED)
            errors.append(f"{plane} {_fmt(comp['relative_error'], 3)}")
        if drawn_ex:
            first = next(iter(s2["axes"][axis_name]))
            phi = drawn_ex[0][0]
            label = "phi^2 of the exemplar" if one else f"phi^2 of exemplar {first}"
            ax.axhline(phi * phi, colour=(128, 128, 128), dash=_DOTTED, label=label)
        ax.xlabel = f"lag r along {axis_name} (voxels)"
        ax.ylabel = "S2(r): both points in phase 1" if i == 0 else ""
        ax.title_text = f"along {axis_name}: relative error {', '.join(errors)}"
        ax.ylim = (0.0, None)
        ax.finish()
    return chart


def write_s2_plot(metrics: Mapping[str, Any], out_dir: str | Path, *, dpi: int = 100) -> Path | None:
    """Write ``s2.png``, the two-point correlation curves of a volume's metrics; ``None`` without S2.

    One panel per physical axis ``x``, ``y``, ``z``: the volume's ``S2(r)`` (solid) and each exemplar's
    along the same physical axis (dashed; the ``xy`` exemplar's columns along ``x``, and so on), the
    exemplars' correlation lengths (dotted) and the relative errors of
    :func:`texsynth.synth.evaluate.evaluate_volume`.
    """
    chart = _s2_chart(metrics)
    if chart is None:
        return None
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return _save(chart, out / "s2.png", dpi)


def write_plots(
    exemplar: np.ndarray | Mapping[str, np.ndarray],
    output: np.ndarray,
    metrics: Mapping[str, Any],
    out_dir: str | Path,
    *,
    dpi: int = 100,
    fringes: Mapping[str, Fringes] | None = None,
    submit: Submit | None = None,
) -> list[Path]:
    """Write the comparison plots of an evaluation as PNG files.

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, 3), or mapping ``{'xy', 'xz', 'yz'} -> ndarray``
        The exemplar, in [0, 1]; a volume's per-plane exemplars (the fringe overlay shows ``'xy'``).
    output : ndarray, shape (H, W), (H, W, 3) or (D, H, W)
        The synthesis output; a volume when ``metrics["kind"] == "volume"``.
    metrics : mapping
        The result of :func:`texsynth.synth.evaluate.evaluate_pair` or
        :func:`texsynth.synth.evaluate.evaluate_volume` for these images (its settings also drive the fringe
    overlays). out_dir : str or Path
        Directory, created if missing.
    dpi : int
        Resolution of the charts (100: the sizes below; others are resampled).
    fringes : mapping ``{'exemplar', 'output'} -> Fringes``, optional
        The fringes of the exemplar and of the (2-D) output when the caller already extracted them
        with the metrics' settings (:func:`texsynth.synth.evaluate.measures.evaluate_pair_fringes`); else they
        are extracted here.
    submit : callable, optional
        Takes each chart's encoding and writing (a job without arguments) to run elsewhere, e.g. on another
        thread while the next chart is drawn (:func:`texsynth.synth.output.artifacts.write_artifacts`); the
        caller then waits for those jobs. Default: each chart is written here before the next is drawn.

    Returns
    -------
    list of Path
        The files written: ``grey_histogram.png`` (640 x 400), ``orientation_rose.png``, and with
        fringe metrics ``fringe_distributions.png``, ``fringes_exemplar.png``, ``fringes_output.png``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fringe_chart = _fringe_chart(metrics)
    # the fringe overlays first: the largest pictures, whose encoding (with ``submit``, on another thread)
    # then runs while the charts are drawn; the paths keep their order
    overlays = (
        [] if fringe_chart is None else _fringe_overlays(exemplar, output, metrics, out, fringes, submit)
    )
    paths = [
        _save(_grey_chart(metrics), out / "grey_histogram.png", dpi, submit),
        _save(_orientation_chart(metrics), out / "orientation_rose.png", dpi, submit),
    ]
    if fringe_chart is None:
        return paths
    paths.append(_save(fringe_chart, out / "fringe_distributions.png", dpi, submit))
    return paths + overlays


def _fringe_overlays(
    exemplar: np.ndarray | Mapping[str, np.ndarray],
    output: np.ndarray,
    metrics: Mapping[str, Any],
    out: Path,
    fringes: Mapping[str, Fringes] | None,
    submit: Submit | None,
) -> list[Path]:
    """:func:`write_plots`' ``fringes_exemplar.png`` and ``fringes_output.png``."""
    settings = metrics.get("settings", {})
    options = dict(settings.get("fringe_options") or {})
    pixel_size = settings.get("pixel_size_nm")
    ex = (
        _as_grey(exemplar["xy"], "exemplar_xy")
        if isinstance(exemplar, Mapping)
        else _as_grey(exemplar, "exemplar")
    )
    out_img = np.asarray(output)
    name = "output"
    volume = metrics.get("kind") == "volume"
    if volume:
        if out_img.ndim != 3:
            raise InvalidInput(
                "output", f"metrics describe a volume but the output has shape {out_img.shape}"
            )
        mid = out_img.shape[0] // 2
        out_img = out_img[mid]
        name = f"volume slice {mid} along axis 0"
    out_grey = _as_grey(out_img, "output")
    paths = []
    for key, label, img, fname in (
        ("exemplar", "exemplar", ex, "fringes_exemplar.png"),
        ("output", name, out_grey, "fringes_output.png"),
    ):
        if fringes is not None and key in fringes and not (volume and key == "output"):
            fr = fringes[key]
        else:
            from texsynth.synth.analysis.fringes import extract_fringes

            fr = extract_fringes(img, pixel_size=pixel_size, **options)
        paths.append(_save(_overlay_chart(img, fr, _fringe_title(label, fr)), out / fname, submit=submit))
    return paths
