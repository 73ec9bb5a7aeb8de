"""Comparison plots of an evaluation (PNG, matplotlib's Agg backend, no pyplot state).

:func:`write_plots` draws, from the metrics of :func:`synth.evaluate.evaluate_pair` or
:func:`synth.evaluate.evaluate_volume` and the images themselves:

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

Figures are :class:`matplotlib.figure.Figure` objects printed by ``FigureCanvasAgg``: nothing is
registered with pyplot, so this module is safe in worker processes and threads.

References
----------
R. D. Urs, J.-P. Da Costa, J.-M. Leyssale, G. Vignoles, C. Germain, "Non-parametric synthesis of
laminar volumetric textures from a 2D sample", Proc. BMVC 2012 (Figs 7-10 are the model).
M. L. Botero et al., Carbon 96 (2016) 459-473 (fringe overlays).
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from synth.analysis.fringes import Fringes, extract_fringes
from synth.errors import InvalidInput
from synth.evaluate import as_grey

__all__ = ["fringe_overlay", "save_fringe_overlay", "write_plots", "write_s2_plot"]

# Charts are drawn off-screen (FigureCanvasAgg); pyplot, if anyone imports it, gets no GUI either.
matplotlib.use("Agg")

_EXEMPLAR_COLOUR = "#1f4e9a"
_OUTPUT_COLOURS = ("#d1495b", "#2a9d8f", "#e9a03b")
#: Fringe colours: matplotlib's tab20 without its two greys, which vanish on a grey micrograph.
_PALETTE = np.asarray(
    [c for i, c in enumerate(colormaps["tab20"].colors) if i not in (14, 15)], dtype=np.float64
)


def _save(fig: Figure, path: Path, dpi: int) -> Path:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi)
    return path


def fringe_overlay(image: np.ndarray, fringes: Fringes) -> np.ndarray:
    """RGB image (float in [0, 1]) of ``image`` in grey with every fringe in its own colour.

    Colours cycle through matplotlib's ``tab20`` palette (without its greys) by fringe number.
    """
    grey = as_grey(image, "image")
    rgb = np.repeat(grey[..., None], 3, axis=2)
    labels = fringes.labels
    if labels.shape != grey.shape:
        raise InvalidInput("fringes", f"label image {labels.shape} does not match image {grey.shape}")
    on = labels > 0
    rgb[on] = _PALETTE[(labels[on] - 1) % len(_PALETTE)]
    return rgb


def _overlay_figure(image: np.ndarray, fringes: Fringes, title: str, scale: int = 3) -> Figure:
    rgb = fringe_overlay(image, fringes)
    h, w = rgb.shape[:2]
    scale = max(1, min(scale, 1200 // max(h, w)))
    dpi = 100
    width_in = max(w * scale / dpi, 3.0)
    lines = textwrap.wrap(title, width=max(30, int(width_in * 14)))
    title_in = 0.08 + 0.16 * len(lines)
    image_in = h * scale / dpi
    fig = Figure(figsize=(width_in, image_in + title_in), dpi=dpi)
    ax = fig.add_axes((0.0, 0.0, 1.0, image_in / (image_in + title_in)))
    ax.imshow(rgb, interpolation="nearest")
    ax.set_axis_off()
    fig.text(0.5, 1.0 - 0.04 / (image_in + title_in), "\n".join(lines), ha="center", va="top", fontsize=8)
    return fig


def _fringe_title(name: str, fringes: Fringes) -> str:
    s = fringes.summary()
    if not s["count"]:
        return f"{name}: no fringe found"
    unit = f" = {s['median_length_nm']:.2f} nm" if fringes.pixel_size else ""
    return (
        f"{name}: {s['count']} fringes, median length {s['median_length']:.1f} px{unit}, "
        f"median tortuosity {s['median_tortuosity']:.2f}, {100 * s['share_tortuous']:.0f}% above 1.5"
    )


def save_fringe_overlay(
    image: np.ndarray, fringes: Fringes, path: str | Path, *, title: str | None = None, scale: int = 3
) -> Path:
    """Write the fringe overlay of ``image`` as a PNG (enlarged ``scale`` times, nearest neighbour)."""
    path = Path(path)
    fig = _overlay_figure(
        image, fringes, title if title is not None else _fringe_title("fringes", fringes), scale
    )
    return _save(fig, path, 100)


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


def _grey_figure(metrics: Mapping[str, Any]) -> Figure:
    if _per_plane(metrics):
        return _grey_figure_per_plane(metrics)
    block = metrics["overall"] if metrics.get("kind") == "volume" else metrics
    grey = block["grey"]
    ex = np.asarray(grey["histogram"]["exemplar"])
    out = np.asarray(grey["histogram"]["output"])
    edges = np.linspace(0.0, 1.0, len(ex) + 1)
    fig = Figure(figsize=(6.4, 4.0))
    ax = fig.add_subplot()
    label = "volume (all slices)" if metrics.get("kind") == "volume" else "output"
    ax.stairs(out, edges, label=label, color=_OUTPUT_COLOURS[0], linewidth=1.6)
    ax.stairs(ex, edges, label="exemplar", color=_EXEMPLAR_COLOUR, linewidth=1.8, linestyle="--")
    ax.set_xlabel("grey level")
    ax.set_ylabel("fraction of pixels")
    m = block["moments"]
    ax.set_title(
        f"Grey-level histograms ({len(ex)} bins): KL(exemplar || output) = {grey['kl']:.4f} nats\n"
        f"std {m['exemplar']['std']:.3f} vs {m['output']['std']:.3f}, "
        f"skewness {_fmt(m['exemplar']['skewness'])} vs {_fmt(m['output']['skewness'])}",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _grey_figure_per_plane(metrics: Mapping[str, Any]) -> Figure:
    """One panel per axis: the pooled slices of that axis against the exemplar of their plane."""
    blocks = _blocks(metrics)
    fig = Figure(figsize=(4.2 * len(blocks), 3.9))
    for i, (label, block) in enumerate(blocks):
        ax = fig.add_subplot(1, len(blocks), i + 1)
        grey = block["grey"]
        ex = np.asarray(grey["histogram"]["exemplar"])
        out = np.asarray(grey["histogram"]["output"])
        edges = np.linspace(0.0, 1.0, len(ex) + 1)
        ax.stairs(out, edges, label=label, color=_OUTPUT_COLOURS[i % len(_OUTPUT_COLOURS)], linewidth=1.6)
        ax.stairs(
            ex,
            edges,
            label=f"exemplar {block.get('plane', '')}".strip(),
            color=_EXEMPLAR_COLOUR,
            linewidth=1.8,
            linestyle="--",
        )
        m = block["moments"]
        ax.set_title(
            f"{label}: KL = {grey['kl']:.4f} nats\n"
            f"std {m['exemplar']['std']:.3f} vs {m['output']['std']:.3f}, "
            f"skewness {_fmt(m['exemplar']['skewness'])} vs {_fmt(m['output']['skewness'])}",
            fontsize=8,
        )
        ax.set_xlabel("grey level")
        if i == 0:
            ax.set_ylabel("fraction of pixels")
        ax.legend(fontsize=7)
    fig.suptitle(
        "Grey-level histograms per plane (KL(exemplar || slices)); each plane against its own exemplar",
        fontsize=10,
    )
    fig.tight_layout()
    return fig


def _fmt(value: float | None, digits: int = 3) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _rose(ax: Any, hist: Sequence[float], colour: str, title: str) -> None:
    h = np.asarray(hist, dtype=np.float64)
    n = len(h)
    width = np.pi / n
    # gradient-orientation bin centres, plus 90 degrees: the fringe direction
    centres = -np.pi / 2 + width * (np.arange(n) + 0.5) + np.pi / 2
    for shift in (0.0, np.pi):  # mirrored: an orientation is the same line both ways
        ax.bar(centres + shift, h, width=width, color=colour, alpha=0.75, edgecolor="white", linewidth=0.3)
    ax.set_title(title, fontsize=9, pad=12)
    ax.set_yticklabels([])
    ax.set_thetagrids(range(0, 360, 45), fontsize=7)


def _orientation_figure(metrics: Mapping[str, Any]) -> Figure:
    blocks = _blocks(metrics)
    if _per_plane(metrics):
        # two rows: each plane's exemplar above the pooled slices of that plane
        fig = Figure(figsize=(3.3 * len(blocks), 7.8))
        for i, (label, block) in enumerate(blocks):
            s = block["structure"]
            ax = fig.add_subplot(2, len(blocks), i + 1, projection="polar")
            _rose(ax, s["orientation_histogram"]["exemplar"], _EXEMPLAR_COLOUR, f"exemplar {block['plane']}")
            ax = fig.add_subplot(2, len(blocks), len(blocks) + i + 1, projection="polar")
            _rose(
                ax,
                s["orientation_histogram"]["output"],
                _OUTPUT_COLOURS[i % len(_OUTPUT_COLOURS)],
                f"{label}\nKL = {s['orientation_kl']:.3f}, LE = {s['log_euclidean']:.3f}",
            )
        fig.suptitle(
            "Fringe-direction roses per plane (energy-weighted structure tensor, 7x7 window;\n"
            "0 degrees along the slice's columns, 90 degrees up its rows)",
            fontsize=10,
        )
        fig.tight_layout()
        return fig
    panels = 1 + len(blocks)
    fig = Figure(figsize=(3.2 * panels, 3.8))
    first = blocks[0][1]["structure"]
    ax = fig.add_subplot(1, panels, 1, projection="polar")
    _rose(ax, first["orientation_histogram"]["exemplar"], _EXEMPLAR_COLOUR, "exemplar")
    for i, (label, block) in enumerate(blocks):
        s = block["structure"]
        ax = fig.add_subplot(1, panels, i + 2, projection="polar")
        _rose(
            ax,
            s["orientation_histogram"]["output"],
            _OUTPUT_COLOURS[i % len(_OUTPUT_COLOURS)],
            f"{label}\nKL = {s['orientation_kl']:.3f}, LE = {s['log_euclidean']:.3f}",
        )
    fig.suptitle("Fringe-direction roses (energy-weighted structure tensor, 7x7 window)", fontsize=10)
    fig.tight_layout()
    return fig


def _fringe_figure(metrics: Mapping[str, Any]) -> Figure | None:
    blocks = _blocks(metrics)
    if "fringes" not in blocks[0][1]:
        return None
    pixel_size = metrics.get("settings", {}).get("pixel_size_nm")
    fig = Figure(figsize=(10.0, 3.8))
    ax_len, ax_tort = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
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
            ax.stairs(
                values,
                edges,
                label=f"{label} (KS {_fmt(ks, 2)})",
                color=_OUTPUT_COLOURS[i % len(_OUTPUT_COLOURS)],
                linewidth=1.4,
            )
        # the exemplar last and dashed, so that an identical output does not hide it
        if _per_plane(metrics):
            for i, (_, block) in enumerate(blocks):
                values, edges = scaled(block["fringes"][key], "exemplar")
                ax.stairs(
                    values,
                    edges,
                    label=f"exemplar {block['plane']}",
                    color=_OUTPUT_COLOURS[i % len(_OUTPUT_COLOURS)],
                    linewidth=1.4,
                    linestyle="--",
                )
        else:
            values, edges = scaled(blocks[0][1]["fringes"][key], "exemplar")
            ax.stairs(values, edges, label="exemplar", color=_EXEMPLAR_COLOUR, linewidth=1.8, linestyle="--")
        ax.set_xlabel(xlabel)
        if key == "length_histogram":
            ax.set_ylabel("fraction of fringes per nm" if pixel_size else "fraction of fringes per px")
        else:
            ax.set_ylabel("fraction of fringes")
        ax.legend(fontsize=7)
    fr = blocks[0][1]["fringes"]["exemplar"]
    fig.suptitle(
        f"Fringe morphology: exemplar {fr['count']} fringes, "
        f"median tortuosity {_fmt(fr['median_tortuosity'], 2)}",
        fontsize=10,
    )
    fig.tight_layout()
    return fig


_PLANE_COLOURS = {"xy": "#d1495b", "xz": "#2a9d8f", "yz": "#e9a03b"}


def _s2_figure(metrics: Mapping[str, Any]) -> Figure | None:
    """Per physical axis: the volume's S2(r) and that of each exemplar whose plane contains the axis."""
    s2 = metrics.get("s2")
    if not s2:
        return None
    axes_order = [a for a in ("x", "y", "z") if a in s2["axes"]]
    one = not _per_plane(metrics)  # one exemplar for every plane: name it once
    fig = Figure(figsize=(4.3 * len(axes_order), 4.0))
    for i, axis_name in enumerate(axes_order):
        ax = fig.add_subplot(1, len(axes_order), i + 1)
        drawn_ex: list[list[float]] = []
        drawn_vol: list[list[float]] = []
        errors = []
        for plane, comp in s2["axes"][axis_name].items():
            colour = _PLANE_COLOURS.get(plane, _EXEMPLAR_COLOUR)
            ex, vol = comp["s2"]["exemplar"], comp["s2"]["volume"]
            direction = "columns" if comp["exemplar_direction"] == "col" else "rows"
            if vol not in drawn_vol:
                label = "volume" if not drawn_vol else f"volume (threshold of {plane})"
                ax.plot(np.arange(len(vol)), vol, color="black", linewidth=1.6, label=label)
                drawn_vol.append(vol)
            if ex not in drawn_ex:
                ax.plot(
                    np.arange(len(ex)),
                    ex,
                    color=colour,
                    linewidth=1.6,
                    linestyle="--",
                    label=f"exemplar, along its {direction}"
                    if one
                    else f"exemplar {plane}, along its {direction}",
                )
                drawn_ex.append(ex)
                length = comp["correlation_length"]["exemplar"]
                if length is not None:
                    ax.axvline(length, color=colour, linewidth=0.8, linestyle=":")
            errors.append(f"{plane} {_fmt(comp['relative_error'], 3)}")
        if drawn_ex:
            first = next(iter(s2["axes"][axis_name]))
            phi = drawn_ex[0][0]
            label = "phi^2 of the exemplar" if one else f"phi^2 of exemplar {first}"
            ax.axhline(phi * phi, color="grey", linewidth=0.8, linestyle=":", label=label)
        ax.set_xlabel(f"lag r along {axis_name} (voxels)")
        if i == 0:
            ax.set_ylabel("S2(r): both points in phase 1")
        ax.set_title(f"along {axis_name}: relative error {', '.join(errors)}", fontsize=9)
        ax.set_ylim(bottom=0.0)
        ax.legend(fontsize=7)
    values = list(s2["thresholds"].values())
    if all(t == values[0] for t in values):
        thresholds = f"{values[0]:.3g}"
    else:
        thresholds = ", ".join(f"{p} {t:.3g}" for p, t in s2["thresholds"].items())
    fig.suptitle(
        f"Two-point correlation, phase 1 = grey >= threshold ({thresholds}); "
        "dotted: exemplar correlation lengths (the error's window)",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def write_s2_plot(metrics: Mapping[str, Any], out_dir: str | Path, *, dpi: int = 100) -> Path | None:
    """Write ``s2.png``, the two-point correlation curves of a volume's metrics; ``None`` without S2.

    One panel per physical axis ``x``, ``y``, ``z``: the volume's ``S2(r)`` (solid) and each exemplar's
    along the same physical axis (dashed; the ``xy`` exemplar's columns along ``x``, and so on), the
    exemplars' correlation lengths (dotted) and the relative errors of
    :func:`synth.evaluate.evaluate_volume`.
    """
    fig = _s2_figure(metrics)
    if fig is None:
        return None
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return _save(fig, out / "s2.png", dpi)


def write_plots(
    exemplar: np.ndarray | Mapping[str, np.ndarray],
    output: np.ndarray,
    metrics: Mapping[str, Any],
    out_dir: str | Path,
    *,
    dpi: int = 100,
) -> list[Path]:
    """Write the comparison plots of an evaluation as PNG files.

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, 3), or mapping ``{'xy', 'xz', 'yz'} -> ndarray``
        The exemplar, in [0, 1]; a volume's per-plane exemplars (the fringe overlay shows ``'xy'``).
    output : ndarray, shape (H, W), (H, W, 3) or (D, H, W)
        The synthesis output; a volume when ``metrics["kind"] == "volume"``.
    metrics : mapping
        The result of :func:`synth.evaluate.evaluate_pair` or :func:`synth.evaluate.evaluate_volume`
        for these images (its settings also drive the fringe overlays).
    out_dir : str or Path
        Directory, created if missing.
    dpi : int
        Resolution of the charts.

    Returns
    -------
    list of Path
        The files written: ``grey_histogram.png``, ``orientation_rose.png``, and with fringe
        metrics ``fringe_distributions.png``, ``fringes_exemplar.png``, ``fringes_output.png``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [
        _save(_grey_figure(metrics), out / "grey_histogram.png", dpi),
        _save(_orientation_figure(metrics), out / "orientation_rose.png", dpi),
    ]
    fringe_fig = _fringe_figure(metrics)
    if fringe_fig is None:
        return paths
    paths.append(_save(fringe_fig, out / "fringe_distributions.png", dpi))
    settings = metrics.get("settings", {})
    options = dict(settings.get("fringe_options") or {})
    pixel_size = settings.get("pixel_size_nm")
    ex = (
        as_grey(exemplar["xy"], "exemplar_xy")
        if isinstance(exemplar, Mapping)
        else as_grey(exemplar, "exemplar")
    )
    out_img = np.asarray(output)
    name = "output"
    if metrics.get("kind") == "volume":
        if out_img.ndim != 3:
            raise InvalidInput(
                "output", f"metrics describe a volume but the output has shape {out_img.shape}"
            )
        mid = out_img.shape[0] // 2
        out_img = out_img[mid]
        name = f"volume slice {mid} along axis 0"
    out_grey = as_grey(out_img, "output")
    for label, img, fname in (
        ("exemplar", ex, "fringes_exemplar.png"),
        (name, out_grey, "fringes_output.png"),
    ):
        fr = extract_fringes(img, pixel_size=pixel_size, **options)
        paths.append(_save(_overlay_figure(img, fr, _fringe_title(label, fr)), out / fname, 100))
    return paths
