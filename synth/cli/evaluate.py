"""``texsynth evaluate``: the quantitative benchmark of a synthesis result against its exemplar.

``texsynth evaluate --exemplar EX --output OUT [--json] [--plots DIR] [--pixel-size NM]``
``texsynth evaluate --exemplar-xy XY --exemplar-xz XZ --exemplar-yz YZ --output VOLUME.tif ...``

``OUT`` is a 2-D image, or a volume: a TIFF with more than one page is read with
:func:`texsynth.synth.io.load_volume` and evaluated slice by slice along each axis, with the two-point
correlation ``S2(r)`` along ``x``, ``y`` and ``z`` (:func:`texsynth.synth.evaluate.evaluate_volume`). A volume
of an anisotropic material is compared plane by plane with three exemplars (``--exemplar-xy``,
``--exemplar-xz``, ``--exemplar-yz``) instead of one. Prints a table (per axis for a volume), or the
full metrics as JSON with ``--json``; ``--plots DIR`` also writes the comparison PNGs
(:func:`texsynth.synth.output.plots.write_plots`, and ``s2.png`` for volumes). Bad input is one line on stderr
and exit status 2 (handled by :func:`texsynth.synth.cli.main`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from texsynth.synth.cli.inputs import add_threads_argument, threads_from
from texsynth.synth.errors import InvalidInput

__all__ = ["format_table", "register", "run"]

_DESCRIPTION = """\
Compare a synthesis output with its exemplar (the benchmark of the volumetric-synthesis study,
Urs et al. 2012, section 3.2):

  grey levels  64-bin histograms, KL(exemplar || output) in nats; mean, std, skewness, kurtosis
  structure    energy-weighted orientation histograms (structure tensor, 7x7 window) and their KL;
               coherence; Log-Euclidean distance of the mean tensors
  fringes      HRTEM lattice fringes: count, length, tortuosity (length / end-to-end distance),
               Kolmogorov-Smirnov statistics of the distributions

OUTPUT may be a volume (a TIFF with several pages, one per z): every slice along each of the three
axes is compared with the exemplar, per axis and overall, and the two-point correlation S2(r) of the
volume along x, y and z with the exemplar's along the same axis (relative error up to the exemplar's
correlation length; phase 1 = grey >= the exemplar's Otsu threshold). An anisotropic material gives
one exemplar per plane instead: --exemplar-xy (rows y, columns x), --exemplar-xz (rows z, columns x),
--exemplar-yz (rows z, columns y).
"""


def _is_stack(path: str) -> bool:
    """Whether ``path`` is a TIFF with more than one page (anything unreadable: no, load_image says why)."""
    import tifffile  # deferred: ``--help`` needs no image codecs

    try:
        with tifffile.TiffFile(path) as tif:
            return len(tif.pages) > 1
    except (OSError, tifffile.TiffFileError, ValueError):
        return False


def _num(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, str):  # a blank: the row does not apply to this column
        return value
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}f}"


Getter = Callable[[Mapping[str, Any]], Any]


def _columns(metrics: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any], str]]:
    """``(header, block, side)`` per column; ``side`` is ``'exemplar'`` or ``'output'``.

    One exemplar column, then the output's; a volume with per-plane exemplars gets an exemplar
    column before each axis (and the pooled exemplars before ``all axes``).
    """
    if metrics["kind"] != "volume":
        return [("exemplar", metrics, "exemplar"), ("output", metrics, "output")]
    overall = dict(metrics["overall"])
    if metrics.get("s2"):
        overall["s2_summary"] = metrics["s2"]["summary"]
    axes = [
        (f"axis {k} ({block['plane']})" if "plane" in block else f"axis {k}", block)
        for k, block in metrics["axes"].items()
    ]
    if metrics.get("isotropic", True):
        return [
            ("exemplar", _merged_blocks([b for _, b in axes]), "exemplar"),
            *((name, block, "output") for name, block in axes),
            ("all axes", overall, "output"),
        ]
    cols: list[tuple[str, Mapping[str, Any], str]] = []
    for name, block in axes:
        cols += [(f"ex {block.get('plane', '')}".strip(), block, "exemplar"), (name, block, "output")]
    return [*cols, ("ex pooled", overall, "exemplar"), ("all axes", overall, "output")]


def _merged_blocks(blocks: list[Mapping[str, Any]]) -> Mapping[str, Any]:
    """The exemplar side of one exemplar shared by every axis: the first block, with every axis's S2."""
    merged = dict(blocks[0])
    s2: dict[str, Any] = {}
    for block in blocks:
        for axis, comp in block.get("s2", {}).items():
            s2.setdefault(axis, comp)
    merged["s2"] = s2
    return merged


def _s2_rows() -> list[tuple[str, str, Getter | None, Getter]]:
    rows: list[tuple[str, str, Getter | None, Getter]] = []
    for axis in ("x", "y", "z"):

        def error(b: Mapping[str, Any], a: str = axis) -> Any:
            if "s2_summary" in b:
                return b["s2_summary"].get(a)
            return b.get("s2", {}).get(a, {}).get("relative_error", "")

        rows.append(("S2", f"relative error along {axis}", None, error))
    for axis in ("x", "y", "z"):

        def length(b: Mapping[str, Any], side: str, a: str = axis) -> Any:
            comp = b.get("s2", {}).get(a)
            return comp["correlation_length"][side] if comp else ""

        rows.append(
            (
                "S2",
                f"correlation length along {axis}, vox",
                lambda b, f=length: f(b, "exemplar"),
                lambda b, f=length: f(b, "output"),
            )
        )
    return rows


def format_table(metrics: Mapping[str, Any]) -> str:
    """A plain-text table of the headline figures of ``evaluate_pair``/``evaluate_volume`` metrics."""
    cols = _columns(metrics)
    first = cols[0][1]
    pixel_size = metrics["settings"].get("pixel_size_nm")
    # (section, label, value on the exemplar side or None, value on an output block)
    rows: list[tuple[str, str, Getter | None, Getter]] = [
        ("grey", "KL(exemplar || output), nats", None, lambda b: b["grey"]["kl"]),
    ]
    for key in ("mean", "std", "skewness", "kurtosis"):
        rows.append(
            (
                "grey",
                key,
                lambda b, k=key: b["moments"]["exemplar"][k],
                lambda b, k=key: b["moments"]["output"][k],
            )
        )
    rows += [
        ("structure", "orientation KL, nats", None, lambda b: b["structure"]["orientation_kl"]),
        (
            "structure",
            "dominant fringe direction, deg",
            lambda b: b["structure"]["dominant_structure_direction_deg"]["exemplar"],
            lambda b: b["structure"]["dominant_structure_direction_deg"]["output"],
        ),
        (
            "structure",
            "mean coherence",
            lambda b: b["structure"]["coherence_mean"]["exemplar"],
            lambda b: b["structure"]["coherence_mean"]["output"],
        ),
        ("structure", "coherence KL, nats", None, lambda b: b["structure"]["coherence_kl"]),
        ("structure", "Log-Euclidean, mean tensors", None, lambda b: b["structure"]["log_euclidean"]),
        (
            "grain",
            "variance share finer than 1 px",
            lambda b: b["grain"]["exemplar"],
            lambda b: b["grain"]["output"],
        ),
    ]
    if "fringes" in first:
        side_rows = [
            ("count", "count"),
            ("density per 10k px", "density_per_10k_px"),
            ("mean length, px", "mean_length"),
            ("median length, px", "median_length"),
        ]
        if pixel_size:
            side_rows += [("mean length, nm", "mean_length_nm"), ("median length, nm", "median_length_nm")]
        side_rows += [
            ("median tortuosity", "median_tortuosity"),
            ("share tortuosity > 1.5", "share_tortuous"),
        ]
        for label, key in side_rows:
            rows.append(
                (
                    "fringes",
                    label,
                    lambda b, k=key: b["fringes"]["exemplar"][k],
                    lambda b, k=key: b["fringes"]["output"][k],
                )
            )
        rows += [
            ("fringes", "KS statistic, length", None, lambda b: b["fringes"]["ks_length"]["statistic"]),
            (
                "fringes",
                "KS statistic, tortuosity",
                None,
                lambda b: b["fringes"]["ks_tortuosity"]["statistic"],
            ),
        ]

    if metrics.get("s2"):
        rows += _s2_rows()
    header = ["", "", *(name for name, _, _ in cols)]
    table = [header]
    last_section = None
    for section, label, ex_get, out_get in rows:
        cells = [section if section != last_section else "", label]
        for _, block, side in cols:
            getter = ex_get if side == "exemplar" else out_get
            cells.append(_num(getter(block)) if getter is not None else "")
        table.append(cells)
        last_section = section
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    lines = []
    for r in table:
        left = f"{r[0]:<{widths[0]}}  {r[1]:<{widths[1]}}"
        right = "  ".join(f"{c:>{max(widths[i + 2], 9)}}" for i, c in enumerate(r[2:]))
        lines.append(f"{left}  {right}".rstrip())
    shape = metrics["shape"]
    target = "volume" if metrics["kind"] == "volume" else "output"
    if metrics["kind"] == "volume" and not metrics.get("isotropic", True):
        exemplar_text = "exemplars " + ", ".join(
            f"{p} {'x'.join(map(str, reversed(sh)))}" for p, sh in shape["exemplars"].items()
        )
    else:
        exemplar_text = f"exemplar {'x'.join(map(str, reversed(shape['exemplar'])))}"
    title = f"{exemplar_text} vs {target} {'x'.join(map(str, reversed(shape[target])))}" + (
        f", {pixel_size:g} nm/px" if pixel_size else ""
    )
    notes = []
    if metrics.get("s2"):
        thresholds = metrics["s2"]["thresholds"]
        values = sorted(set(thresholds.values()))
        where = (
            f"{values[0]:.4g}"
            if len(values) == 1
            else ", ".join(f"{p} {t:.4g}" for p, t in thresholds.items())
        )
        notes = [
            "",
            f"S2: phase 1 = grey >= {where}; relative error = sum |S2_vol - S2_ex| / sum S2_ex over r up to "
            "the exemplar's correlation length",
        ]
    return "\n".join([title, "", *lines, *notes])


def run(args: argparse.Namespace) -> int:
    """Load, evaluate, print; write plots on request."""
    from texsynth.synth.cli import imports_without_gc, modules_on_demand

    with imports_without_gc():  # the package's doc: a one-shot command's imports live to the end
        modules_on_demand()
        from texsynth.synth.evaluate import evaluate_pair, evaluate_volume
        from texsynth.synth.io import load_image, load_volume

    planes = {p: getattr(args, f"exemplar_{p}") for p in ("xy", "xz", "yz")}
    given = [p for p, path in planes.items() if path is not None]
    if given and args.exemplar is not None:
        raise InvalidInput("--exemplar", "give either one exemplar or one per plane (--exemplar-xy/-xz/-yz)")
    if given and len(given) < 3:
        missing = next(p for p in planes if planes[p] is None)
        raise InvalidInput(f"--exemplar-{missing}", "missing: per-plane exemplars come as all three")
    if not given and args.exemplar is None:
        raise InvalidInput(
            "--exemplar", "missing: give --exemplar, or --exemplar-xy, --exemplar-xz and --exemplar-yz"
        )
    options = {"pixel_size": args.pixel_size, "fringes": not args.no_fringes, "threads": threads_from(args)}
    exemplars = {p: load_image(path, mode="grey") for p, path in planes.items()} if given else None
    exemplar = load_image(args.exemplar) if args.exemplar is not None else None
    if _is_stack(args.output):
        output = load_volume(args.output)
        metrics = evaluate_volume(
            exemplars if exemplars is not None else exemplar,
            output,
            slice_step=args.slice_step,
            threshold=args.threshold,
            **options,
        )
    else:
        if exemplars is not None:
            raise InvalidInput(
                str(args.output), "per-plane exemplars are for volumes; this is a 2-D image (give --exemplar)"
            )
        output = load_image(args.output)
        metrics = evaluate_pair(exemplar, output, **options)
    if args.plots is not None:
        from texsynth.synth.output.plots import write_plots  # deferred: only when plots are asked for

        try:
            written = write_plots(
                exemplars if exemplars is not None else exemplar, output, metrics, args.plots
            )
            if metrics["kind"] == "volume":
                from texsynth.synth.output.plots import write_s2_plot

                s2_plot = write_s2_plot(metrics, args.plots)
                written += [s2_plot] if s2_plot is not None else []
        except OSError as exc:
            raise InvalidInput(str(args.plots), f"cannot write the plots: {exc.strerror or exc}") from None
        if not args.json:
            print(f"plots: {', '.join(str(p) for p in written)}", file=sys.stderr)
    if args.json:
        print(json.dumps(metrics, indent=2, allow_nan=False))
    else:
        print(format_table(metrics))
    return 0


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number")
    return value


def _unit_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be a grey level in [0, 1]")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``evaluate`` to the ``texsynth`` command line."""
    parser = subparsers.add_parser(
        "evaluate",
        help="compare an output image or volume with its exemplar: histograms, orientations, fringes",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--exemplar", metavar="EX", help="the exemplar image (PNG, TIFF, JPEG)")
    for plane, rows, cols in (("xy", "y", "x"), ("xz", "z", "x"), ("yz", "z", "y")):
        parser.add_argument(
            f"--exemplar-{plane}",
            metavar=plane.upper(),
            help=f"volumes of anisotropic materials: the exemplar of the {plane} slices "
            f"(rows {rows}, columns {cols}); all three planes together, instead of --exemplar",
        )
    parser.add_argument(
        "--output",
        required=True,
        metavar="OUT",
        help="the synthesis output: an image, or a volume as a multi-page TIFF",
    )
    parser.add_argument("--json", action="store_true", help="print all metrics as JSON instead of a table")
    add_threads_argument(parser)
    parser.add_argument(
        "--plots", type=Path, metavar="DIR", help="also write the comparison plots (PNG) into DIR"
    )
    parser.add_argument(
        "--pixel-size",
        type=_positive_float,
        metavar="NM",
        help="nanometres per pixel, to report fringe lengths in nm (hrtem-soot images: about 0.0556)",
    )
    parser.add_argument(
        "--no-fringes",
        action="store_true",
        help="skip the fringe analysis (textures without lattice fringes)",
    )
    parser.add_argument(
        "--threshold",
        type=_unit_float,
        metavar="T",
        help="volumes: grey level of the phase boundary for S2 (phase 1 = grey >= T; "
        "default: each exemplar's Otsu threshold)",
    )
    parser.add_argument(
        "--slice-step",
        type=_positive_int,
        default=1,
        metavar="N",
        help="volumes: evaluate every N-th slice along each axis (default 1: all)",
    )
    parser.set_defaults(func=run)
